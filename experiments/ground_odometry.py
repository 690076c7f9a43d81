"""ground_odometry: KITTI odometry errors of a VO on the simulated routes, per route and pooled.

Methods are ``vo`` plug-ins (``--set method=pkg.mod:Factory`` runs yours): ``u2``, ``w2``, ``u6``,
``w6`` (GroundVO, 2- or 6-parameter ground model, uniform or weighted RANSAC, ``downsample=1``, 3-D
integration) and ``mono`` (the monocular VISO2-M analogue: GroundVO's estimator with the scale read
once from the true speed, then held through the structure). The ``w6`` trial also reports the
oracle-scale bound (its own rotations, true step lengths) and every GroundVO trial the planar
re-integration of the same estimates. Errors: KITTI devkit segments of 100-800 m every 10 frames,
pooled over all segments of all routes. Routes under 100 m (the quick size's, cut to the first
``max_frames`` = 120 frames, 54-65 m) hold no 100 m segment: their tables, checks and findings use
the non-standard scaled segments (L_j = j·L_max/8), labelled so.
Splits: ``dev`` the ten routes every parameter was chosen on (seed 0); ``test`` twelve held-out routes
(seeds >= 10,000, every ground family, three never tuned on), seed 10,000.
"""

import numpy as np

from polar_sim.experiments import _ground_common as G
from polar_sim.experiments import _ground_pictures as pictures
from polar_sim.runner import Check, Experiment, Finding, get_method
from polar_sim.runner.report import savefig

TARGET_T_PCT, TARGET_R_DEGM, TARGET_MS = 2.0, 0.01, 15.0
OURS = ("u2", "w2", "u6", "w6", "mono")
RECORDED_ROTATION_MISSES = ("test_checker", "test_random_2")  # w6 rotation misses recorded in RESULTS (test, full)
PUBLISHED = "w6 6.21 < u6 7.01 < w2 7.15 < u2 7.19 %; VISO2-M 12.58 % worse"  # translation error, KITTI table


def trial(params, seed, ctx):
    G.single_thread()
    from polar_sim import metrics
    from polar_sim.ground.integration import integrate
    from polar_sim.ground.replay import replay
    from polar_sim.metrics.ground import kitti_scores as _scores
    from polar_sim.metrics.ground import oracle_step_speeds, speed_error_scales

    rec, tr = G.load(params, ctx)
    m = params["method"]
    kw = dict(G.rover_vo_params(tr), integration="3d") if m in OURS else {}  # a user's VO gets the protocol only
    if m == "mono":
        kw["speed_truth"] = tr["speed_cd"]
    run = replay(get_method("vo", m)(tr["K"], tr["h"], seed=seed, **kw), rec.frames(keys=("rgb", "t")))
    est = run["poses"]
    out = {"route_used": G.route_of(params, ctx), "length_m": tr["length_m"], "frames": len(rec), **_scores(tr["gt"], est)}
    arrays = {"gt": tr["gt"], "est": est}
    if np.isfinite(run["speed"]).all() and np.isfinite(run["yaw_rate"]).all():
        rates = np.where(np.isfinite(run["rates_raw"]), run["rates_raw"], 0.0)
        rates[:, 1] = run["yaw_rate"]  # the filtered yaw rate, as the estimator integrates
        arrays["planar"] = integrate(run["times"], run["speed"], rates, "planar")
        out.update(_scores(tr["gt"], arrays["planar"], "planar_"))
        out["dv_raw"], out["dv_filtered"] = speed_error_scales(run["speed_raw"], run["speed"], tr["speed_cd"])
        if m == "w6":
            arrays["oracle"] = integrate(run["times"], oracle_step_speeds(tr["t"], tr["step"]), rates, "3d")
            out.update(_scores(tr["gt"], arrays["oracle"], "oracle_"))
    out["cpu_ms_median"] = float(np.median(run["cpu_ms"][2:]))
    ctx.save_arrays("trajectories", **arrays)
    metrics.write_kitti(ctx.out_dir / f"{m.replace(':', '_')}_kitti.txt", est)
    metrics.write_kitti(ctx.out_dir / "gt_kitti.txt", tr["gt"])
    return out


def summarize(table, ctx):
    pooled = list(G.pooled_odometry(table, ctx).values())
    cols = ["method", "routes", "t_pct", "r_degm", "t_pct_scaled", "r_degm_scaled", "cpu_ms_median"]
    rcols = ["route", "method", "length_m", "t_pct", "r_degm", "planar_t_pct", "t_pct_scaled", "r_degm_scaled", "ate_m",
             "oracle_t_pct", "dv_raw", "dv_filtered", "cpu_ms_median"]
    rows = sorted(table, key=lambda r: (r["route"], r["method"]))
    why = G.why_absent(table)
    lines = [f"Split `{ctx.split}`, size `{ctx.size}`. KITTI devkit errors (segments of 100–800 m every 10 frames; "
             "`t_pct` %, `r_degm` deg/m) with 3-D integration, pooled over all segments of all routes; `*_scaled`: "
             "non-standard segments L_j = j·L_max/8 per route (the only ones a route under 100 m has); `planar`: the "
             "same estimates integrated in the plane. CPU: median ms of `process` per 621x188 frame, one thread.",
             "", G.table(pooled, cols, why), "", "Per route:", "", G.table(rows, rcols, why), ""]
    key, _, seg, _ = G.segments(table)
    fig = pictures.per_route_bars(table, key, TARGET_T_PCT, f"translation error (%), {seg}",
                                  f"KITTI translation error per route ({ctx.split} split, simulated routes)")
    return "\n".join(lines + [savefig(fig, ctx.out_dir, "ground_odometry_errors")])


def checks(table, ctx):
    p = G.pooled_odometry(table, ctx)
    key, _, seg, _ = G.segments(table)
    if "w6" not in p or (key != "t_pct" and "mono" not in p):
        return []  # a run of other methods (e.g. a user's VO alone) has nothing to check against
    cpu = p["w6"]["cpu_ms_median"]
    if key != "t_pct":  # routes under 100 m (e.g. 54 m from rest): the ordering on scaled segments
        t, tm = p["w6"][key], p["mono"][key]
        # Measured on the held-out quick route (test_random_0, seed 10,000): w6 7.63 % against the
        # held-scale baseline's 1.31 %, recorded in RESULTS as a miss; not yet understood.
        return [Check(f"w6 beats the held-scale monocular baseline ({seg})", t < tm,
                      f"{t:.2f} % vs {tm:.2f} %", known_miss=ctx.split == "test")]
    t, r = p["w6"]["t_pct"], p["w6"]["r_degm"]
    others = {m: p[m]["t_pct"] for m in OURS if m in p and m != "w6"}
    per_route = {row["route"]: row["r_degm"] for row in table if row["method"] == "w6"}
    over = sorted(k for k, v in per_route.items() if not v <= TARGET_R_DEGM)
    # RESULTS (issue 35, test split, fifth pass: the rover's sideways slip): 1.65 %, 0.0068 deg/m; checker 0.0174 and
    # random_2 0.0112 deg/m (0.0099 before the slip).
    return [Check(f"w6 pooled translation error ≤ {TARGET_T_PCT} % ({ctx.split})", t <= TARGET_T_PCT, f"{t:.3f} %"),
            Check(f"w6 pooled rotation error ≤ {TARGET_R_DEGM} deg/m ({ctx.split})", r <= TARGET_R_DEGM, f"{r:.5f} deg/m"),
            Check(f"w6 rotation error ≤ {TARGET_R_DEGM} deg/m on every route ({ctx.split})", not over,
                  "; ".join(f"{k} {per_route[k]:.4f}" for k in over) or f"worst {max(per_route.values()):.5f} deg/m",
                  known_miss=bool(over) and set(over) <= set(RECORDED_ROTATION_MISSES)),
            Check("w6 has the lowest pooled translation error", all(t < v for v in others.values()),
                  "; ".join(f"{m} {v:.3f} %" for m, v in others.items()), known_miss=ctx.split == "test"),
            Check(f"per-frame CPU ≤ {TARGET_MS} ms (621x188, median)", cpu <= TARGET_MS, f"{cpu:.1f} ms", timing=True)]


def findings(table, ctx):
    p = G.pooled_odometry(table, ctx)
    key, rkey, _, seg = G.segments(table)
    have = [m for m in ("w6", "u6", "w2", "u2") if m in p]
    n = len({r["route"] for r in table})
    note = (f"{ctx.split} split, {n} simulated route{'s' if n != 1 else ''}, {seg}; VISO2-M is not run here: "
            "`mono` is GroundVO with the scale read once from the true speed, then held through the structure")
    if len(have) < 4:
        ours = ", ".join(f"{m} {p[m][key]:.2f} %" for m in have + (["mono"] if "mono" in p else []))
        return [Finding("Ch. 4, KITTI table", PUBLISHED, ours or "none of u2, w2, u6, w6 run", "not tested the same way",
                        note + "; this run has only " + ", ".join(sorted(p)))]
    v = {m: p[m][key] for m in have}
    six, two = v["w6"] < v["u6"], v["w2"] < v["u2"]
    order = six and two and v["u6"] < v["w2"]
    mono = p["mono"][key] if "mono" in p else None
    worse = mono is not None and mono > max(v.values())
    ours = [" < ".join(f"{m} {v[m]:.2f}" for m in sorted(have, key=v.get)) + " %"]
    ours += [] if six else ["our ordering reverses the 6-parameter pair (w6 > u6)"]
    ours += [] if two else ["our ordering reverses the 2-parameter pair (w2 > u2)"]
    ours += [f"our monocular baseline differs from VISO2-M (held-scale GroundVO): {mono:.2f} %, "
             + ("worse than all four" if worse else "not worse than all four")] if mono is not None else \
        ["no monocular baseline run: the VISO2-M part is not tested"]
    verdict = "held" if order and worse else "partly held" if six or two or worse else "not held"
    rs = {m: p[m][rkey] for m in have}
    return [Finding("Ch. 4, KITTI table", PUBLISHED, "; ".join(ours), verdict, note, n=n, n_of="routes"),
            Finding("Ch. 4, KITTI table", "rotation error equal across u2, w2, u6, w6",
                    ", ".join(f"{m} {rs[m]:.4f} deg/m" for m in have),
                    "held" if max(rs.values()) <= 1.1 * min(rs.values()) else "not held",
                    f"{ctx.split} split, {seg}; equal = within 10 %", n=n, n_of="routes")]


EXPERIMENT = Experiment(
    name="ground_odometry",
    description="KITTI odometry errors of a VO (GroundVO u2/w2/u6/w6, the held-scale monocular baseline, or "
                "yours) on the simulated routes, per route and pooled, with an oracle-scale bound",
    grid={"route": list(G.DEV10), "method": list(OURS)},
    methods={"method": "vo"},
    splits={"dev": {"seeds": [0]}, "test": {"seeds": [10_000], "grid": {"route": list(G.TEST_ROUTES)}}},
    choices={"route": G.route_choices},
    params=dict(G.ROUTE_PARAMS),
    sizes={"quick": {"n_seeds": 1, "grid": {"route": ["quick"], "method": ["w6", "mono"]}, "params": dict(G.QUICK_PARAMS)},
           "full": {}},
    trial=trial, summarize=summarize, checks=checks, findings=findings,
)
