"""gazebo1: the GPisMap authors' ``gazebo1`` log (2879 scans of a **Gazebo simulation** of an office,
not real data) mapped in the default and the published modes; self-consistency on held-out scans.

The ``mapper2d`` method (``gpis``: default mode; ``gpis_legacy``: the published behaviour,
``GPISMap2D.published()``, a name kept so that committed runs still load) fuses every ``map_every_scans``-th scan (1: all) except the held-out ones (every
``held_out_every_scans``-th, offset 5: 288 scans at 10) at the log's *sensor* poses (the base poses
moved by the log's 0.08 m laser offset; quick: every 10th scan maps, every 20th offset 5 is held
out). The log comes with poses but no geometry, so the map is scored by *self-consistency* on the
held-out scans: the |SDF| at their beam end points (on the true surface, up to the simulation's
pose and range noise), and the share of the mid-points of their beams (observed free space) that
the map calls free (SDF > 0). gazebo1 is the log the GPIS parameters were compared and tuned on
(the parity tests), so it is a dev-split figure only; the held-out real log is ``intel_lab``. Check: default mode, median |SDF| at held-out end points <= 2 cm.
"""

from __future__ import annotations

import numpy as np

from polar_sim.runner import Check, Experiment
from polar_sim.runner.report import markdown_table, savefig, write_csv_table

from polar_sim.experiments import _gpis_common as C

COLS = ["method", "map_scans", "held_out_scans", "endpoints", "abs_sdf_median_m", "abs_sdf_mean_m", "abs_sdf_p90_m",
        "abs_sdf_p99_m", "within_5cm", "midpoints_free", "n_samples", "map_mb", "update_cpu_ms_median",
        "update_cpu_ms_p99", "load"]


def _split(n, map_every, held_every):
    """Indices of the mapping scans (every ``map_every``-th, less the held-out ones) and of the
    held-out scans (every ``held_every``-th, offset 5)."""
    k = np.arange(n)
    held = k % held_every == 5
    return np.nonzero((k % map_every == 0) & ~held)[0], np.nonzero(held)[0]


def trial(params, seed, ctx):
    from polar_sim.datasets import load_gazebo1
    from polar_sim.geometry import compose2d
    from polar_sim.metrics.maps import hit_points

    g = load_gazebo1()
    off = np.r_[g["sensor_offset"], 0.0]
    poses = compose2d(g["poses"], off)                       # laser poses: the mappers take the sensor pose
    used, held = _split(len(g["ranges"]), ctx.params["map_every_scans"], ctx.params["held_out_every_scans"])
    m = C.make("mapper2d", params["method"], seed=seed)
    cpu = C.fuse(m, g["thetas"], poses[used], g["ranges"][used])
    E = hit_points(g["thetas"], poses[held], g["ranges"][held], max_range=np.inf)
    a = np.abs(m.query(E)[0])
    mid = m.query(hit_points(g["thetas"], poses[held], 0.5 * g["ranges"][held], max_range=np.inf))[0]
    row = {"map_scans": len(used), "held_out_scans": len(held), "endpoints": len(E),
           "abs_sdf_median_m": float(np.median(a)), "abs_sdf_mean_m": float(a.mean()),
           "abs_sdf_p90_m": float(np.percentile(a, 90)), "abs_sdf_p99_m": float(np.percentile(a, 99)),
           "within_5cm": float(np.mean(a < 0.05)), "midpoints_free": float(np.mean(mid > 0)),
           "n_samples": int(len(m.samples()["points"])) if hasattr(m, "samples") else -1,
           "map_mb": m.nbytes() / 1e6 if hasattr(m, "nbytes") else float("nan"), **C.cpu_stats(cpu), "load": C.load_now()}
    ends = hit_points(g["thetas"], poses[used[:: max(1, len(used) // 300)]], g["ranges"][used[:: max(1, len(used) // 300)]],
                      max_range=np.inf)
    ctx.save_arrays(**C.map_picture(m, np.vstack([poses[:, :2], ends]), ctx.params["picture_res_m"]), path=poses[:, :2], held=E[::5])
    return row


def checks(table, ctx):
    by = {r["method"]: r for r in table}
    if "gpis" not in by:
        return []
    dm = by["gpis"]["abs_sdf_median_m"]
    return [Check("default mode: held-out end points on the zero level, median |SDF| <= 2 cm", dm <= 0.02,
                  f"{100 * dm:.2f} cm over {by['gpis']['endpoints']} end points")]


def summarize(table, ctx):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(table, key=lambda r: r["method"])
    write_csv_table(rows, COLS, ctx.out_dir / "gazebo1.csv")
    fig, ax = plt.subplots(1, len(rows), figsize=(7.5 * len(rows), 6.5), squeeze=False)
    for a, r in zip(ax[0], rows):
        C.map_panel(a, ctx.arrays(r), f"gazebo1 (Gazebo simulation), {r['method']}: held-out end points median |SDF| "
                    f"{100 * r['abs_sdf_median_m']:.1f} cm")
    by = {r["method"]: r for r in rows}
    cmp = ""
    if {"gpis", "gpis_legacy"} <= set(by):
        dm, lm = by["gpis"]["abs_sdf_median_m"], by["gpis_legacy"]["abs_sdf_median_m"]
        cmp = (f"Default vs published: median |SDF| at held-out end points {100 * dm:.2f} cm vs {100 * lm:.2f} cm; surface "
               f"samples {by['gpis']['n_samples']} vs {by['gpis_legacy']['n_samples']}.")
    return "\n".join(["Self-consistency on held-out scans of the simulated gazebo1 log (the map never saw them; dev "
                      "split: the log the parameters were compared on).", "", markdown_table(rows, COLS), "", cmp, "",
                      "`within_5cm`: share of held-out end points with |SDF| < 5 cm; `midpoints_free`: share of the "
                      "mid-points of held-out beams with SDF > 0. The published mode (`gpis_legacy`) returns f + fbias, a distance "
                      "only near surfaces. Table: `gazebo1.csv`.", "", savefig(fig, ctx.out_dir, "gpis_gazebo1_modes")])


EXPERIMENT = Experiment(
    name="gazebo1",
    description="the GPisMap authors' gazebo1 log (a Gazebo simulation) in the default and the published modes; held-out self-consistency",
    grid={"method": ["gpis", "gpis_legacy"]},
    methods={"method": "mapper2d"},
    splits={"dev": {"seeds": [0]}},
    params={"map_every_scans": 1, "held_out_every_scans": 10, "picture_res_m": 0.1},
    sizes={"quick": {"n_seeds": 1, "params": {"map_every_scans": 10, "held_out_every_scans": 20, "picture_res_m": 0.2}},
           "full": {}},
    trial=trial, summarize=summarize, checks=checks,
)
