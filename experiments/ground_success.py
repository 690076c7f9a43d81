"""ground_success: RANSAC success rate ps against iterations, weighted vs uniform sampling (spec §8.2–8.3).

Protocol (spec §8.2, dissertation Fig. 4.7): one online w6 pass of ``GroundVO`` over each route gives,
per frame, the RANSAC candidates (level-frame u, v and d̄), the learned P(ground) that weights them,
and their true ground label (the route's ground mask at the candidate's middle-frame pixel). Every
condition (model, lambda, sampling, iterations) then re-fits RANSAC on exactly these candidates, one
repetition per seed; uniform and weighted draws of one seed share their random numbers. ps is the
share of true-ground candidates that RANSAC returns as inliers, pooled over the frames of one
repetition (with precision and F1). The boxplots are over repetitions, and ps(N) = p_max − (p_max −
p_0)·p^N is fitted over all (N, ps) pairs (spec §8.3).

Full size: 100 equally spaced frames (after a 3 s warm-up) of each of the ten routes, 30 repetitions;
2-parameter model {1, 2, 4, 8, 16} iterations, 6-parameter model {5, 11, 25, 55, 125} with lambda in
{1, 0.1, 0.01}. Quick size: every frame after the warm-up of the first 120 frames of terrain_00, the
2-parameter model and the 6-parameter model with lambda 0.1, 10 repetitions.
"""

import numpy as np

from polar_sim.experiments import _ground_common as G
from polar_sim.runner import Check, Experiment
from polar_sim.runner.report import fmt, markdown_table, savefig, write_csv_table

ALL_N = sorted(set(G.ITERATIONS["2param"]) | set(G.ITERATIONS["6param"]))


def trial(params, seed, ctx):
    G.single_thread()
    from polar_sim.metrics.ground import ground_success

    routes, frames, n_pick = G.DATASETS[params["data"]]
    data = G.candidate_set(routes, frames, n_pick)
    model, lam = G.CONFIGS[params["config"]]
    out = {"n_frames": len(data), "n_candidates": int(sum(len(d["u"]) for d in data)),
           "ground_share": float(np.mean(np.concatenate([d["label"] for d in data])))}
    for n in G.ITERATIONS[model]:
        labels, inliers, _ = G.refit(data, model=model, sampling=params["sampling"], n_iter=n, lam=lam, seed=seed)
        s = ground_success(labels, inliers)
        out[f"ps_{n}"], out[f"precision_{n}"], out[f"f1_{n}"] = s.ps, s.precision, s.f1
    return out


def _values(table, config, sampling, n):
    return np.array([r[f"ps_{n}"] for r in table if r["config"] == config and r["sampling"] == sampling
                     and isinstance(r.get(f"ps_{n}"), float)], dtype=float)


def _paired(table, config, n):
    """ps(weighted) − ps(uniform) per seed, for the seeds that have both."""
    u = {r["seed"]: r[f"ps_{n}"] for r in table if r["config"] == config and r["sampling"] == "uniform"}
    w = {r["seed"]: r[f"ps_{n}"] for r in table if r["config"] == config and r["sampling"] == "weighted"}
    return np.array([w[s] - u[s] for s in sorted(set(u) & set(w))], dtype=float)


def _configs(table):
    return [c for c in G.CONFIGS if any(r["config"] == c for r in table)]


def _rows(table):
    from scipy.stats import wilcoxon

    rows = []
    for cfg in _configs(table):
        model = G.CONFIGS[cfg][0]
        for n in G.ITERATIONS[model]:
            u, w = _values(table, cfg, "uniform", n), _values(table, cfg, "weighted", n)
            if not len(u) or not len(w):
                continue
            d = _paired(table, cfg, n)
            p = float(wilcoxon(d).pvalue) if len(d) >= 6 and np.any(d != 0) else float("nan")
            prec = {s: np.mean([r[f"precision_{n}"] for r in table if r["config"] == cfg and r["sampling"] == s])
                    for s in ("uniform", "weighted")}
            rows.append(dict(config=cfg, n_iter=n, ps_uniform=u.mean(), ps_uniform_std=u.std(),
                             ps_weighted=w.mean(), ps_weighted_std=w.std(), diff=w.mean() - u.mean(),
                             seeds_w_better=f"{int((d > 0).sum())}/{len(d)}", wilcoxon_p=p,
                             precision_uniform=prec["uniform"], precision_weighted=prec["weighted"]))
    return rows


def summarize(table, ctx):
    out_dir, quick = ctx.out_dir, ctx.quick
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from polar_sim.metrics.ground import fit_success_curve

    rows = _rows(table)
    cols = ["config", "n_iter", "ps_uniform", "ps_uniform_std", "ps_weighted", "ps_weighted_std", "diff",
            "seeds_w_better", "wilcoxon_p", "precision_uniform", "precision_weighted"]
    write_csv_table(rows, cols, out_dir / "ground_success_table.csv")
    r0 = table[0]
    lines = [f"Candidate set `{r0['data']}`: {r0['n_frames']} frames, {r0['n_candidates']} RANSAC candidates, "
             f"{100 * r0['ground_share']:.1f} % of them on true ground; {len({r['seed'] for r in table})} "
             "repetitions (seeds). ps = recall of true-ground candidates among the RANSAC inliers (spec §8.2), "
             "mean ± std over repetitions; `seeds_w_better`: repetitions in which weighted beat uniform "
             "(paired: same random numbers); `wilcoxon_p`: two-sided signed-rank test of the paired "
             "differences.", "", markdown_table(rows, cols), ""]

    fits = []
    cfgs = _configs(table)
    fig, axes = plt.subplots(1, len(cfgs), figsize=(4.2 * len(cfgs), 3.6), squeeze=False)
    for ax, cfg in zip(axes[0], cfgs):
        model, lam = G.CONFIGS[cfg]
        ns = G.ITERATIONS[model]
        pos = np.log(ns)  # boxes and curves on a log-N axis
        half = 0.16 * float(np.min(np.diff(pos)))
        for k, (samp, col) in enumerate((("uniform", "tab:blue"), ("weighted", "tab:red"))):
            vals = [_values(table, cfg, samp, n) for n in ns]
            bp = ax.boxplot(vals, positions=pos + (2 * k - 1) * half, widths=1.6 * half, patch_artist=True,
                            showfliers=True, flierprops=dict(markersize=2), manage_ticks=False)
            for b in bp["boxes"]:
                b.set(facecolor=col, alpha=0.35, edgecolor=col)
            for med in bp["medians"]:
                med.set(color=col)
            allN = np.concatenate([[n] * len(v) for n, v in zip(ns, vals)])
            allp = np.concatenate(vals)
            try:
                fc = fit_success_curve(allN, allp)
            except ValueError:
                continue
            fits.append(dict(config=cfg, sampling=samp, p_max=fc.p_max, p_0=fc.p_0, p=fc.p, n95=fc.n95))
            nn = np.geomspace(ns[0] * 0.8, ns[-1] * 1.25, 200)
            ax.plot(np.log(nn), fc(nn), color=col, lw=1.2, label=f"{samp}: p_max {fc.p_max:.3f}, p {fc.p:.3f}")
        ax.set_xticks(pos, [str(n) for n in ns])
        ax.set_xlabel("RANSAC iterations N")
        ax.set_ylabel("ps")
        ax.set_title(f"{'2-parameter' if model == '2param' else '6-parameter, λ = ' + fmt(lam)}")
        ax.legend(fontsize=7, loc="lower right")
        ax.grid(alpha=0.3)
    fig.suptitle("RANSAC success rate ps: uniform (blue) vs weighted (red) sampling; curves: fitted "
                 "ps(N) = p_max − (p_max − p_0)·p^N", fontsize=9)
    fig.tight_layout()
    lines += [savefig(fig, out_dir, "ground_success_ps"), ""]
    fcols = ["config", "sampling", "p_max", "p_0", "p", "n95"]
    write_csv_table(fits, fcols, out_dir / "ground_success_fits.csv")
    lines += ["Fitted ps(N) = p_max − (p_max − p_0)·p^N over all repetitions (spec §8.3); n95: iterations to "
              "reach 95 % of p_max.", "", markdown_table(fits, fcols), "",
              "Tables: `ground_success_table.csv`, `ground_success_fits.csv`."]
    return "\n".join(lines)


def checks(table, ctx):
    quick = ctx.quick
    rows = _rows(table)
    out = []
    for cfg in _configs(table):
        rs = [r for r in rows if r["config"] == cfg]
        ok = bool(rs) and all(r["ps_weighted"] > r["ps_uniform"] for r in rs)
        detail = "; ".join(f"N={r['n_iter']}: {r['ps_weighted']:.4f} vs {r['ps_uniform']:.4f}" for r in rs)
        out.append(Check(f"weighted beats uniform in mean ps at every iteration count ({cfg})", ok, detail))
    return out


EXPERIMENT = Experiment(
    name="ground_success",
    description="RANSAC ground success rate ps vs iterations: weighted vs uniform sampling, 2- and 6-parameter "
                "models (spec §8.2-8.3)",
    grid={"data": ["routes10"], "config": list(G.CONFIGS), "sampling": ["uniform", "weighted"]},
    splits={"dev": {"seeds": range(30)}},
    sizes={"quick": {"n_seeds": 10, "grid": {"data": ["quick"], "config": ["2p", "6p_lam0.1"], "sampling": ["uniform", "weighted"]}}, "full": {}},
    trial=trial,
    summarize=summarize,
    checks=checks,
)
