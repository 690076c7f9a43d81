"""``polar-sim compare RUN_A RUN_B``: per-metric differences between two runs, with bootstrap CIs.

Rows are grouped by their parameters (all but the seed, or ``by``). Within a group, when both runs
hold the same seeds the difference is paired (B - A per seed, then the mean); otherwise it is the
difference of the means. The 95 % interval is the percentile bootstrap over seeds (``n_boot``
resamples, seeded). Writes ``compare.md``, ``compare.csv`` and ``compare.png``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from polar_sim.runner.report import fmt, markdown_table, write_csv_table
from polar_sim.runner.results import RESERVED, ResultsFile

__all__ = ["compare_runs", "bootstrap_difference"]


def _run(folder, name):
    folder = Path(folder)
    if not (folder / "results.csv").is_file():
        raise ValueError(f"{name}: {str(folder)!r} holds no results.csv (give a run folder of polar-sim run)")
    rows = [r for r in ResultsFile(folder / "results.csv").read() if r.get("status") == "ok"]
    if not rows:
        raise ValueError(f"{name}: {str(folder)!r} has no finished trials")
    cfg = {}
    if (folder / "config.json").is_file():
        try:
            cfg = json.loads((folder / "config.json").read_text())
        except json.JSONDecodeError:
            raise ValueError(f"{name}: {folder / 'config.json'} is corrupt") from None
    return rows, cfg


def bootstrap_difference(a, b, *, paired, n_boot=2000, rng=None, level=0.95):
    """Mean difference ``b - a`` and its percentile bootstrap interval.

    ``paired``: ``a`` and ``b`` are matched element by element (same seeds). Returns
    ``(diff, low, high)``; with one sample the interval is ``(nan, nan)``.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    rng = rng if rng is not None else np.random.default_rng(0)
    if paired:
        d = b - a
        diff = float(d.mean())
        if len(d) < 2:
            return diff, math.nan, math.nan
        boots = d[rng.integers(0, len(d), (n_boot, len(d)))].mean(1)
    else:
        diff = float(b.mean() - a.mean())
        if len(a) < 2 or len(b) < 2:
            return diff, math.nan, math.nan
        boots = (b[rng.integers(0, len(b), (n_boot, len(b)))].mean(1)
                 - a[rng.integers(0, len(a), (n_boot, len(a)))].mean(1))
    lo, hi = np.percentile(boots, [50 * (1 - level), 100 - 50 * (1 - level)])
    return diff, float(lo), float(hi)


def _numeric(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def compare_runs(run_a, run_b, *, by=None, metrics=None, out=None, n_boot=2000, seed=0):
    """Compare two run folders; returns the path of ``compare.md``."""
    if isinstance(n_boot, bool) or not isinstance(n_boot, int) or n_boot < 100:
        raise ValueError(f"n_boot: expected an integer >= 100, got {n_boot!r}")
    rows_a, cfg_a = _run(run_a, "run_a")
    rows_b, cfg_b = _run(run_b, "run_b")
    params = set(cfg_a.get("grid", {})) | set(cfg_b.get("grid", {}))
    if not params:   # no config: every non-numeric, non-reserved column is a parameter
        params = {k for k, v in rows_a[0].items() if k not in RESERVED and not _numeric(v)}
    by = sorted(params) if by is None else list(by)
    unknown = [k for k in by if k not in rows_a[0] or k not in rows_b[0]]
    if unknown:
        raise ValueError(f"by: {unknown} are not columns of both runs; parameters: {', '.join(sorted(params))}")
    skip = RESERVED | params | {"elapsed_s", "load"}
    common = [k for k in rows_a[0] if k in rows_b[0] and k not in skip
              and any(_numeric(r.get(k)) for r in rows_a) and any(_numeric(r.get(k)) for r in rows_b)]
    if metrics is not None:
        bad = [m for m in metrics if m not in common]
        if bad:
            raise ValueError(f"metric: {bad} are not numeric metrics of both runs; valid: {', '.join(common)}")
        common = list(metrics)
    if not common:
        raise ValueError("metric: the runs share no numeric metric")
    rng = np.random.default_rng(seed)

    def groups(rows):
        g = {}
        for r in rows:
            g.setdefault(tuple(r.get(k) for k in by), {})[r["seed"]] = r
        return g

    ga, gb = groups(rows_a), groups(rows_b)
    table = []
    for key in [k for k in ga if k in gb]:
        seeds = sorted(set(ga[key]) & set(gb[key]))
        paired = len(seeds) >= 1 and set(ga[key]) == set(gb[key])
        for m in common:
            if paired:
                pairs = [(ga[key][s].get(m), gb[key][s].get(m)) for s in seeds]
                pairs = [(x, y) for x, y in pairs if _numeric(x) and _numeric(y)]
                a = [x for x, _ in pairs]
                b = [y for _, y in pairs]
            else:
                a = [r.get(m) for r in ga[key].values() if _numeric(r.get(m))]
                b = [r.get(m) for r in gb[key].values() if _numeric(r.get(m))]
            if not a or not b:
                continue
            diff, lo, hi = bootstrap_difference(a, b, paired=paired, n_boot=n_boot, rng=rng)
            row = dict(zip(by, key))
            row.update(metric=m, mean_a=float(np.mean(a)), mean_b=float(np.mean(b)), diff_b_minus_a=diff,
                       ci95_low=lo, ci95_high=hi, n_a=len(a), n_b=len(b), paired=paired,
                       significant=bool(math.isfinite(lo) and (lo > 0 or hi < 0)))
            table.append(row)
    if not table:
        raise ValueError(f"by: the runs share no group of {by}; compare runs of the same experiment")
    out = Path(out) if out is not None else Path(run_b) / "compare"
    out.mkdir(parents=True, exist_ok=True)
    cols = by + ["metric", "mean_a", "mean_b", "diff_b_minus_a", "ci95_low", "ci95_high", "n_a", "n_b", "paired",
                 "significant"]
    write_csv_table(table, cols, out / "compare.csv")
    _plot(table, by, out / "compare.png")
    text = [f"# compare: B = {run_b} against A = {run_a}", "",
            f"A: {cfg_a.get('experiment', '?')} ({cfg_a.get('split', '?')} split, {cfg_a.get('size', '?')} size); "
            f"B: {cfg_b.get('experiment', '?')} ({cfg_b.get('split', '?')} split, {cfg_b.get('size', '?')} size).",
            f"Differences are B - A with 95 % percentile-bootstrap intervals over seeds ({n_boot} resamples, "
            "paired when both runs hold the same seeds); *significant*: the interval excludes 0.", "",
            markdown_table(table, cols), "", "![differences](compare.png)", ""]
    (out / "compare.md").write_text("\n".join(text))
    return out / "compare.md"


def _plot(table, by, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metrics = list(dict.fromkeys(r["metric"] for r in table))
    fig, axes = plt.subplots(len(metrics), 1, figsize=(7, 0.5 + 0.45 * len(table) / max(len(metrics), 1) + 1.2 * len(metrics)),
                             squeeze=False)
    for ax, m in zip(axes[:, 0], metrics):
        rows = [r for r in table if r["metric"] == m]
        y = np.arange(len(rows))
        d = np.array([r["diff_b_minus_a"] for r in rows])
        lo = np.array([r["ci95_low"] for r in rows])
        hi = np.array([r["ci95_high"] for r in rows])
        err = np.vstack([np.where(np.isfinite(lo), d - lo, 0), np.where(np.isfinite(hi), hi - d, 0)])
        ax.errorbar(d, y, xerr=err, fmt="o", capsize=3)
        ax.axvline(0, c="0.5", lw=1)
        ax.set_yticks(y, [", ".join(fmt(r[k]) for k in by) or "all" for r in rows], fontsize=7)
        ax.set_xlabel(f"{m}: B - A (95 % bootstrap CI)")
        ax.grid(alpha=0.3)
    fig.suptitle("differences between the runs, per group")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
