"""ground_success: RANSAC success rate ps against iterations, weighted vs uniform sampling.

Protocol (dissertation Fig. 4.7): one online w6 pass of ``GroundVO`` per route gives, per frame, the
RANSAC candidates (level-frame u, v and d̄), the learned P(ground) that weights them and their true
ground label at the middle frame. Every condition (model and lambda, sampling, iterations N) re-fits
RANSAC on exactly these candidates, one repetition per seed; the uniform and weighted draws of a
seed share their random numbers. ps is the share of true-ground candidates that RANSAC returns as
inliers, pooled over the frames of a repetition (with precision and F1). One row per (config,
sampling, N, seed); ps(N) = p_max − (p_max − p_0)·p^N is fitted over all rows of a curve.

Data: ``dev10`` (100 equally spaced frames of each of the ten dev routes, seeds 0-29) on the dev split,
``test12`` (the twelve held-out routes, seeds 10,000-10,029) on the test split; the quick size takes
every frame after the warm-up of the split's 120-frame quick route, 10 seeds and 4 iteration counts.
"""

import numpy as np

from polar_sim.experiments import _ground_candidates as C
from polar_sim.experiments import _ground_common as G
from polar_sim.experiments import _ground_pictures as pictures
from polar_sim.runner import Check, Experiment, Finding
from polar_sim.runner.report import savefig


def trial(params, seed, ctx):
    from polar_sim.metrics.ground import ground_success

    data = C.data_of(params, ctx)
    labels, inliers, _ = C.refit(data, config=params["config"], sampling=params["sampling"], n_iter=params["n_iter"],
                                 seed=seed)
    s = ground_success(labels, inliers)
    return {"n_frames": len(data), "n_candidates": int(sum(len(d["u"]) for d in data)),
            "ground_share": float(np.mean(np.concatenate([d["label"] for d in data]))),
            "ps": s.ps, "precision": s.precision, "f1": s.f1}


def _by(table, config, sampling, n):
    return {r["seed"]: r for r in table if r["config"] == config and r["sampling"] == sampling and r["n_iter"] == n}


def _rows(table):
    from scipy.stats import wilcoxon

    rows = []
    for cfg in [c for c in C.CONFIGS if any(r["config"] == c for r in table)]:
        for n in sorted({r["n_iter"] for r in table if r["config"] == cfg}):
            u, w = _by(table, cfg, "uniform", n), _by(table, cfg, "weighted", n)
            both = sorted(set(u) & set(w))
            if not both:
                continue
            pu, pw = np.array([u[s]["ps"] for s in both]), np.array([w[s]["ps"] for s in both])
            d = pw - pu
            p = float(wilcoxon(d).pvalue) if len(d) >= 6 and np.any(d != 0) else float("nan")
            rows.append(dict(config=cfg, n_iter=n, ps_uniform=pu.mean(), ps_uniform_std=pu.std(), ps_weighted=pw.mean(),
                             ps_weighted_std=pw.std(), diff=d.mean(), seeds_w_better=f"{int((d > 0).sum())}/{len(d)}",
                             wilcoxon_p=p, precision_uniform=np.mean([u[s]["precision"] for s in both]),
                             precision_weighted=np.mean([w[s]["precision"] for s in both])))
    return rows


def _fits(table):
    from polar_sim.metrics.ground import fit_success_curve

    out = {}
    for cfg in C.CONFIGS:
        for samp in ("uniform", "weighted"):
            rs = [r for r in table if r["config"] == cfg and r["sampling"] == samp]
            if len({r["n_iter"] for r in rs}) >= 3:
                out[(cfg, samp)] = fit_success_curve([r["n_iter"] for r in rs], [r["ps"] for r in rs])
    return out


def summarize(table, ctx):
    rows, fits = _rows(table), _fits(table)
    r0 = table[0]
    lines = [f"Split `{ctx.split}`: {r0['n_frames']} frames, {r0['n_candidates']} RANSAC candidates "
             f"({100 * r0['ground_share']:.1f} % on true ground), {len({r['seed'] for r in table})} repetitions. ps: "
             "recall of the true-ground candidates among the inliers, mean ± std over repetitions; `seeds_w_better`: "
             "paired repetitions in which weighted beat uniform; `wilcoxon_p`: signed-rank test of the pairs.", "",
             G.table(rows, list(rows[0]) if rows else [],
                     {"wilcoxon_p": "the signed-rank test needs ≥ 6 paired repetitions and a nonzero difference"}), ""]
    cfgs = sorted({c for c, _ in fits}, key=list(C.CONFIGS).index)
    fig = pictures.success_boxplots(table, fits, cfgs, ctx.split, C.model_label)
    fit_rows = [dict(config=c, sampling=s, p_max=f.p_max, p_0=f.p_0, p=f.p, n95=f.n95) for (c, s), f in fits.items()]
    lines += [savefig(fig, ctx.out_dir, "ground_success_ps"), "", "Fitted curves (n95: iterations to 95 % of p_max):",
              "", G.table(fit_rows, ["config", "sampling", "p_max", "p_0", "p", "n95"])]
    return "\n".join(lines)


def checks(table, ctx):
    out = []
    for cfg in [c for c in C.CONFIGS if any(r["config"] == c for r in table)]:
        rs = [r for r in _rows(table) if r["config"] == cfg]
        out.append(Check(f"weighted beats uniform in mean ps at every N ({cfg}, {ctx.split})",
                         bool(rs) and all(r["ps_weighted"] > r["ps_uniform"] for r in rs),
                         "; ".join(f"N={r['n_iter']}: {r['ps_weighted']:.4f} vs {r['ps_uniform']:.4f}" for r in rs)))
    return out


def findings(table, ctx):
    rows, fits = _rows(table), _fits(table)
    won = [r for r in rows if r["ps_weighted"] > r["ps_uniform"]]
    pairs = [int(r["seeds_w_better"].split("/")[0]) == int(r["seeds_w_better"].split("/")[1]) for r in rows]
    n95 = [(c, fits[(c, "weighted")].n95, fits[(c, "uniform")].n95) for c in C.CONFIGS
           if (c, "weighted") in fits and (c, "uniform") in fits]
    note = f"{ctx.split} split, simulated routes; our candidates come from a KLT front end, not libviso2"
    return [Finding("Ch. 4, Fig. 4.7", "weighted RANSAC reaches a higher ps than uniform at every N",
                    f"higher mean ps in {len(won)}/{len(rows)} (config, N) cells; every paired repetition in "
                    f"{sum(pairs)}/{len(rows)}", "held" if len(won) == len(rows) else "partly held" if won else "not held", note),
            Finding("Ch. 4, Fig. 4.7", "weighted sampling needs fewer iterations to reach 95 % of p_max",
                    "; ".join(f"{c}: {w:.1f} vs {u:.1f}" for c, w, u in n95) + " iterations (weighted vs uniform)",
                    "held" if all(w < u for _, w, u in n95) else "partly held" if any(w < u for _, w, u in n95)
                    else "not held", note)]


EXPERIMENT = Experiment(
    name="ground_success",
    description="RANSAC ground success rate ps vs iterations: weighted vs uniform sampling, 2- and 6-parameter "
                "models, re-fitted on the candidates of one online pass per route",
    grid={"data": ["dev10"], "config": list(C.CONFIGS), "sampling": ["uniform", "weighted"], "n_iter": list(C.ITERATIONS)},
    splits={"dev": {"seeds": range(30)}, "test": {"seeds": range(10_000, 10_030), "grid": {"data": ["test12"]}}},
    choices={"data": ["quick", *C.DATASETS]},
    sizes={"quick": {"n_seeds": 10, "grid": {"data": ["quick"], "config": ["2p", "6p_lam0.1"], "n_iter": [1, 4, 16, 55]}},
           "full": {}},
    trial=trial, summarize=summarize, checks=checks, findings=findings,
)
