"""Glue shared by the GPIS-chapter experiments (not an experiment itself: the leading underscore keeps
it out of ``polar-sim list``). The library does the work: recorded drives and orbits come from
``polar_sim.sim.drives2d`` / ``polar_sim.sim.orbits``, scores from ``polar_sim.metrics.maps``,
methods from the plug-in registry (``polar_sim.runner.methods``)."""

from __future__ import annotations

import os
import time

import numpy as np

from polar_sim.metrics.maps import polyline_points
from polar_sim.runner.gpis_methods import call_factory
from polar_sim.runner.methods import get_method

SCENES_2D = ("office2d", "warehouse2d")
#: The mapping drive of gpis_accuracy / surface_vs_rate: 60 s, 5 regions, 1 m/s.
ROUTE = {"n_rooms": 5, "duration": 60.0, "speed": 1.0}


def load_now():
    """1-minute load average (context for every timing)."""
    try:
        return float(os.getloadavg()[0])
    except OSError:  # pragma: no cover
        return float("nan")


def make(kind, name, **available):
    """An instance of plug-in ``name`` of ``kind``, given the optional keywords it accepts."""
    return call_factory(get_method(kind, name), **available)


def fuse(m, angles, poses, ranges):
    """Feed every scan to mapper ``m``; returns the CPU time of each update, ms (n,)."""
    cpu = []
    for p, r in zip(poses, ranges):
        t0 = time.process_time()
        m.update(angles, r, p)
        cpu.append(time.process_time() - t0)
    return 1e3 * np.asarray(cpu)


def fuse3d(m, orbit):
    """Feed every frame of a recorded orbit to mapper3d ``m``; CPU time per update, ms (n,)."""
    cpu = []
    for z, K, T in zip(orbit.depths, orbit.Ks, orbit.poses):
        t0 = time.process_time()
        m.update(z, K, T)
        cpu.append(time.process_time() - t0)
    return 1e3 * np.asarray(cpu)


def orbit_trial(method, seed, *, n_frames, n_eval, **options):
    """Map a recorded ``object_orbit`` (``World("object_orbit", seed, **options)``) with mapper3d
    ``method`` and score it (``metrics.object_map_scores``). Returns (row, map, ObjectTruth, the mesh
    comparison of ``ObjectTruth.compare_mesh``)."""
    from polar_sim.metrics.maps import object_map_scores
    from polar_sim.sim import World
    from polar_sim.sim.orbits import ObjectTruth, recorded_orbit

    w = World("object_orbit", seed=seed, **options)
    orb = recorded_orbit(w, n_frames, seed)
    m = make("mapper3d", method, seed=seed)
    cpu = fuse3d(m, orb)
    truth = ObjectTruth(w, orb)
    E = truth.eval_points(n_eval, seed)
    S = m.surface()
    V, F = np.asarray(S.vertices), np.asarray(S.faces)
    cmp = truth.compare_mesh(V, F, E["samples"][E["seen"]]) if len(F) else \
        {"dist": np.zeros(0), "visible": np.zeros(0, bool), "to_surface": np.zeros(0), "true_normals": np.zeros((0, 3))}
    vis = cmp["visible"]
    row = object_map_scores(m.query(E["P"])[0], E["gt"], dist=cmp["dist"], visible=vis, to_surface=cmp["to_surface"],
                            vertex_grad=m.query(V[vis])[1] if vis.any() else np.zeros((0, 3)),
                            true_normals=cmp["true_normals"][vis])
    row.update(object=orb.name, seen_fraction=E["seen_fraction"], n_frames=int(n_frames), **cpu_stats(cpu),
               update_cpu_ms_max=float(cpu.max()), load=load_now())
    if hasattr(m, "samples"):
        row["n_samples"] = int(len(m.samples()["points"]))
    w.close()
    return row, m, truth, cmp


def surface_points(m, spacing=0.01):
    """The estimated surface of a mapper2d as points: ``surface_points()`` if it has one, else its
    ``surface()`` polylines sampled every ``spacing`` m, else None."""
    if callable(getattr(m, "surface_points", None)):
        return np.asarray(m.surface_points(), float).reshape(-1, 2)
    if callable(getattr(m, "surface", None)):
        return polyline_points(m.surface(), spacing)
    return None


def truth_world(scene, seed):
    """The scene without sensor noise, for its exact SDF and corners (no MuJoCo import here)."""
    from polar_sim.sim.drives2d import lidar_world

    return lidar_world(scene, seed, noise=False)


def cpu_stats(cpu_ms, prefix="update_cpu_ms"):
    """Median and p99 of per-update CPU times (ms)."""
    return {f"{prefix}_median": float(np.median(cpu_ms)), f"{prefix}_p99": float(np.percentile(cpu_ms, 99))}


def mean(rows, key):
    """Mean of a numeric column over rows, NaN-safe."""
    v = np.array([r[key] for r in rows if isinstance(r.get(key), (int, float))], float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else float("nan")


def error_figure(ax, z, r, scene):
    """Two panels from a trial's arrays: |SDF error| near surfaces, and ``surface()`` with its worst
    1 % classed (corner / sparse / wall)."""
    ax[0].scatter(z["hits"][:, 0], z["hits"][:, 1], s=0.2, c="0.6", lw=0)
    sc = ax[0].scatter(z["P"][:, 0], z["P"][:, 1], c=np.abs(z["err"]), s=1.5, cmap="inferno_r", vmin=0, vmax=0.1, lw=0)
    ax[0].plot(z["path"][:, 0], z["path"][:, 1], "-", c="tab:blue", lw=1, label="drive")
    ax[0].figure.colorbar(sc, ax=ax[0], shrink=0.8, label="|SDF error| (m), points within 0.3 m of observed surfaces")
    ax[0].set_title(f"{scene} seed {r['seed']}, {r['method']}: SDF error near surfaces (RMSE {r['near_rmse_m'] * 100:.1f} cm)",
                    fontsize=9)
    ax[1].scatter(z["hits"][:, 0], z["hits"][:, 1], s=0.2, c="0.6", lw=0, label="observed true surface")
    if "est" in z:
        sel = z["dA"] > 0.05
        ax[1].scatter(z["est"][:, 0], z["est"][:, 1], s=0.3, c="k", lw=0, label="estimated surface")
        ax[1].scatter(z["est"][sel, 0], z["est"][sel, 1], c=np.minimum(z["dA"][sel], 0.3), s=3, cmap="autumn_r",
                      vmin=0.05, vmax=0.3, lw=0, label="estimate > 5 cm off the truth")
        for k, (name, c) in enumerate(zip(["corner", "sparse", "wall"], ["tab:red", "tab:purple", "tab:green"])):
            s = z["worst_cls"] == k
            ax[1].scatter(z["worst"][s, 0], z["worst"][s, 1], marker="x", s=18, c=c, label=f"worst 1%: {name}")
        ax[1].set_title(f"surface: Hausdorff {r['hausdorff_m'] * 100:.1f} cm", fontsize=9)
    for a in ax:
        a.set_aspect("equal")
        a.set_xlabel("x (m)")
        a.set_ylabel("y (m)")
        a.legend(loc="lower left", fontsize=7, markerscale=2)


def map_picture(m, pts, step):
    """The map's SDF and variance on a grid of ``step`` m over the box of ``pts`` (k, 2) plus 1 m,
    and its ``surface()`` polylines (NaN-separated), as arrays for :func:`map_panel`."""
    lo, hi = pts.min(0) - 1.0, pts.max(0) + 1.0
    xs, ys = np.arange(lo[0], hi[0], step), np.arange(lo[1], hi[1], step)
    X, Y = np.meshgrid(xs, ys)
    Q = np.column_stack([X.ravel(), Y.ravel()])
    s, v = np.empty(len(Q)), np.full(len(Q), np.nan)
    for i in range(0, len(Q), 10_000):       # below the size where a query goes multi-threaded
        d, _, var = m.query(Q[i:i + 10_000])
        s[i:i + 10_000] = d
        if var is not None:
            v[i:i + 10_000] = var
    lines = m.surface() if callable(getattr(m, "surface", None)) else []
    return {"xs": xs, "ys": ys, "sdf": s.reshape(X.shape).astype(np.float32), "var": v.reshape(X.shape).astype(np.float32),
            "lines": np.vstack([np.vstack([ln, [np.nan, np.nan]]) for ln in lines]) if lines else np.zeros((0, 2))}


def map_panel(ax, z, title, *, var_max=1.0):
    """Draw :func:`map_picture` arrays: the SDF where the variance is below ``var_max`` (never observed
    space blank), the surface, the path."""
    ext = [z["xs"][0], z["xs"][-1], z["ys"][0], z["ys"][-1]]
    show = np.where(~(z["var"] >= var_max), z["sdf"], np.nan)
    im = ax.imshow(np.clip(show, -1.0, 2.0), origin="lower", extent=ext, cmap="RdBu", vmin=-2.0, vmax=2.0)
    if len(z["lines"]):
        ax.plot(z["lines"][:, 0], z["lines"][:, 1], "-", c="k", lw=0.7, label="zero level (surface())")
    ax.plot(z["path"][:, 0], z["path"][:, 1], "-", c="tab:orange", lw=1.0, label="path")
    ax.set(title=title, xlabel="x (m)", ylabel="y (m)", aspect="equal")
    ax.title.set_fontsize(9)
    ax.legend(loc="lower left", fontsize=7)
    ax.figure.colorbar(im, ax=ax, shrink=0.7, label=f"SDF (m); blank: variance >= {var_max:g} (never observed)")
