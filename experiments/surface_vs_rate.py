"""surface_vs_rate: surface accuracy of GPIS and grid maps versus the data rate (issue 4).

The kinematic rover drives the seeded 60 s ``office2d`` route of ``gpis_accuracy`` (2D lidar,
1081 beams, sigma = 1 cm); a scan is fed every ``spacing_m`` metres of travel (0.1, 0.25, 0.5,
1.0 m). Four maps get the same scans at the true poses:

- ``gpis``: ``GPISMap2D(sensor_offset=(0, 0))``, default mode; its surface is ``surface()``
  (polylines, sampled every 1 cm);
- ``grid5`` / ``grid10``: ``OccupancyGrid2D`` at 5 / 10 cm; the surface is the centres of the
  occupied cells that touch a free cell (``surface_points()``);
- ``edt``: ``DiscreteSDF2D.from_grid`` of the 5 cm grid; its surface is the zero contour of the
  interpolated field (marching squares on the cell-centre distances, sampled every 1 cm).

Scores (``_gpis_common.score_surface_2d``), against the exact geometry: *surface RMSE*, the RMS
of the exact |SDF| at the estimated surface points inside the observed area; *Hausdorff*, the
larger of (max |SDF| at the estimated points) and (max distance from an observed true surface
point, i.e. a noise-free beam end point of the scans fed, to the estimated surface). The
diagnosis ``hausdorff_wellseen_m`` restricts both to surface seen from at least 1 m of the drive
(hit by at least as many scans as are taken over 1 m of travel, and at least 2).

Where the worst errors are (``_gpis_common.classify_worst``): the worst 1% of both directed
errors, each located at its true surface point, is classed as ``corner`` (within 0.3 m of a true
corner), ``sparse`` (hit by fewer scans than are taken over 1 m of travel, at least 2: seen from
less than a metre of the drive) or ``wall`` (a well-seen flat stretch).

Headline check (the published finding that continuous maps use sparse data better): at the
sparsest rate GPIS has a lower Hausdorff distance than both grids (mean over seeds).
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

METHODS = ["gpis", "grid5", "grid10", "edt"]
SURF = ["surface_rmse_m", "hausdorff_m", "h_est_to_true_m", "h_true_to_est_m", "p99_est_to_true_m",
        "p99_true_to_est_m", "hausdorff_wellseen_m", "worst_corner_share", "worst_sparse_share", "worst_wall_share"]


def _edt_surface(sdf):
    from skimage.measure import find_contours

    lines = find_contours(sdf.sdf_, 0.0)
    return [sdf.origin_ + (ln + 0.5) * sdf.cell_size_ for ln in lines if len(ln) >= 2]


def trial(params, seed, ctx):
    from polar_sim.baselines import DiscreteSDF2D, OccupancyGrid2D
    from polar_sim.gpis import GPISMap2D

    spacing = float(params["spacing_m"])
    w = C.office_world(seed)
    d = C.drive(w, C.route(w, seed), duration=60.0, speed=1.0, every_m=spacing)
    maps = {"gpis": GPISMap2D(sensor_offset=(0.0, 0.0)), "grid5": OccupancyGrid2D(cell_size=0.05),
            "grid10": OccupancyGrid2D(cell_size=0.10)}
    cpu = {k: 0.0 for k in maps}
    for p, r in zip(d.poses, d.ranges):
        for k, m in maps.items():
            t0 = time.process_time()
            m.update(d.angles, r, p)
            cpu[k] += time.process_time() - t0
    edt = DiscreteSDF2D.from_grid(maps["grid5"])
    surfaces = {"gpis": C.polyline_points(maps["gpis"].surface()), "grid5": maps["grid5"].surface_points(),
                "grid10": maps["grid10"].surface_points(), "edt": C.polyline_points(_edt_surface(edt))}
    obs = C.Observation(d)
    cor = C.corners(w)
    row = {"n_scans": len(d.poses), "travelled_m": float(d.travelled[-1]), "load": C.load_now()}
    arrays = {"hits": obs.hits[::5], "path": d.poses[:, :2]}
    for k in METHODS:
        k1m = max(2, int(round(1.0 / spacing)))        # scans taken over 1 m of travel
        m, det = C.score_surface_2d(w, surfaces[k], obs, well_k=k1m)
        shares, (q, cls) = C.classify_worst(w, det, obs, cor, sparse_k=k1m)
        m.update(shares)
        row.update({f"{k}_{key}": v for key, v in m.items()})
        arrays[f"{k}_est"] = det["est"] if det else np.zeros((0, 2))
        arrays[f"{k}_dA"] = det["dA"] if det else np.zeros(0)
        arrays[f"{k}_worst"], arrays[f"{k}_worst_cls"] = q, cls
    # near-surface SDF of the two distance fields (GPIS and EDT), for reference
    E = C.eval_points_2d(w, obs, 15_000 if ctx.quick else 40_000, seed)
    for k, m in (("gpis", maps["gpis"]), ("edt", edt)):
        s, _ = C.score_sdf_2d(m, E)
        row[f"{k}_near_rmse_m"] = s["near_rmse_m"]
        row[f"{k}_far_mae_m"] = s["far_mae_m"]
    for k in maps:
        row[f"{k}_update_cpu_ms"] = 1e3 * cpu[k] / max(len(d.poses), 1)
    np.savez_compressed(ctx.out_dir / "surfaces.npz", **arrays)
    w.close()
    return row


def _mean(rows, key):
    v = np.array([r[key] for r in rows if isinstance(r.get(key), (int, float))], float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else float("nan")


def _long(table):
    """One row per (spacing, method): means over seeds."""
    out = []
    for sp in sorted({r["spacing_m"] for r in table}):
        rows = [r for r in table if r["spacing_m"] == sp]
        for k in METHODS:
            d = {"spacing_m": sp, "method": k, "seeds": len(rows), "n_scans": _mean(rows, "n_scans")}
            for key in SURF + ["near_rmse_m", "far_mae_m"]:
                if f"{k}_{key}" in rows[0]:
                    d[key] = _mean(rows, f"{k}_{key}")
            d["hausdorff_max_m"] = max(r[f"{k}_hausdorff_m"] for r in rows)
            out.append(d)
    return out


def checks(table, ctx):
    quick = ctx.quick
    sparsest = max(r["spacing_m"] for r in table)
    rows = [r for r in table if r["spacing_m"] == sparsest]
    g = _mean(rows, "gpis_hausdorff_m")
    g5, g10 = _mean(rows, "grid5_hausdorff_m"), _mean(rows, "grid10_hausdorff_m")
    wins = sum(r["gpis_hausdorff_m"] < min(r["grid5_hausdorff_m"], r["grid10_hausdorff_m"]) for r in rows)
    return [Check(f"at the sparsest rate ({sparsest:g} m) GPIS beats both grids on Hausdorff",
                  bool(g < g5 and g < g10),
                  f"mean over {len(rows)} seeds: GPIS {g:.3f} m, grid 5 cm {g5:.3f} m, grid 10 cm {g10:.3f} m; "
                  f"GPIS lower than both in {wins}/{len(rows)} seeds")]


def _figures(table, ctx):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = ctx.out_dir
    lines = []
    long = _long(table)
    sps = sorted({r["spacing_m"] for r in table})
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    for k, c in zip(METHODS, ["tab:blue", "tab:orange", "tab:green", "tab:red"]):
        rs = [r for r in long if r["method"] == k]
        ax[0].plot(sps, [r["hausdorff_m"] for r in rs], "o-", c=c, label=k)
        ax[1].plot(sps, [r["hausdorff_wellseen_m"] for r in rs], "o-", c=c, label=k)
        ax[2].plot(sps, [r["surface_rmse_m"] for r in rs], "o-", c=c, label=k)
    for a, t in zip(ax, ["Hausdorff (all observed surface)", "Hausdorff (surface seen over >= 1 m of travel)",
                         "surface RMSE (estimated -> true)"]):
        a.set_xlabel("scan spacing (m of travel)")
        a.set_ylabel("m")
        a.set_title(t)
        a.set_yscale("log")
        a.grid(alpha=0.3)
    ax[0].legend()
    lines.append(savefig(fig, out_dir, "structure_surface_vs_rate"))
    seeds = sorted({r["seed"] for r in table})
    sp = sps[-1]
    r0 = [r for r in table if r["spacing_m"] == sp and r["seed"] == seeds[0]][0]
    z = np.load(ctx.trial_dir(r0) / "surfaces.npz")
    fig, ax = plt.subplots(2, 2, figsize=(13, 13))
    cols = np.array(["tab:red", "tab:purple", "tab:green"])
    for a, k in zip(ax.ravel(), METHODS):
        a.scatter(z["hits"][:, 0], z["hits"][:, 1], s=0.3, c="0.75", lw=0)
        sc = a.scatter(z[f"{k}_est"][:, 0], z[f"{k}_est"][:, 1], s=0.6, c=np.minimum(z[f"{k}_dA"], 0.2),
                       cmap="viridis", vmin=0, vmax=0.2, lw=0)
        for j, name in enumerate(["corner", "sparse", "wall"]):
            s = z[f"{k}_worst_cls"] == j
            a.scatter(z[f"{k}_worst"][s, 0], z[f"{k}_worst"][s, 1], marker="x", s=14, c=cols[j], label=f"worst 1%: {name}")
        a.plot(z["path"][:, 0], z["path"][:, 1], ".", c="tab:orange", ms=2)
        a.set_title(f"{k}: Hausdorff {r0[f'{k}_hausdorff_m']:.2f} m, surface RMSE {100 * r0[f'{k}_surface_rmse_m']:.1f} cm")
        a.set_aspect("equal")
        a.legend(loc="lower left", fontsize=7, markerscale=2)
    fig.colorbar(sc, ax=ax, shrink=0.5, label="|exact SDF| at the estimated surface (m)")
    fig.suptitle(f"office2d seed {seeds[0]}, a scan every {sp:g} m ({r0['n_scans']} scans); orange dots: scan poses")
    lines.append(savefig(fig, out_dir, "structure_surfaces_sparsest"))
    return lines


def summarize(table, ctx):
    out_dir, quick = ctx.out_dir, ctx.quick
    long = _long(table)
    cols = ["spacing_m", "method", "seeds", "n_scans", "surface_rmse_m", "hausdorff_m", "hausdorff_max_m",
            "hausdorff_wellseen_m", "h_est_to_true_m", "h_true_to_est_m", "p99_est_to_true_m", "p99_true_to_est_m",
            "near_rmse_m", "far_mae_m"]
    write_csv_table(long, cols + ["worst_corner_share", "worst_sparse_share", "worst_wall_share"],
                    out_dir / "surface_vs_rate.csv")
    per_seed = sorted(table, key=lambda r: (r["spacing_m"], r["seed"]))
    pcols = ["spacing_m", "seed", "n_scans"] + [f"{k}_hausdorff_m" for k in METHODS] + \
        [f"{k}_surface_rmse_m" for k in METHODS]
    write_csv_table(per_seed, pcols, out_dir / "surface_vs_rate_per_seed.csv")
    wl = markdown_table(long, ["spacing_m", "method", "worst_corner_share", "worst_sparse_share", "worst_wall_share"])
    figs = _figures(table, ctx)
    return "\n".join([
        "Means over seeds (metres). `hausdorff_max_m`: worst seed. `near_rmse_m` / `far_mae_m`: SDF error of "
        "the two distance fields near surfaces and in observed free space (as in `gpis_accuracy`).", "",
        markdown_table(long, cols), "",
        "Where the worst 1% of each method's surface errors lie (share of corner / sparsely seen / well-seen wall):",
        "", wl, "", "Per seed:", "", markdown_table(per_seed, pcols), "",
        "Tables: `surface_vs_rate.csv`, `surface_vs_rate_per_seed.csv`.", ""] + figs)


EXPERIMENT = Experiment(
    name="surface_vs_rate",
    description="issue 4: surface RMSE and Hausdorff of GPIS, grids (5/10 cm) and EDT vs scan spacing in office2d",
    grid={"spacing_m": [0.1, 0.25, 0.5, 1.0]},
    splits={"dev": {"seeds": range(5)}},
    sizes={"quick": {"n_seeds": 1, "grid": {"spacing_m": [1.0]}}, "full": {}},
    trial=trial,
    summarize=summarize,
    checks=checks,
)
