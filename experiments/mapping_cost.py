"""mapping_cost: GPIS update cost per scan, and whether it depends on the size of the map (issue 4).

The world is ``office2d`` tiled n x n (``World("office2d", seed, tiles=n)``: n^2 copies of the
30 m x 30 m floor, each with its own furniture, joined by doors), so its area is 1x, 4x, 16x
and 64x that of ``office2d`` for n = 1, 2, 4, 8. The kinematic rover drives a snake through the
whole world: east along the corridor of the first row of tiles, north through an office, a door
in the tile wall and a store room into the next row's corridor, west along it, and so on, at up to
1.5 m/s, with a lidar scan (1081 beams, sigma 1 cm) every ``every_m`` metres of travel. One
``GPISMap2D(sensor_offset=(0, 0))`` (default mode and parameters) fuses every scan at the true
pose; each ``update`` is timed in process CPU time (``time.process_time``, fairer than the wall
clock on a shared machine; the wall time is recorded too, with the load average).

Reported: the distribution of update time per scan (histogram), its median / p90 / p99 for each
world size, and, within one drive, the median over the scans taken in the k-th tile visited
(k = 1, 4, 16, 64): the map then already holds k tiles, i.e. k times the ``office2d`` area. The
first 5 scans of a drive are left out of the statistics (warm-up).

Headline check: the cost is local, independent of the map size: the median update time in the
largest world is at most 1.5x that in the smallest (the issue-3 criterion for gazebo1 applied to
map size).
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

WARMUP = 5


def snake(n, tile=30.0):
    """Waypoints (k, 2) of the snake through an n x n tiled office (see the module docstring)."""
    from polar_sim.sim.office import LANE_X

    pts = [(-13.0, 0.0)]
    for j in range(n):
        y = tile * j
        east = j % 2 == 0
        last = j == n - 1
        if last:
            x_end = tile * (n - 1) + 13.0 if east else -13.0
            pts.append((x_end, y))
        else:
            x_lane = tile * (n - 1) + LANE_X if east else LANE_X
            pts += [(x_lane, y), (x_lane, y + tile)]
    p = np.asarray(pts, float)
    out = [p[0]]
    for a, b in zip(p[:-1], p[1:]):
        k = max(1, int(np.ceil(np.linalg.norm(b - a) / 0.1)))
        out += list(a + (b - a) * (np.arange(1, k + 1) / k)[:, None])
    return np.asarray(out)


def trial(params, seed, ctx):
    from polar_sim.gpis import GPISMap2D
    from polar_sim.sim import World
    from polar_sim.sim.sensors import RangeNoise

    n = int(params["tiles"])
    every = 1.0 if ctx.quick else 0.5
    w = World("office2d", seed=seed, kinematic=True, noise={"lidar": RangeNoise(sigma=C.LIDAR_SIGMA)}, tiles=n)
    path = snake(n)
    follow = C.Follower(path, lookahead=0.6)
    m = GPISMap2D(sensor_offset=(0.0, 0.0))
    cpu, wall, tile_of, samples = [], [], [], []
    prev = w.truth()["robot_pose2d"]
    dist, last = 0.0, -np.inf
    max_steps = int(1.3 * (len(path) * 0.1) / (1.5 * w.dt)) + 200
    for _ in range(max_steps):
        if dist - last >= every - 1e-9:
            last = dist
            s = w.lidar("lidar")
            pose = C.T_to_pose2d(s.T_world_sensor)
            t0, c0 = time.perf_counter(), time.process_time()
            m.update(s.angles, s.ranges, pose)
            cpu.append(time.process_time() - c0)
            wall.append(time.perf_counter() - t0)
            tile_of.append((int(np.floor((pose[0] + 15.0) / 30.0)), int(np.floor((pose[1] + 15.0) / 30.0))))
            samples.append(len(m.tree_.alive()) if hasattr(m, "tree_") else 0)
        if follow.done:
            break
        w.step(follow(prev, 1.5))
        cur = w.truth()["robot_pose2d"]
        dist += float(np.hypot(*(cur[:2] - prev[:2])))
        prev = cur
    w.close()
    cpu, wall = np.asarray(cpu) * 1e3, np.asarray(wall) * 1e3
    # visiting order of the tiles: the k-th distinct tile entered
    order, idx = {}, []
    for t in tile_of:
        order.setdefault(t, len(order) + 1)
        idx.append(order[t])
    idx = np.asarray(idx)
    c = cpu[WARMUP:]
    row = {"area_x": n * n, "n_scans": len(cpu), "travelled_m": dist, "cpu_ms_median": float(np.median(c)),
           "cpu_ms_p90": float(np.percentile(c, 90)), "cpu_ms_p99": float(np.percentile(c, 99)),
           "cpu_ms_max": float(c.max()), "wall_ms_median": float(np.median(wall[WARMUP:])),
           "wall_ms_p99": float(np.percentile(wall[WARMUP:], 99)), "n_samples": int(samples[-1]),
           "map_mb": m.nbytes() / 1e6, "tiles_visited": len(order), "load": C.load_now()}
    for k in (1, 4, 16, 64):
        sel = idx[WARMUP:] == k
        row[f"cpu_ms_median_tile{k}"] = float(np.median(c[sel])) if sel.any() else float("nan")
    # the map must cover the whole world: samples in every tile
    pts = m.samples()["points"]
    cov = {(int(np.floor((x + 15) / 30)), int(np.floor((y + 15) / 30))) for x, y in pts}
    row["tiles_with_samples"] = len(cov)
    np.savez_compressed(ctx.out_dir / "cost.npz", cpu_ms=cpu, wall_ms=wall, tile_index=idx,
                        samples=np.asarray(samples))
    return row


def _series(ctx, table):

    out = {}
    for r in table:
        z = np.load(ctx.trial_dir(r) / "cost.npz")
        out[(r["tiles"], r["seed"])] = {k: z[k] for k in z.files}
    return out


def checks(table, ctx):
    quick = ctx.quick
    by = {}
    for r in table:
        by.setdefault(r["tiles"], []).append(r["cpu_ms_median"])
    lo, hi = min(by), max(by)
    a, b = float(np.median(by[lo])), float(np.median(by[hi]))
    out = [Check(f"update cost independent of map size: median at {hi * hi}x area <= 1.5 x median at {lo * lo}x",
                 b <= 1.5 * a, f"{b:.2f} ms vs {a:.2f} ms CPU (ratio {b / a:.2f})")]
    full = [r for r in table if r["tiles"] == hi]
    cov = min(r["tiles_with_samples"] for r in full)
    out.append(Check("the map covers every tile of the largest world", cov == hi * hi, f"{cov}/{hi * hi} tiles"))
    return out


def summarize(table, ctx):
    out_dir, quick = ctx.out_dir, ctx.quick
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(table, key=lambda r: (r["tiles"], r["seed"]))
    cols = ["tiles", "area_x", "seed", "n_scans", "travelled_m", "cpu_ms_median", "cpu_ms_p90", "cpu_ms_p99",
            "cpu_ms_max", "wall_ms_median", "wall_ms_p99", "n_samples", "map_mb", "load"]
    write_csv_table(rows, cols, out_dir / "mapping_cost.csv")
    tcols = ["tiles", "seed"] + [f"cpu_ms_median_tile{k}" for k in (1, 4, 16, 64)]
    ser = _series(ctx, table)
    fig, ax = plt.subplots(1, 2, figsize=(13, 4.2))
    bins = np.linspace(0, max(np.percentile(v["cpu_ms"][WARMUP:], 99.5) for v in ser.values()) * 1.1, 60)
    for (n, s), v in sorted(ser.items()):
        ax[0].hist(v["cpu_ms"][WARMUP:], bins=bins, histtype="step", lw=1.5, density=True,
                   label=f"{n * n}x area (seed {s}, {len(v['cpu_ms'])} scans)")
    ax[0].set_xlabel("GPISMap2D.update CPU time per scan (ms)")
    ax[0].set_ylabel("density")
    ax[0].legend(fontsize=8)
    ax[0].set_title("update time per scan")
    big = max(ser)
    v = ser[big]
    x = np.arange(WARMUP, len(v["cpu_ms"]))
    ax[1].plot(x, v["cpu_ms"][WARMUP:], ".", ms=1.5, alpha=0.5, label="per scan")
    k = 51
    if len(x) > k:
        med = np.array([np.median(v["cpu_ms"][max(WARMUP, i - k // 2): i + k // 2 + 1]) for i in x])
        ax[1].plot(x, med, "-", c="k", lw=1.2, label=f"running median ({k} scans)")
    ax2 = ax[1].twinx()
    ax2.plot(x, v["samples"][WARMUP:], "-", c="tab:red", lw=1, label="surface samples in the map")
    ax2.set_ylabel("samples", color="tab:red")
    ax[1].set_xlabel(f"scan index ({big[0] * big[0]}x world, the map grows along the drive)")
    ax[1].set_ylabel("CPU ms")
    ax[1].set_ylim(0, np.percentile(v["cpu_ms"][WARMUP:], 99.5) * 1.2)
    ax[1].legend(loc="upper left", fontsize=8)
    ax[1].set_title("update time as the map grows")
    fig_line = savefig(fig, out_dir, "structure_mapping_cost")
    return "\n".join([
        "Per-scan `GPISMap2D.update` time (ms; CPU = process time, wall = perf_counter; first 5 scans left out). "
        "`load`: 1-minute load average at the end of the trial.", "", markdown_table(rows, cols), "",
        "Median CPU time of the scans taken in the k-th tile visited (the map then holds k tiles = k x the "
        "office2d area):", "", markdown_table(rows, tcols), "", "Table: `mapping_cost.csv`.", "", fig_line])


EXPERIMENT = Experiment(
    name="mapping_cost",
    description="issue 4: GPIS update time per scan and its (in)dependence on map size, tiled office worlds 1x-64x",
    grid={"tiles": [1, 2, 4, 8]},
    splits={"dev": {"seeds": [0]}},
    sizes={"quick": {"n_seeds": 1, "grid": {"tiles": [1, 2]}}, "full": {}},
    trial=trial,
    summarize=summarize,
    checks=checks,
)
