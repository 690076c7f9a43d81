"""Glue shared by the GPIS-chapter experiments (not an experiment itself: the leading underscore keeps
it out of ``polar-sim list``). The library does the work: recorded drives and orbits come from
``polar_sim.sim.recorders.drives2d`` / ``polar_sim.sim.recorders.orbits``, scores from ``polar_sim.metrics.maps``,
methods from the plug-in registry (``polar_sim.runner.methods``), pictures from
``polar_sim.runner.pictures2d``."""

from __future__ import annotations

import os
import time

import numpy as np

from polar_sim.gpis import GPISMap2D
from polar_sim.metrics.maps import polyline_points
from polar_sim.runner.gpis_methods import call_factory
from polar_sim.runner.methods import get_method
from polar_sim.runner.pictures2d import error_rows_figure, map_panel, map_picture, spacing_figure  # noqa: F401 (C.<name>)

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


def timed_updates(m, frames):
    """Call ``m.update(*args)`` for each frame's ``args``; returns the CPU time of each update, ms (n,)."""
    cpu = []
    for args in frames:
        t0 = time.process_time()
        m.update(*args)
        cpu.append(time.process_time() - t0)
    return 1e3 * np.asarray(cpu)


def fuse(m, angles, poses, ranges):
    """Feed every scan to mapper ``m``; returns the CPU time of each update, ms (n,)."""
    return timed_updates(m, ((angles, r, p) for p, r in zip(poses, ranges)))


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
    cpu = timed_updates(m, zip(orb.depths, orb.Ks, orb.poses))
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


def drive_trial(scene, method, seed, ctx, drive, n_eval, k, hits_every, ungated=False):
    """Map ``scene``'s recorded drive (``recorded_drives`` options ``drive``) with mapper2d ``method`` at
    the true poses and score it against the exact SDF (``metrics.map_scores_2d``, ``k`` scans for
    well-seen and sparse); saves the path, every ``hits_every``-th observed hit and the score arrays.
    ``ungated`` scores GPIS's whole zero level (``surface(evidence=False)``), as the grids' surfaces are."""
    from polar_sim.metrics.maps import ObservedArea, map_scores_2d
    from polar_sim.sim.recorders.drives2d import recorded_drives, section_corners

    d, = recorded_drives(scene, seed, [dict(route_seed=seed, **drive, **ROUTE)])
    m = make("mapper2d", method, seed=seed)
    cpu = fuse(m, d.angles, d.poses, d.ranges)
    w = truth_world(scene, seed)
    obs = ObservedArea(d.angles, d.poses, d.clean)
    kw = {"evidence": False} if ungated and isinstance(m, GPISMap2D) else {}
    row, arr = map_scores_2d(m.query, surface_points(m, **kw), w.sdf, obs, section_corners(w), n_eval=n_eval, seed=seed,
                             well_k=k, sparse_k=k)
    w.close()
    ctx.save_arrays(path=d.poses[:, :2], hits=obs.hits[::hits_every], **arr)
    return {**row, "n_scans": len(d.poses), "travelled_m": float(d.travelled[-1]), **cpu_stats(cpu), "load": load_now()}


def group_means(table, keys, cols, maxima=None):
    """One row per value of the ``keys`` columns (sorted): their values, ``seeds``, the means of ``cols``
    and, for each ``name: col`` of ``maxima``, the largest ``col`` as ``name``."""
    groups = sorted({tuple(r[k] for k in keys) for r in table})
    return [{**dict(zip(keys, g)), "seeds": len(rs), **{c: mean(rs, c) for c in cols},
             **{name: max(r[c] for r in rs) for name, c in (maxima or {}).items()}}
            for g in groups for rs in [[r for r in table if tuple(r[k] for k in keys) == g]]]


def pooled_by_method(table, ctx, fail_m):
    """Per localisation method: errors pooled over every step of every seed (``pooled_pose2d_errors``),
    seeds with a failure, medians over seeds of the per-seed median step times, and the errors ``err``."""
    from polar_sim.metrics import pooled_pose2d_errors

    out = []
    for k in sorted({r["method"] for r in table}):
        rows = [r for r in table if r["method"] == k]
        e = np.vstack([ctx.arrays(r)["err"] for r in rows])
        out.append({"method": k, "seeds": len(rows), **pooled_pose2d_errors(e, fail_m),
                    "seeds_with_failure": sum(r["fail_steps"] > 0 for r in rows),
                    "cpu_ms_median": float(np.median([r["cpu_ms_median"] for r in rows])),
                    "wall_ms_median": float(np.median([r["wall_ms_median"] for r in rows])), "err": e})
    return out


def localise_trial(ctx, loc, mapping, drive, seed, fail_m, fitted):
    """Fit localizer ``loc`` on the ``mapping`` drive at its true poses (timed), call ``fitted()``, then
    localise along ``drive`` with noisy odometry from a start 0.1 m and 2 deg off; saves the errors,
    true poses and odometry, returns the trial's row."""
    from polar_sim.metrics import pooled_pose2d_errors
    from polar_sim.runner.localise import localise_drive, noisy_odometry, perturbed_start

    t0 = time.process_time()
    loc.fit(mapping.angles, mapping.ranges, mapping.poses)
    fit_cpu = time.process_time() - t0
    fitted()
    rng = np.random.default_rng(np.random.SeedSequence([seed, 777]))
    truth = drive.poses
    odom = noisy_odometry(truth, rng)
    r = localise_drive(loc, drive.angles, drive.ranges, truth, odom, perturbed_start(truth[0], rng, offset_m=0.1, offset_deg=2.0))
    e, cpu = r["err"], r["cpu_ms"]
    st = pooled_pose2d_errors(e, fail_m)
    ctx.save_arrays(err=e, truth=truth, odom=odom)
    return {**{k: st[k] for k in ("pos_median_m", "pos_p90_m", "pos_max_m", "head_median_deg", "head_p90_deg", "fail_steps")},
            "not_ok_steps": int(getattr(loc, "not_ok_", 0)), "cpu_ms_median": float(np.median(cpu)),
            "cpu_ms_p90": float(np.percentile(cpu, 90)), "wall_ms_median": float(np.median(r["wall_ms"])),
            "n_steps": len(truth), "map_scans": len(mapping.poses), "fit_cpu_s": fit_cpu,
            "loc_travel_m": float(drive.travelled[-1]),
            "odom_pos_max_m": float(np.hypot(*(odom[:, :2] - truth[:, :2]).T).max()), "load": load_now()}


def reloc_scores(e, cpu_ms, fail_m=0.5):
    """Scores of relocalised scans: their errors ``e`` (k, 2: position m, heading deg) and CPU times (ms)."""
    return {"reloc_median_m": float(np.median(e[:, 0])), "reloc_p90_m": float(np.percentile(e[:, 0], 90)),
            "reloc_max_m": float(e[:, 0].max()), "reloc_head_median_deg": float(np.median(e[:, 1])),
            "reloc_fail": int((e[:, 0] > fail_m).sum()), "reloc_scans": len(e), "reloc_cpu_ms_median": float(np.median(cpu_ms))}
