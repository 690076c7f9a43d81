"""localisation: PF on an occupancy grid vs ICP-D vs ICP-G on maps built in the simulator (issue 4).

Per seed: ``office2d`` with that seed's furniture; 2D lidar (1081 beams, 270 deg, sigma = 1 cm).

1. *Mapping drive*: the kinematic rover follows a seeded route through all five rooms (up to
   150 s at 1 m/s; quick: 60 s), a scan every 2nd step (5 Hz; quick: every 3rd), fused at the
   true poses into a ``GPISMap2D(sensor_offset=(0, 0))`` (default mode) and a 5 cm
   ``OccupancyGrid2D``.
2. *Localisation drive*: the world is reset and the rover follows another seeded route (60 s;
   quick: 30 s). Odometry integrates the true motion increments with a 2% scale error, a yaw drift
   of 0.5 deg per metre and Gaussian noise (5% of each step's translation, 1% sideways, and
   0.05 rad/rad + 0.005 rad/m in heading). Every 2nd step (5 Hz) each method gets the scan and the
   odometry. All start from the same initial estimate, 0.1 m and 2 deg off the true pose:

   - ``pf1000`` / ``pf5000`` / ``pf10000``: ``ParticleFilterLocalizer`` (MCL, odometry motion
     model with its default noise, likelihood field of the 5 cm grid, 60 beams scored) with 1000,
     5000 and 10000 particles, initial spread (0.1 m, 0.1 m, 0.05 rad);
   - ``icpd``: ``ICPLocalizer(method="sdf")`` on the signed EDT of the 5 cm grid, started from
     the previous estimate moved by the odometry increment;
   - ``icpg``: ``polar_sim.gpis.localize.localize`` (ICP-G) on the GPIS map, started the same
     way. A registration that does not return status "ok" keeps the odometry prediction.

Scored against the true lidar pose at every step: position error (m) and heading error (deg);
distribution over all steps of all seeds (median, p90, max) and *failures*: steps with a position
error > 0.5 m (and the number of seeds with any). Each method's step is timed (process CPU and
wall). "The same compute budget": the PF with the fewest particles whose median CPU time per step
is at least ICP-G's (chosen in the checks from the measured times); ICP-G must beat it.
"""

from __future__ import annotations

import time

import numpy as np

from polar_sim.runner import Check, Experiment
from polar_sim.runner.report import markdown_table, savefig, write_csv_table

try:
    from polar_sim.experiments import _gpis_common as C
except ImportError:  # pragma: no cover
    import _gpis_common as C

METHODS = ["pf1000", "pf5000", "pf10000", "icpd", "icpg"]
PF_N = {"pf1000": 1000, "pf5000": 5000, "pf10000": 10000}
LABEL = {"pf1000": "PF, 1000 particles (grid 5 cm)", "pf5000": "PF, 5000 particles (grid 5 cm)",
         "pf10000": "PF, 10000 particles (grid 5 cm)",
         "icpd": "ICP-D (EDT of the 5 cm grid)", "icpg": "ICP-G (GPIS)"}
FAIL_M = 0.5


def noisy_odometry(base_poses, rng, scale=1.02, drift_deg_per_m=0.5):
    """Odometry poses (n, 3) integrating the true increments of ``base_poses`` (n, 3) with a scale
    error, a yaw drift per metre and Gaussian noise (see the module docstring)."""
    from polar_sim.geometry import between2d, compose2d

    out = [base_poses[0].copy()]
    for a, b in zip(base_poses[:-1], base_poses[1:]):
        dx, dy, dth = between2d(a, b)
        tr = float(np.hypot(dx, dy))
        ndx = dx * scale + rng.normal(0.0, 0.05 * tr)
        ndy = dy * scale + rng.normal(0.0, 0.01 * tr)
        ndth = dth + np.radians(drift_deg_per_m) * tr + rng.normal(0.0, 0.05 * abs(dth) + 0.005 * tr)
        out.append(compose2d(out[-1], np.array([ndx, ndy, ndth])))
    return np.asarray(out)


def _err(est, truth):
    d = (est[2] - truth[2] + np.pi) % (2 * np.pi) - np.pi
    return float(np.hypot(est[0] - truth[0], est[1] - truth[1])), float(abs(np.degrees(d)))


def trial(params, seed, ctx):
    from polar_sim.baselines import ICPLocalizer, LikelihoodField, OccupancyGrid2D, ParticleFilterLocalizer
    from polar_sim.geometry import between2d, compose2d
    from polar_sim.gpis import GPISMap2D
    from polar_sim.gpis.localize import localize

    quick = ctx.quick
    w = C.office_world(seed)
    clear = C.clearance_map(w)
    # 1. mapping drive
    d1 = C.drive(w, C.route(w, seed, n_rooms=5, clearance=clear), duration=60.0 if quick else 150.0,
                 speed=1.0, every_steps=3 if quick else 2)
    gpis = GPISMap2D(sensor_offset=(0.0, 0.0))
    grid = OccupancyGrid2D(cell_size=0.05)
    t0 = time.process_time()
    for p, r in zip(d1.poses, d1.ranges):
        gpis.update(d1.angles, r, p)
    map_cpu = time.process_time() - t0
    for p, r in zip(d1.poses, d1.ranges):
        grid.update(d1.angles, r, p)
    field = LikelihoodField().fit(grid)
    icpd = ICPLocalizer(method="sdf").fit(grid)
    # 2. localisation drive on another route
    w.reset()
    d2 = C.drive(w, C.route(w, 10_000 + seed, n_rooms=3, clearance=clear), duration=30.0 if quick else 60.0,
                 speed=1.0, every_steps=2)
    w.close()
    rng = np.random.default_rng(np.random.SeedSequence([seed, 777]))
    truth = d2.poses
    odom = noisy_odometry(truth, rng)
    a = rng.uniform(-np.pi, np.pi)
    init = truth[0] + np.array([0.1 * np.cos(a), 0.1 * np.sin(a), np.radians(2.0) * rng.choice([-1.0, 1.0])])
    pfs = {k: ParticleFilterLocalizer(n_particles=n, seed=seed).initialize(field, init, std=(0.1, 0.1, 0.05))
           for k, n in PF_N.items()}
    est = {k: init.copy() for k in ("icpd", "icpg")}
    errs = {k: [] for k in METHODS}
    cpu = {k: [] for k in METHODS}
    wall = {k: [] for k in METHODS}
    bad = {k: 0 for k in ("icpd", "icpg")}
    angles = d2.angles
    for i in range(len(truth)):
        scan = (angles, d2.ranges[i])
        inc = between2d(odom[i - 1], odom[i]) if i else np.zeros(3)
        for k in METHODS:
            t0, c0 = time.perf_counter(), time.process_time()
            if k.startswith("pf"):
                pfs[k].update(angles, d2.ranges[i], odom[i])
                pose = pfs[k].pose_
            else:
                pred = compose2d(est[k], inc)
                if k == "icpg":
                    pose, _, info = localize(gpis, scan, pred)
                else:
                    pose, _, info = icpd.localize(scan, pred)
                if info["status"] != "ok":
                    bad[k] += 1
                    pose = pred
                est[k] = pose
            cpu[k].append(time.process_time() - c0)
            wall[k].append(time.perf_counter() - t0)
            errs[k].append(_err(pose, truth[i]))
    row = {"n_steps": len(truth), "map_scans": len(d1.poses), "map_cpu_s_per_scan": map_cpu / len(d1.poses),
           "loc_travel_m": float(d2.travelled[-1]), "load": C.load_now()}
    arrays = {"truth": truth, "odom": odom}
    for k in METHODS:
        e = np.asarray(errs[k])
        arrays[f"{k}_err"] = e
        row.update({f"{k}_pos_median_m": float(np.median(e[:, 0])), f"{k}_pos_p90_m": float(np.percentile(e[:, 0], 90)),
                    f"{k}_pos_max_m": float(e[:, 0].max()), f"{k}_head_median_deg": float(np.median(e[:, 1])),
                    f"{k}_head_p90_deg": float(np.percentile(e[:, 1], 90)), f"{k}_fail_steps": int((e[:, 0] > FAIL_M).sum()),
                    f"{k}_cpu_ms_median": 1e3 * float(np.median(cpu[k])), f"{k}_wall_ms_median": 1e3 * float(np.median(wall[k])),
                    f"{k}_cpu_ms_p90": 1e3 * float(np.percentile(cpu[k], 90))})
    for k in bad:
        row[f"{k}_not_ok_steps"] = bad[k]
    oe = np.array([_err(o, t) for o, t in zip(odom, truth)])
    row["odom_pos_final_m"] = float(oe[-1, 0])
    row["odom_pos_max_m"] = float(oe[:, 0].max())
    np.savez_compressed(ctx.out_dir / "errors.npz", **arrays)
    return row


def _pooled(ctx, table):

    pooled = {k: [] for k in METHODS}
    for r in table:
        z = np.load(ctx.trial_dir(r) / "errors.npz")
        for k in METHODS:
            pooled[k].append(z[f"{k}_err"])
    return {k: np.vstack(v) for k, v in pooled.items()}


def _stats(table, pooled):
    out = []
    for k in METHODS:
        e = pooled[k]
        out.append({"method": LABEL[k], "key": k, "steps": len(e), "pos_median_m": float(np.median(e[:, 0])),
                    "pos_p90_m": float(np.percentile(e[:, 0], 90)), "pos_max_m": float(e[:, 0].max()),
                    "head_median_deg": float(np.median(e[:, 1])), "head_p90_deg": float(np.percentile(e[:, 1], 90)),
                    "fail_steps": int((e[:, 0] > FAIL_M).sum()),
                    "seeds_with_failure": int(sum(r[f"{k}_fail_steps"] > 0 for r in table)), "seeds": len(table),
                    "cpu_ms_median": float(np.median([r[f"{k}_cpu_ms_median"] for r in table])),
                    "wall_ms_median": float(np.median([r[f"{k}_wall_ms_median"] for r in table]))})
    return out


def budget_pf(table):
    """The PF variant with the fewest particles whose median CPU time per step (median over seeds)
    is at least ICP-G's, or the slowest one if none is; and that CPU time."""
    g = float(np.median([r["icpg_cpu_ms_median"] for r in table]))
    times = {k: float(np.median([r[f"{k}_cpu_ms_median"] for r in table])) for k in PF_N}
    ok = [k for k in PF_N if times[k] >= g]
    k = min(ok, key=lambda k: PF_N[k]) if ok else max(PF_N, key=lambda k: PF_N[k])
    return k, times[k], g


def checks(table, ctx):
    quick = ctx.quick
    # From the per-seed rows: the worst seed's median error, and failures over all steps.
    med = lambda k: float(np.median([r[f"{k}_pos_median_m"] for r in table]))  # noqa: E731
    g_pos = max(r["icpg_pos_median_m"] for r in table)
    g_head = max(r["icpg_head_median_deg"] for r in table)
    g_fail = sum(r["icpg_fail_steps"] for r in table)
    pk, p_cpu, g_cpu = budget_pf(table)
    pf1 = float(np.median([r["pf1000_cpu_ms_median"] for r in table]))
    wins = sum(r["icpg_pos_median_m"] < r[f"{pk}_pos_median_m"] for r in table)
    return [
        Check("ICP-G median position error <= 5 cm (worst seed)", g_pos <= 0.05, f"{100 * g_pos:.2f} cm"),
        Check("ICP-G median heading error <= 1 deg (worst seed)", g_head <= 1.0, f"{g_head:.3f} deg"),
        Check("ICP-G: no failures (position error > 0.5 m)", g_fail == 0, f"{g_fail} failed steps"),
        Check("ICP-G error lower than PF's at the same compute budget",
              bool(med("icpg") < med(pk) and p_cpu >= g_cpu),
              f"median over seeds of the median position error: ICP-G {100 * med('icpg'):.2f} cm vs {pk} "
              f"{100 * med(pk):.2f} cm (lower in {wins}/{len(table)} seeds); median CPU per step ICP-G "
              f"{g_cpu:.2f} ms, {pk} {p_cpu:.2f} ms"),
        Check("one ICP-G step <= 10 ms (1081-beam scan; median CPU)", g_cpu <= 10.0, f"{g_cpu:.2f} ms"),
        Check("PF with 1000 particles <= 20 ms per update (median CPU)", pf1 <= 20.0, f"{pf1:.2f} ms"),
    ]


def summarize(table, ctx):
    out_dir, quick = ctx.out_dir, ctx.quick
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pooled = _pooled(ctx, table)
    st = _stats(table, pooled)
    cols = ["method", "steps", "seeds", "pos_median_m", "pos_p90_m", "pos_max_m", "head_median_deg", "head_p90_deg",
            "fail_steps", "seeds_with_failure", "cpu_ms_median", "wall_ms_median"]
    write_csv_table(st, cols, out_dir / "localisation.csv")
    rows = sorted(table, key=lambda r: r["seed"])
    pcols = ["seed", "n_steps", "odom_pos_max_m"] + [f"{k}_pos_median_m" for k in METHODS] + \
        [f"{k}_head_median_deg" for k in METHODS] + [f"{k}_fail_steps" for k in METHODS] + \
        [f"{k}_cpu_ms_median" for k in METHODS] + ["load"]
    write_csv_table(rows, pcols, out_dir / "localisation_per_seed.csv")
    fig, ax = plt.subplots(1, 2, figsize=(13, 4.2))
    for k, c in zip(METHODS, ["gold", "tab:orange", "tab:red", "tab:green", "tab:blue"]):
        for j, (a, unit) in enumerate(zip(ax, ["position error (m)", "heading error (deg)"])):
            e = np.sort(pooled[k][:, j])
            a.plot(np.maximum(e, 1e-4), np.arange(1, len(e) + 1) / len(e), c=c, label=LABEL[k])
            a.set_xscale("log")
            a.set_xlabel(unit)
            a.set_ylabel("fraction of steps")
            a.grid(alpha=0.3)
    ax[0].axvline(FAIL_M, c="k", ls=":", lw=1)
    ax[0].axvline(0.05, c="0.5", ls="--", lw=1)
    ax[1].axvline(1.0, c="0.5", ls="--", lw=1)
    ax[0].legend(fontsize=8)
    fig.suptitle(f"localisation in office2d: {len(table)} seeds, {len(pooled['icpg'])} steps per method (CDF)")
    fl = savefig(fig, out_dir, "structure_localisation")
    return "\n".join([
        "Errors pooled over every localisation step of every seed; `fail_steps`: steps with a position error "
        f"> {FAIL_M} m; times are medians over seeds of the per-seed median step time (ms).", "",
        markdown_table(st, cols), "", "Per seed:", "", markdown_table(rows, pcols), "",
        "Tables: `localisation.csv`, `localisation_per_seed.csv`.", "", fl])


EXPERIMENT = Experiment(
    name="localisation",
    description="issue 4: PF (grid) vs ICP-D vs ICP-G localisation on maps built in office2d, noisy odometry",
    grid={"odometry": ["noisy"]},
    splits={"dev": {"seeds": range(20)}},
    sizes={"quick": {"n_seeds": 1, "grid": {"odometry": ["noisy"]}}, "full": {}},
    trial=trial,
    summarize=summarize,
    checks=checks,
)
