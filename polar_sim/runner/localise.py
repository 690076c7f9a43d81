"""The localisation protocols the GPIS-chapter experiments share (numpy only).

- :func:`noisy_odometry`: odometry poses integrating a drive's true increments with a scale error,
  a yaw drift per metre and Gaussian noise;
- :func:`perturbed_start`: a pose moved a fixed distance in a seeded direction and turned a fixed
  angle with a seeded sign (the start every method gets);
- :func:`localise_drive`: a ``localizer2d`` plug-in driven step by step along a drive, scored against
  the true poses at every step, with its CPU and wall time per step;
- :func:`relocalise`: each of a set of single scans localised from a perturbed start, no motion;
- :func:`budget_match`: the particle filter that matches a reference method's CPU per step;
- :func:`error_cdf_figure`: CDFs of per-step errors.

Scores come from :mod:`polar_sim.metrics`: :func:`~polar_sim.metrics.pose2d_errors` per step,
:func:`~polar_sim.metrics.pooled_pose2d_errors` over steps and
:func:`~polar_sim.metrics.relation_scores` on benchmark relations.

Poses are ``(x, y, theta)`` in metres and radians; errors are ``(position m, heading deg)``.
"""

from __future__ import annotations

import time

import numpy as np

from polar_sim.metrics import pose2d_errors

__all__ = ["noisy_odometry", "perturbed_start", "localise_drive", "relocalise", "budget_match", "error_cdf_figure"]


def noisy_odometry(poses, rng, *, scale=1.02, drift_deg_per_m=0.5):
    """Odometry poses (n, 3) integrating the true increments of ``poses`` (n, 3), starting at
    ``poses[0]``: each increment's forward and sideways motion scaled by ``scale``, plus Gaussian noise
    (5 % of the step's translation forward, 1 % sideways), and its heading change plus a drift of
    ``drift_deg_per_m`` per metre travelled and noise (0.05 rad/rad + 0.005 rad/m). ``rng`` is a
    ``numpy.random.Generator``; it draws three normals per step, in that order."""
    from polar_sim.geometry import between2d, compose2d

    poses = np.asarray(poses, float)
    if poses.ndim != 2 or poses.shape[1] != 3 or len(poses) < 1:
        raise ValueError(f"poses: expected shape (n, 3) with n >= 1, got {poses.shape}")
    out = [poses[0].copy()]
    for a, b in zip(poses[:-1], poses[1:]):
        dx, dy, dth = between2d(a, b)
        tr = float(np.hypot(dx, dy))
        out.append(compose2d(out[-1], np.array([dx * scale + rng.normal(0.0, 0.05 * tr), dy * scale + rng.normal(0.0, 0.01 * tr),
                                                dth + np.radians(drift_deg_per_m) * tr + rng.normal(0.0, 0.05 * abs(dth) + 0.005 * tr)])))
    return np.asarray(out)


def perturbed_start(pose, rng, *, offset_m, offset_deg):
    """``pose`` (3,) moved ``offset_m`` in a uniform random direction and turned ``offset_deg`` with a
    random sign (draws a uniform, then a choice)."""
    b = rng.uniform(-np.pi, np.pi)
    return np.asarray(pose, float) + np.array([offset_m * np.cos(b), offset_m * np.sin(b),
                                               np.radians(offset_deg) * rng.choice([-1.0, 1.0])])


def localise_drive(loc, angles, ranges, truth, odom, start):
    """Drive ``loc`` (a ``localizer2d``, already fitted) along a recorded drive.

    ``loc.reset(start)``, then at each step i ``loc.step(angles, ranges[i], odometry increment)``, the
    increment being the motion from ``odom[i - 1]`` to ``odom[i]`` in the former's frame (zero at
    step 0). Returns ``{"err": (n, 2) position m / heading deg against truth (n, 3), "cpu_ms": (n,),
    "wall_ms": (n,)}`` (CPU: process time of each step).
    """
    from polar_sim.geometry import between2d

    loc.reset(start)
    est, cpu, wall = [], [], []
    for i in range(len(truth)):
        inc = between2d(odom[i - 1], odom[i]) if i else np.zeros(3)
        t0, c0 = time.perf_counter(), time.process_time()
        pose = loc.step(angles, ranges[i], inc)
        cpu.append(1e3 * (time.process_time() - c0))
        wall.append(1e3 * (time.perf_counter() - t0))
        est.append(np.array(pose, dtype=float))     # a copy: a localiser may reuse its pose buffer
    return {"err": pose2d_errors(np.asarray(est).reshape(-1, 3), truth), "cpu_ms": np.asarray(cpu), "wall_ms": np.asarray(wall)}


def relocalise(loc, angles, ranges, poses, rng, *, offset_m=0.2, offset_deg=3.0, steps=3):
    """Localise each scan ``ranges[k]`` (k, m) alone: from its pose ``poses[k]`` perturbed by
    :func:`perturbed_start`, ``steps`` calls of ``loc.step`` with no motion. Returns (err (k, 2)
    position m / heading deg against ``poses``, CPU ms of the ``steps`` calls (k,))."""
    est, truth, cpu = [], [], []
    for r, p in zip(ranges, poses):
        loc.reset(perturbed_start(p, rng, offset_m=offset_m, offset_deg=offset_deg))
        c0 = time.process_time()
        for _ in range(steps):
            pose = loc.step(angles, r, np.zeros(3))
        cpu.append(1e3 * (time.process_time() - c0))
        est.append(np.array(pose, dtype=float))
        truth.append(np.asarray(p, dtype=float))
    return pose2d_errors(np.asarray(est).reshape(-1, 3), np.asarray(truth).reshape(-1, 3)), np.asarray(cpu)


def budget_match(stats, *, reference="icpg", prefix="pf"):
    """The method of ``stats`` (dicts with ``method`` and ``cpu_ms_median``) named ``prefix<N>`` with
    the fewest ``N`` whose median CPU per step is at least the ``reference`` method's (else the one
    with the most ``N``; None if there is none): "the same compute budget". Returns (it, reference CPU ms)."""
    g = next(s for s in stats if s["method"] == reference)["cpu_ms_median"]
    cands = sorted((s for s in stats if s["method"].startswith(prefix) and s["method"][len(prefix):].isdigit()),
                   key=lambda s: int(s["method"][len(prefix):]))
    return next((s for s in cands if s["cpu_ms_median"] >= g), cands[-1] if cands else None), g


def error_cdf_figure(series, *, fail_m, title):
    """A figure of two CDF panels (position m, heading deg; log x) of per-step errors, one line per
    ``series`` entry ``{label: err (n, 2)}``, the failure threshold ``fail_m`` dotted."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(13, 4.2))
    for label, err in series.items():
        for j, (a, unit) in enumerate(zip(ax, ["position error (m)", "heading error (deg)"])):
            e = np.sort(np.asarray(err)[:, j])
            a.plot(np.maximum(e, 1e-4), np.arange(1, len(e) + 1) / len(e), label=label)
            a.set(xscale="log", xlabel=unit, ylabel="fraction of steps")
            a.grid(alpha=0.3)
    ax[0].axvline(fail_m, c="k", ls=":", lw=1)
    ax[0].legend(fontsize=8)
    fig.suptitle(title)
    return fig
