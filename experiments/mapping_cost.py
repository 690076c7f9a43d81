"""mapping_cost: the update cost per scan, and whether it depends on the size of the map (Ch. 7).

The world is ``office2d`` tiled n x n (``World("office2d", seed, tiles=n)``: n^2 copies of the 30 m
floor, each with its own furniture, joined by doors): 1x, 4x, 16x and 64x the office2d area for
n = 1, 2, 4, 8. The kinematic rover drives the snake through the whole world
(``polar_sim.sim.recorders.drives2d.snake_route``) at up to 1.5 m/s, a lidar scan (1081 beams, sigma 1 cm)
every ``every_m`` metres (0.5; quick: 1.0); the drive is recorded, then the ``mapper2d`` method
(``gpis``: ``GPISMap2D``, default mode) fuses every scan at the true pose, each ``update`` timed in
process CPU time (the wall time too, with the load average). Reported: the distribution of update
time per scan, its median / p90 / p99 per world size, and, within one drive, the median over the
scans taken in the k-th tile visited (the map then holds k tiles). The first 5 scans are left out.

Headline check: the median update time in the largest world is at most 1.5x that in the smallest.
It is a CPU-time figure: measured at full size and recorded in benchmarks/RESULTS.md.
"""

from __future__ import annotations

import time

import numpy as np

from polar_sim.runner import Check, Experiment, Finding
from polar_sim.runner.report import duration, markdown_table, savefig, write_csv_table

from polar_sim.experiments import _gpis_common as C

WARMUP = 5
COLS = ["method", "tiles", "area_x", "seed", "n_scans", "travelled_m", "cpu_ms_median", "cpu_ms_p90", "cpu_ms_p99",
        "cpu_ms_max", "wall_ms_median", "n_samples", "map_mb", "tiles_with_samples", "load"]


def trial(params, seed, ctx):
    from polar_sim.sim.recorders.drives2d import recorded_drives, snake_route

    n = int(params["tiles"])
    steps = int(1.3 * len(snake_route(n)) * 0.1 / (1.5 * 0.1)) + 200      # enough control steps for the snake
    d, = recorded_drives("office2d", seed, [dict(route="snake", duration=0.1 * steps, speed=1.5, lookahead=0.6,
                                                 every_m=ctx.params["every_m"], clean=False)], tiles=n)
    m = C.make("mapper2d", params["method"], seed=seed)
    cpu, wall, samples = [], [], []
    for p, r in zip(d.poses, d.ranges):
        t0, c0 = time.perf_counter(), time.process_time()
        m.update(d.angles, r, p)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
        samples.append(len(m.tree_.alive()) if hasattr(m, "tree_") else 0)
    cpu, wall = 1e3 * np.asarray(cpu), 1e3 * np.asarray(wall)
    tiles = [(int(np.floor((x + 15) / 30)), int(np.floor((y + 15) / 30))) for x, y in d.poses[:, :2]]
    order = {}
    idx = np.array([order.setdefault(t, len(order) + 1) for t in tiles])      # the k-th distinct tile entered
    c = cpu[WARMUP:]
    row = {"area_x": n * n, "n_scans": len(cpu), "travelled_m": float(d.travelled[-1]), "cpu_ms_median": float(np.median(c)),
           "cpu_ms_p90": float(np.percentile(c, 90)), "cpu_ms_p99": float(np.percentile(c, 99)), "cpu_ms_max": float(c.max()),
           "wall_ms_median": float(np.median(wall[WARMUP:])), "wall_ms_p99": float(np.percentile(wall[WARMUP:], 99)),
           "n_samples": int(samples[-1]), "tiles_visited": len(order), "load": C.load_now(),
           "map_mb": m.nbytes() / 1e6 if hasattr(m, "nbytes") else float("nan")}
    for k in (1, 4, 16, 64):
        sel = idx[WARMUP:] == k
        row[f"cpu_ms_median_tile{k}"] = float(np.median(c[sel])) if sel.any() else float("nan")
    if hasattr(m, "samples"):     # the map must cover the whole world: samples in every tile
        row["tiles_with_samples"] = len({(int(np.floor((x + 15) / 30)), int(np.floor((y + 15) / 30)))
                                         for x, y in m.samples()["points"]})
    ctx.save_arrays(cpu_ms=cpu, wall_ms=wall, tile_index=idx, samples=np.asarray(samples))
    return row


def _ratio(table, method="gpis"):
    by = {}
    for r in table:
        if r["method"] == method:
            by.setdefault(r["tiles"], []).append(r["cpu_ms_median"])
    lo, hi = min(by), max(by)
    return lo, hi, float(np.median(by[lo])), float(np.median(by[hi]))


def checks(table, ctx):
    lo, hi, a, b = _ratio(table)
    big = [r for r in table if r["tiles"] == hi and r["method"] == "gpis"]
    cov = min(r.get("tiles_with_samples", 0) for r in big)
    return [Check(f"update cost independent of map size: median CPU at {hi * hi}x area <= 1.5 x median at {lo * lo}x",
                  b <= 1.5 * a, f"{b:.2f} ms vs {a:.2f} ms CPU (ratio {b / a:.2f})", timing=True),
            Check("the map covers every tile of the largest world", cov == hi * hi, f"{cov}/{hi * hi} tiles")]


def findings(table, ctx):
    lo, hi, a, b = _ratio(table)
    return [Finding("Ch. 7, update time as the map grows", "the median GPIS update time stays flat as the map grows",
                    f"median CPU per scan {duration(a / 1e3, 'ms', decimals=2)} at {lo * lo}x the office2d area, "
                    f"{duration(b / 1e3, 'ms', decimals=2)} at {hi * hi}x "
                    f"(ratio {b / a:.2f})", "held" if b <= 1.5 * a else "not held",
                    "tiled simulated office, 1081-beam lidar; CPU time on a shared machine")]


def summarize(table, ctx):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(table, key=lambda r: (r["method"], r["tiles"], r["seed"]))
    write_csv_table(rows, COLS, ctx.out_dir / "mapping_cost.csv")
    tcols = ["method", "tiles", "seed"] + [f"cpu_ms_median_tile{k}" for k in (1, 4, 16, 64)]
    ser = {(r["method"], r["tiles"], r["seed"]): ctx.arrays(r) for r in rows}
    fig, ax = plt.subplots(1, 2, figsize=(13, 4.2))
    bins = np.linspace(0, max(np.percentile(v["cpu_ms"][WARMUP:], 99.5) for v in ser.values()) * 1.1, 60)
    for (k, n, s), v in sorted(ser.items()):
        ax[0].hist(v["cpu_ms"][WARMUP:], bins=bins, histtype="step", lw=1.5, density=True,
                   label=f"{k}, {n * n}x area (seed {s}, {len(v['cpu_ms'])} scans)")
    ax[0].set(xlabel="update CPU time per scan (ms)", ylabel="density", title="update time per scan")
    ax[0].legend(fontsize=8)
    v = ser[max(ser, key=lambda t: t[1])]
    x = np.arange(WARMUP, len(v["cpu_ms"]))
    ax[1].plot(x, v["cpu_ms"][WARMUP:], ".", ms=1.5, alpha=0.5, label="per scan")
    if len(x) > 51:
        ax[1].plot(x, [np.median(v["cpu_ms"][max(WARMUP, i - 25): i + 26]) for i in x], "-", c="k", lw=1.2,
                   label="running median (51 scans)")
    ax2 = ax[1].twinx()
    ax2.plot(x, v["samples"][WARMUP:], "-", c="tab:red", lw=1, label="surface samples in the map")
    ax2.set_ylabel("samples in the map", color="tab:red")
    ax[1].set(xlabel="scan index (largest world; the map grows along the drive)", ylabel="CPU ms",
              ylim=(0, np.percentile(v["cpu_ms"][WARMUP:], 99.5) * 1.2), title="update time as the map grows")
    ax[1].legend(loc="upper left", fontsize=8)
    return "\n".join([
        "Per-scan update time (ms; CPU = process time, wall = perf_counter; first 5 scans left out). `load`: 1-minute "
        "load average at the end of the trial.", "", markdown_table(rows, COLS), "",
        "Median CPU time of the scans taken in the k-th tile visited (the map then holds k tiles; tiles no "
        "drive reached are left out):", "",
        markdown_table(rows, tcols), "", "Table: `mapping_cost.csv`.", "", savefig(fig, ctx.out_dir, "structure_mapping_cost")])


EXPERIMENT = Experiment(
    name="mapping_cost",
    description="update time per scan and its (in)dependence on map size, tiled office worlds 1x-64x",
    grid={"tiles": [1, 2, 4, 8], "method": ["gpis"]},
    methods={"method": "mapper2d"},
    splits={"dev": {"seeds": [0]}, "test": {"seeds": [10_000]}},
    params={"every_m": 0.5},
    sizes={"quick": {"n_seeds": 1, "grid": {"tiles": [1, 2]}, "params": {"every_m": 1.0}}, "full": {}},
    trial=trial, summarize=summarize, checks=checks, findings=findings,
)
