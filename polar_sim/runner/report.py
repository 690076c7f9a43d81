"""Helpers for experiment summaries (tables, grouped statistics, figures) and the combined report."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

__all__ = ["markdown_table", "group_rows", "fmt", "savefig", "write_csv_table", "build_report"]


def fmt(x, digits=4):
    """Compact number formatting for tables."""
    if x is None:
        return ""
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        if math.isnan(x):
            return "nan"
        if x != 0 and (abs(x) < 1e-3 or abs(x) >= 1e5):
            return f"{x:.{digits - 1}e}"
        return f"{x:.{digits}g}"
    return str(x)


def markdown_table(rows, columns, headers=None):
    """A markdown table of ``rows`` (dicts) restricted to ``columns``."""
    headers = headers or columns
    out = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        out.append("| " + " | ".join(fmt(r.get(c)) for c in columns) + " |")
    return "\n".join(out)


def write_csv_table(rows, columns, path):
    """The same table as CSV."""
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for r in rows:
            w.writerow([r.get(c, "") for c in columns])


def group_rows(rows, by, metrics, stats=("mean",)):
    """Aggregate metrics over rows sharing the values of ``by``.

    ``stats`` names numpy reductions: "mean", "median", "std", "min", "max", "p90", "p99", "n".
    Returns a list of dicts ``{by..., f"{metric}_{stat}": value}`` in first-seen order.
    """
    groups = {}
    for r in rows:
        key = tuple(r.get(b) for b in by)
        groups.setdefault(key, []).append(r)
    out = []
    for key, rs in groups.items():
        d = dict(zip(by, key))
        for m in metrics:
            vals = np.array([r[m] for r in rs if isinstance(r.get(m), (int, float)) and r.get(m) is not None], float)
            for s in stats:
                name = f"{m}_{s}" if len(stats) > 1 or s != "mean" else m
                if s == "n":
                    d[name] = int(len(vals))
                elif len(vals) == 0:
                    d[name] = float("nan")
                elif s.startswith("p"):
                    d[name] = float(np.percentile(vals, float(s[1:])))
                else:
                    d[name] = float(getattr(np, s)(vals))
        out.append(d)
    return out


def savefig(fig, out_dir, name):
    """Save a matplotlib figure as PNG into ``out_dir`` and return the markdown image line."""
    path = Path(out_dir) / f"{name}.png"
    fig.savefig(path, dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return f"![{name}]({path.name})"


def build_report(results, out_dir):
    """One markdown report for several runs: a table of their checks, then each run's summary
    with headings demoted a level and figure links rewritten to the run folder.

    ``results`` is a list of ``RunResult``; returns the path of ``report.md``.
    """
    out_dir = Path(out_dir)

    def rel(p):
        p = Path(p)
        return p.relative_to(out_dir) if p.is_relative_to(out_dir) else p

    lines = ["# polar_sim report", "", "| experiment | checks passed | trials | folder |", "|---|---|---|---|"]
    for r in results:
        name = json.loads((r.out_dir / "config.json").read_text())["experiment"]
        n_ok = sum(c.passed for c in r.checks)
        lines.append(f"| {name} | {n_ok}/{len(r.checks)} | {len(r.table)} | {rel(r.out_dir)} |")
    for r in results:
        text = (r.out_dir / "summary.md").read_text()
        text = re.sub(r"^(#+) ", r"#\1 ", text, flags=re.M)
        text = re.sub(r"!\[([^\]]*)\]\((?!http)([^)]+)\)", lambda m: f"![{m[1]}]({rel(r.out_dir)}/{m[2]})", text)
        lines += ["", text]
    path = out_dir / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path
