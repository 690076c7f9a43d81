"""Glue shared by the GPIS-chapter experiments (not an experiment itself: the leading underscore keeps
it out of ``polar-sim list``). The library does the work: recorded drives and orbits come from
``polar_sim.sim.recorders.drives2d`` / ``polar_sim.sim.recorders.orbits``, scores from ``polar_sim.metrics.maps``,
methods from the plug-in registry (``polar_sim.runner.methods``), pictures from
``polar_sim.runner.pictures2d``."""

from __future__ import annotations

import os
import time

import numpy as np

from polar_sim.metrics.maps import polyline_points
from polar_sim.runner.gpis_methods import call_factory
from polar_sim.runner.methods import get_method
from polar_sim.runner.pictures2d import error_figure, map_picture, map_panel  # noqa: F401 (used as C.<name>)

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
    from polar_sim.sim.recorders.orbits import ObjectTruth, recorded_orbit

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


def surface_points(m, spacing=0.01, **surface_kw):
    """The estimated surface of a mapper2d as points: ``surface_points()`` if it has one, else its
    ``surface(**surface_kw)`` polylines sampled every ``spacing`` m, else None."""
    if callable(getattr(m, "surface_points", None)):
        return np.asarray(m.surface_points(), float).reshape(-1, 2)
    if callable(getattr(m, "surface", None)):
        return polyline_points(m.surface(**surface_kw), spacing)
    return None


def truth_world(scene, seed):
    """The scene without sensor noise, for its exact SDF and corners (no MuJoCo import here)."""
    from polar_sim.sim.recorders.drives2d import lidar_world

    return lidar_world(scene, seed, noise=False)


def cpu_stats(cpu_ms, prefix="update_cpu_ms"):
    """Median and p99 of per-update CPU times (ms)."""
    return {f"{prefix}_median": float(np.median(cpu_ms)), f"{prefix}_p99": float(np.percentile(cpu_ms, 99))}


def mean(rows, key):
    """Mean of a numeric column over rows, NaN-safe."""
    v = np.array([r[key] for r in rows if isinstance(r.get(key), (int, float))], float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else float("nan")
