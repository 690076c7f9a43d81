"""ground_odometry: KITTI odometry errors of a VO on the simulated routes, per route and pooled.

Methods are ``vo`` plug-ins (``--set method=pkg.mod:Factory`` runs yours): ``u2``, ``w2``, ``u6``,
``w6`` (GroundVO, 2- or 6-parameter ground model, uniform or weighted RANSAC, ``downsample=1``, 3-D
integration) and ``mono`` (the monocular VISO2-M analogue: GroundVO's estimator with the scale read
once from the true speed, then held through the structure). The ``w6`` trial also reports the
oracle-scale bound (its own rotations, true step lengths) and every GroundVO trial the planar
re-integration of the same estimates. Errors: KITTI devkit segments of 100-800 m every 10 frames,
pooled over all segments of all routes. The quick routes (120 frames, about 54 m) hold no 100 m
segment: their tables show the non-standard scaled segments (L_j = j·L_max/8), labelled so.
Splits: ``dev`` the ten routes every parameter was chosen on (seed 0); ``test`` twelve held-out routes
(seeds >= 10,000, every ground family, three never tuned on), seed 10,000.
"""

import numpy as np

from polar_sim.experiments import _ground_common as G
from polar_sim.runner import Check, Experiment, Finding, get_method
from polar_sim.runner.report import savefig

TARGET_T_PCT, TARGET_R_DEGM, TARGET_MS = 2.0, 0.01, 15.0
OURS = ("u2", "w2", "u6", "w6", "mono")


def trial(params, seed, ctx):
    G.single_thread()
    from polar_sim import metrics
    from polar_sim.ground.integration import integrate
    from polar_sim.ground.replay import replay
    from polar_sim.metrics.ground import kitti_scores as _scores
    from polar_sim.metrics.ground import laplace_scale, oracle_step_speeds

    rec, tr = G.load(params, ctx)
    m = params["method"]
    kw = dict(downsample=1, integration="3d") if m in OURS else {}  # a user's VO gets the protocol only
    if m == "mono":
        kw["speed_truth"] = tr["speed_cd"]
    run = replay(get_method("vo", m)(tr["K"], tr["h"], seed=seed, **kw), rec.frames(keys=("rgb", "t")))
    est, n = run["poses"], len(rec)
    out = {"route_used": G.route_of(params, ctx), "length_m": tr["length_m"], "frames": n, **_scores(tr["gt"], est)}
    arrays = {"gt": tr["gt"], "est": est}
    if np.isfinite(run["speed"]).all() and np.isfinite(run["yaw_rate"]).all():
        rates = np.where(np.isfinite(run["rates_raw"]), run["rates_raw"], 0.0)
        rates[:, 1] = run["yaw_rate"]  # the filtered yaw rate, as the estimator integrates
        arrays["planar"] = integrate(run["times"], run["speed"], rates, "planar")
        out.update(_scores(tr["gt"], arrays["planar"], "planar_"))
        mid, ok = np.arange(n) - 1, np.isfinite(run["speed_raw"]) & (np.arange(n) >= 1)
        out["dv_raw"] = laplace_scale(run["speed_raw"][ok] - tr["speed_cd"][mid[ok]]) if ok.any() else float("nan")
        out["dv_filtered"] = laplace_scale(run["speed"][1:] - tr["speed_cd"][:-1])
        if m == "w6":
            arrays["oracle"] = integrate(run["times"], oracle_step_speeds(tr["t"], tr["step"]), rates, "3d")
            out.update(_scores(tr["gt"], arrays["oracle"], "oracle_"))
    out["cpu_ms_median"] = float(np.median(run["cpu_ms"][2:]))
    ctx.save_arrays("trajectories", **arrays)
    metrics.write_kitti(ctx.out_dir / f"{m.replace(':', '_')}_kitti.txt", est)
    metrics.write_kitti(ctx.out_dir / "gt_kitti.txt", tr["gt"])
    return out


def _pooled(table, ctx):
    """{label: dict(method, routes, t %, deg/m, t % scaled, deg/m scaled, CPU)} pooled over every route."""
    from polar_sim.metrics.ground import kitti_scores_pooled

    pairs = {}
    for r in table:
        z = ctx.arrays(r, "trajectories")
        for key, lab in (("est", r["method"]), ("planar", r["method"] + " planar"), ("oracle", "oracle scale")):
            if key in z:
                pairs.setdefault(lab, []).append((z["gt"], z[key]))
    cpu = {lab: [r["cpu_ms_median"] for r in table if r["method"] == lab] for lab in pairs}
    return {lab: dict(method=lab, **kitti_scores_pooled(ps), cpu_ms_median=float(np.median(cpu[lab])) if cpu[lab] else None)
            for lab, ps in pairs.items()}


def summarize(table, ctx):
    pooled = list(_pooled(table, ctx).values())
    cols = ["method", "routes", "t_pct", "r_degm", "t_pct_scaled", "r_degm_scaled", "cpu_ms_median"]
    rcols = ["route", "method", "length_m", "t_pct", "r_degm", "planar_t_pct", "t_pct_scaled", "r_degm_scaled", "ate_m",
             "oracle_t_pct", "dv_raw", "dv_filtered", "cpu_ms_median"]
    rows = sorted(table, key=lambda r: (r["route"], r["method"]))
    lines = [f"Split `{ctx.split}`, size `{ctx.size}`. KITTI devkit errors (segments of 100–800 m every 10 frames; "
             "`t_pct` %, `r_degm` deg/m) with 3-D integration, pooled over all segments of all routes; `*_scaled`: "
             "non-standard segments L_j = j·L_max/8 per route (the only ones a route under 100 m has); `planar`: the "
             "same estimates integrated in the plane. CPU: median ms of `process` per 621x188 frame, one thread.",
             "", G.table(pooled, cols), "", "Per route:", "", G.table(rows, rcols), ""]
    key = "t_pct_scaled" if ctx.quick else "t_pct"
    fig = G.plot_per_route(table, key, TARGET_T_PCT, "translation error (%)" + (
        ", scaled segments" if ctx.quick else ", 100–800 m segments"),
        f"KITTI translation error per route ({ctx.split} split, simulated routes)")
    lines += [savefig(fig, ctx.out_dir, "ground_odometry_errors")]
    return "\n".join(lines)


def checks(table, ctx):
    p = _pooled(table, ctx)
    if "w6" not in p or (ctx.quick and "mono" not in p):
        return []  # a run of other methods (e.g. a user's VO alone) has nothing to check against
    cpu = p["w6"]["cpu_ms_median"]
    if ctx.quick:  # 54 m from rest: the ordering on scaled segments; the targets at full size
        t, tm = p["w6"]["t_pct_scaled"], p["mono"]["t_pct_scaled"]
        # Measured on the held-out quick route (test_random_0, seed 10,000): w6 7.63 % against the
        # held-scale baseline's 1.31 %, recorded in RESULTS as a miss; not yet understood.
        return [Check("w6 beats the held-scale monocular baseline (quick: scaled segments)", t < tm,
                      f"{t:.2f} % vs {tm:.2f} %", known_miss=ctx.split == "test")]
    t, r = p["w6"]["t_pct"], p["w6"]["r_degm"]
    others = {m: p[m]["t_pct"] for m in OURS if m in p and m != "w6"}
    return [Check(f"w6 pooled translation error ≤ {TARGET_T_PCT} % ({ctx.split})", t <= TARGET_T_PCT, f"{t:.3f} %"),
            Check(f"w6 pooled rotation error ≤ {TARGET_R_DEGM} deg/m ({ctx.split})", r <= TARGET_R_DEGM, f"{r:.5f} deg/m"),
            Check("w6 has the lowest pooled translation error", all(t < v for v in others.values()),
                  "; ".join(f"{m} {v:.3f} %" for m, v in others.items())),
            Check(f"per-frame CPU ≤ {TARGET_MS} ms (621x188, median)", cpu <= TARGET_MS, f"{cpu:.1f} ms")]


def findings(table, ctx):
    p = _pooled(table, ctx)
    key, rkey = ("t_pct_scaled", "r_degm_scaled") if ctx.quick else ("t_pct", "r_degm")
    have = [m for m in ("w6", "u6", "w2", "u2") if m in p]
    ours = ", ".join(f"{m} {p[m][key]:.2f} %" for m in have + (["mono"] if "mono" in p else []))
    note = (f"{ctx.split} split, {len({r['route'] for r in table})} simulated routes"
            + ("; quick size: scaled segments of a 54 m route" if ctx.quick else "")
            + "; our monocular baseline is GroundVO with the scale held through the structure, not VISO2-M")
    out = []
    if len(have) == 4:
        six, two = p["w6"][key] < p["u6"][key], p["w2"][key] < p["u2"][key]
        worse = "mono" in p and p["mono"][key] > max(p[m][key] for m in have)
        order = six and two and p["u6"][key] < p["w2"][key]
        out.append(Finding("Ch. 4, KITTI table", "w6 6.21 < u6 7.01 < w2 7.15 < u2 7.19 %; VISO2-M 12.58 % worse", ours,
                           "held" if order and worse else "partly held" if six and worse else "not held",
                           note + (": the 2-parameter pair comes out reversed (w2 > u2)" if not two else "")))
        rs = [p[m][rkey] for m in have]
        out.append(Finding("Ch. 4, KITTI table", "rotation error equal across u2, w2, u6, w6",
                           ", ".join(f"{m} {p[m][rkey]:.4f} deg/m" for m in have),
                           "held" if max(rs) <= 1.1 * min(rs) else "not held", note + "; equal = within 10 %"))
    else:
        out.append(Finding("Ch. 4, KITTI table", "w6 < u6 < w2 < u2; VISO2-M worse", ours, "not tested the same way",
                           note + "; this size runs only " + ", ".join(sorted(p))))
    return out


EXPERIMENT = Experiment(
    name="ground_odometry",
    description="KITTI odometry errors of a VO (GroundVO u2/w2/u6/w6, the held-scale monocular baseline, or "
                "yours) on the simulated routes, per route and pooled, with an oracle-scale bound",
    grid={"route": list(G.DEV10), "method": list(OURS)},
    methods={"method": "vo"},
    splits={"dev": {"seeds": [0]}, "test": {"seeds": [10_000], "grid": {"route": list(G.TEST_ROUTES)}}},
    sizes={"quick": {"n_seeds": 1, "grid": {"route": ["quick"], "method": ["w6", "mono"]}}, "full": {}},
    trial=trial, summarize=summarize, checks=checks, findings=findings,
)
