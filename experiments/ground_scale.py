"""ground_scale: scale error ΔV_mean of the raw RANSAC speed, weighted vs uniform sampling.

The candidate sets and re-fitting protocol of ``ground_success`` (one online w6 pass per route collects
the RANSAC candidates and their learned P(ground); every condition re-fits RANSAC on the same
candidates, paired random numbers). Per frame with a fit, e = V_RANSAC − V_true, where V_true is the
central-difference camera speed at the middle frame (the flow is a central difference too); the
instantaneous speed is a second column. ΔV_mean is the maximum-likelihood Laplace scale b = mean |e|
(dissertation Eq. 4.15). One row per (config, sampling, N, seed).

Data and splits as ``ground_success``; 10 repetitions (dev seeds 0-9, test 10,000-10,009); the quick
size uses 5 repetitions and 4 iteration counts of the quick route.
"""

import numpy as np

from polar_sim.experiments import _ground_candidates as C
from polar_sim.experiments import _ground_common as G
from polar_sim.experiments import _ground_pictures as pictures
from polar_sim.runner import Check, Experiment, Finding
from polar_sim.runner.report import savefig


def trial(params, seed, ctx):
    from polar_sim.metrics.ground import laplace_scale

    data = C.data_of(params, ctx)
    _, inliers, V = C.refit(data, config=params["config"], sampling=params["sampling"], n_iter=params["n_iter"], seed=seed)
    v_cd, v_inst = np.array([d["speed_cd"] for d in data]), np.array([d["speed"] for d in data])
    ok = np.isfinite(V)
    nan = float("nan")
    return {"n_frames": len(data), "dv": laplace_scale(V[ok] - v_cd[ok]) if ok.any() else nan,
            "dv_inst": laplace_scale(V[ok] - v_inst[ok]) if ok.any() else nan,
            "bias": float(np.mean(V[ok] - v_cd[ok])) if ok.any() else nan, "fit_share": float(ok.mean()),
            "inl10_share": float(np.mean([m.sum() >= 10 for m in inliers]))}


def _rows(table):
    rows = []
    for cfg in [c for c in C.CONFIGS if any(r["config"] == c for r in table)]:
        for n in sorted({r["n_iter"] for r in table if r["config"] == cfg}):
            sel = {s: {r["seed"]: r for r in table if r["config"] == cfg and r["sampling"] == s and r["n_iter"] == n}
                   for s in ("uniform", "weighted")}
            both = sorted(set(sel["uniform"]) & set(sel["weighted"]))
            if not both:
                continue

            def mean(s, k):
                return float(np.mean([sel[s][i][k] for i in both]))

            rows.append(dict(config=cfg, n_iter=n, dv_uniform=mean("uniform", "dv"), dv_weighted=mean("weighted", "dv"),
                             dv_inst_uniform=mean("uniform", "dv_inst"), dv_inst_weighted=mean("weighted", "dv_inst"),
                             bias_uniform=mean("uniform", "bias"), bias_weighted=mean("weighted", "bias"),
                             seeds_w_better=f"{sum(sel['weighted'][i]['dv'] < sel['uniform'][i]['dv'] for i in both)}/{len(both)}",
                             fit_share=mean("weighted", "fit_share"), inl10_share_u=mean("uniform", "inl10_share"),
                             inl10_share_w=mean("weighted", "inl10_share")))
    return rows


def summarize(table, ctx):
    rows = _rows(table)
    lines = [f"Split `{ctx.split}`: {table[0]['n_frames']} frames; {len({r['seed'] for r in table})} repetitions. "
             "ΔV_mean (m/s) = mean |V_RANSAC − V_true| per repetition, averaged over repetitions; `dv` against the "
             "central-difference speed of the middle frame, `dv_inst` against the instantaneous speed; `bias`: mean "
             "signed error; `seeds_w_better`: paired repetitions with a lower ΔV_mean for weighted; `fit_share`: frames "
             "with a model; `inl10_share`: frames with ≥ 10 inliers (a scale the estimator accepts).", "",
             G.table(rows, list(rows[0]) if rows else []), ""]
    cfgs = [c for c in C.CONFIGS if any(r["config"] == c for r in rows)]
    lines.append(savefig(pictures.scale_errorbars(table, cfgs, ctx.split, C.model_label), ctx.out_dir, "ground_scale_dv"))
    return "\n".join(lines)


def checks(table, ctx):
    out = []
    for cfg in [c for c in C.CONFIGS if any(r["config"] == c for r in table)]:
        rs = [r for r in _rows(table) if r["config"] == cfg]
        out.append(Check(f"weighted beats uniform in ΔV_mean at every N ({cfg}, {ctx.split})",
                         bool(rs) and all(r["dv_weighted"] < r["dv_uniform"] for r in rs),
                         "; ".join(f"N={r['n_iter']}: {r['dv_weighted']:.4f} vs {r['dv_uniform']:.4f} m/s" for r in rs)))
    return out


def findings(table, ctx):
    rows = _rows(table)
    won = [r for r in rows if r["dv_weighted"] < r["dv_uniform"]]
    lost = "; ".join(f"{r['config']} N={r['n_iter']}: {r['dv_weighted']:.3f} vs {r['dv_uniform']:.3f} m/s"
                     for r in rows if r not in won)
    return [Finding("Ch. 4, Fig. 4.8", "ΔV_mean of weighted RANSAC is below uniform",
                    f"lower in {len(won)}/{len(rows)} (config, N) cells" + (f"; not in {lost}" if lost else ""),
                    "held" if len(won) == len(rows) else "partly held" if won else "not held",
                    f"{ctx.split} split, simulated routes; V_true is the central-difference speed of the middle frame")]


EXPERIMENT = Experiment(
    name="ground_scale",
    description="scale error ΔV_mean (Laplace scale of the raw RANSAC speed error): weighted vs uniform sampling",
    grid={"data": ["dev10"], "config": list(C.CONFIGS), "sampling": ["uniform", "weighted"], "n_iter": list(C.ITERATIONS)},
    splits={"dev": {"seeds": range(10)}, "test": {"seeds": range(10_000, 10_010), "grid": {"data": ["test12"]}}},
    choices={"data": ["quick", *C.DATASETS]},
    sizes={"quick": {"n_seeds": 5, "grid": {"data": ["quick"], "config": ["2p", "6p_lam0.1"], "n_iter": [1, 4, 16, 55]}},
           "full": {}},
    trial=trial, summarize=summarize, checks=checks, findings=findings,
)
