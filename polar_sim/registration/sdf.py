"""Scan-to-map registration on a signed distance field, without closest points (ICP-G / ICP-D).

Every beam end point ``q`` is pulled along the unit SDF gradient ``n`` by its SDF value ``d``:
its implicit target is ``q - d n`` and its residual is ``d``, linearised as
``d(q(xi)) ~ d + n . dq/dxi``. Gauss-Newton on SE(2) (or SE(3)) minimises the weighted sum of
squared residuals with weights

    w = rho(d) / (var + sigma**2)

where ``var`` is the map's variance at the point (points with ``var > max_variance`` are not
used: the map knows nothing there) and ``rho`` is a robust (IRLS) weight: Huber by default, so
that points on structure the map lacks, or on the wrong side of a thin wall, cannot dominate.
A step that raises the objective is halved and retried (a learned field is not smooth
everywhere, and plain Gauss-Newton can cycle there).

Any object with ``query(points) -> (sdf (n,), grad (n, dim), var (n,))`` is a map: ``GPISMap2D`` /
``GPISMap3D``, :class:`~polar_sim.baselines.DiscreteSDF2D` (ICP-D), or an exact analytic field.

Cost. One call is a handful of ``map.query`` calls (3-5 from a tracking-size error) on at most
``n_points`` points. The beams are subsampled evenly in arc length along the scan (not by a fixed
stride, which would crowd near surfaces), and the loop stops as soon as a step falls below
``tolerance``. A coarse-to-fine schedule (first iterations on a subset) was tried and dropped: on
a GPIS the per-call overhead dominates, so the extra iterations cost more than the points saved.
"""

from __future__ import annotations

import logging
import math
from collections import namedtuple

import numpy as np

from polar_sim._validation import as_float_array, as_int, as_pose, as_pose2d, as_positive_float, check_choice
from polar_sim.registration.gauss_newton import KERNEL_CODES, gauss_newton_step, linearise
from polar_sim.registration.robust import DEFAULT_SCALE, ROBUST_KERNELS
from polar_sim.registration.scans import (
    arc_length_subsample,
    as_scan2d,
    as_sensor_offset,
    beam_points,
    scan3d_points,
    transform2d,
    valid_beams,
)
from polar_sim.errors import NotUpdatedError
from polar_sim.geometry import se3_exp, so3_log

__all__ = ["register_sdf"]

logger = logging.getLogger(__name__)

def _query(map, q, dim):
    """Call ``map.query`` and check what comes back; an empty map is a ValueError naming ``map``."""
    try:
        out = map.query(q)
    except NotUpdatedError as exc:
        raise ValueError(f"map: has no data to localise against ({exc})") from exc
    except ValueError as exc:
        raise ValueError(f"map: query rejected {dim}D scan points (is the map {dim}D?): {exc}") from exc
    try:
        d, g, v = out
    except (TypeError, ValueError) as exc:
        raise TypeError("map: query(points) must return (sdf, grad, var)") from exc
    d = np.asarray(d, dtype=np.float64).reshape(-1)
    g = np.asarray(g, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64).reshape(-1)
    n = q.shape[0]
    if d.shape != (n,) or g.shape != (n, dim) or v.shape != (n,):
        raise ValueError(
            f"map: query of {n} points in {dim}D returned shapes {d.shape}, {g.shape}, {v.shape}; "
            f"expected ({n},), ({n}, {dim}), ({n},) (is the map {dim}D?)"
        )
    return d, g, v


def _wrap(a):
    """``geometry.wrap_angle`` of one float (Python's % is numpy's remainder)."""
    return (float(a) + math.pi) % (2.0 * math.pi) - math.pi


class _Problem2D:
    """Pose (x, y, theta) of the base; the rotation acts about the base position."""

    dof = 3

    def __init__(self, pose):
        self.x = pose.copy()

    def world(self, p):
        return transform2d(self.x, p)

    def centre(self):
        return self.x[:2]

    @staticmethod
    def split(delta):
        return math.hypot(delta[0], delta[1]), abs(delta[2])

    def apply(self, delta):
        self.x = self.x + delta
        self.x[2] = _wrap(self.x[2])

    def correction(self, x0):
        return math.hypot(self.x[0] - x0[0], self.x[1] - x0[1]), abs(_wrap(self.x[2] - x0[2]))


class _Problem3D:
    """Sensor pose (4x4); a twist (omega, v) rotates about the sensor position, then translates."""

    dof = 6

    def __init__(self, T):
        self.x = T.copy()

    def world(self, p):
        return p @ self.x[:3, :3].T + self.x[:3, 3]

    def centre(self):
        return self.x[:3, 3]

    @staticmethod
    def split(delta):
        return np.linalg.norm(delta[3:]), np.linalg.norm(delta[:3])

    def apply(self, delta):
        R = se3_exp(np.concatenate([delta[:3], np.zeros(3)]))[:3, :3]
        T = self.x.copy()
        T[:3, :3] = R @ T[:3, :3]
        T[:3, 3] += delta[3:]
        self.x = T

    def correction(self, x0):
        return np.linalg.norm(self.x[:3, 3] - x0[:3, 3]), np.linalg.norm(so3_log(x0[:3, :3].T @ self.x[:3, :3]))


#: register_sdf's settings after their checks (see its docstring for each).
_Settings = namedtuple("_Settings", "max_iterations min_points tolerance kind scale sigma2 max_variance "
                                    "step corr")


def register_sdf(
    map,
    scan,
    initial_pose,
    *,
    sensor_offset=None,
    n_points: int | None = None,
    max_iterations: int = 30,
    tolerance: float = 5e-4,
    robust: str = "huber",
    robust_scale: float | None = None,
    sigma: float = 0.05,
    max_variance: float = 0.4,
    min_points: int = 10,
    min_range: float = 0.0,
    max_range: float = 30.0,
    pixel_stride: int = 4,
    max_step=(0.5, 0.3),
    max_correction=(1.5, 0.6),
):
    """Register one scan to a signed distance map by Gauss-Newton on the SDF (ICP-G).

    Parameters
    ----------
    map : object
        Anything with ``query(points) -> (sdf (n,), grad (n, dim), var (n,))``: a ``GPISMap2D`` /
        ``GPISMap3D``, a :class:`~polar_sim.baselines.DiscreteSDF2D`, an analytic field.
    scan : tuple
        2D: ``(angles (n,), ranges (n,))`` in the sensor frame (rad, m; inf/NaN = no return).
        3D: ``(depth (H, W), K (3, 3))`` with OpenCV camera axes, or ``(directions (n, 3), ranges (n,))``.
    initial_pose : (x, y, theta) or ndarray of shape (4, 4)
        2D: the robot *base* pose (m, rad); the sensor sits at ``sensor_offset`` in the base.
        3D: the sensor (camera) -> world transform.
    sensor_offset : (x, y) or (x, y, yaw), optional
        2D only. Default: ``map.sensor_offset`` if the map has one, else (0, 0).
    n_points : int, optional
        Point budget after subsampling (default 200 in 2D, 600 in 3D).
    max_iterations : int, default=30
    tolerance : float, default=5e-4
        Converged when a step moves less than this (m and rad).
    robust : {"huber", "tukey", "none"}, default="huber"
    robust_scale : float, optional
        Huber threshold / Tukey cut-off in metres (default 0.1 / 0.5).
    sigma : float, default=0.05
        Measurement noise (m) added to the map variance in the weights.
    max_variance : float, default=0.4
        Points where the map variance exceeds this are unknown to the map and not used.
    min_points : int, default=10
        Fewer usable points than this: no estimate (status ``"no_data"`` or ``"diverged"``).
    min_range, max_range : float, default=0.0, 30.0
        Valid ranges (2D, 3D lidar) or depths (depth images) lie strictly between these.
    pixel_stride : int, default=4
        Depth images: use every k-th pixel in each direction before subsampling.
    max_step : (m, rad), default=(0.5, 0.3)
        One Gauss-Newton step is scaled down to at most this translation and rotation.
    max_correction : (m, rad), default=(1.5, 0.6)
        Moving further than this from ``initial_pose`` counts as divergence.

    Returns
    -------
    pose : ndarray of shape (3,) or (4, 4)
        The registered pose (the initial pose when the status is ``"no_data"`` or ``"diverged"``).
    cov : ndarray of shape (3, 3) or (6, 6)
        Gauss-Newton covariance ``s2 * H^-1`` with ``H = J^T W J`` and the a-posteriori variance
        factor ``s2 = sum(w r^2) / (n - dof)``. 2D: over (x, y, theta). 3D: over the twist
        ``(omega, v)`` that perturbs the pose as ``R <- exp(omega) R``, ``t <- t + v`` (rotation
        about the sensor position, world axes). Infinite diagonal when there is no estimate.
    info : dict
        ``status`` ("ok", "no_data", "diverged", "max_iter"), ``iterations``, ``n_valid`` (valid
        beams or pixels), ``n_points`` (points used in the last Gauss-Newton step), ``rmse`` (m,
        RMS of their SDF residuals before that step), ``cost`` (the objective there: mean of
        ``rho(d) / (var + sigma**2)``), ``n_queried`` (points sent to ``map.query`` in total),
        ``reason`` (why, when not "ok").

    Raises
    ------
    ValueError
        A non-finite or malformed ``initial_pose``, a malformed ``scan``, bad parameters, or a map
        without data (one whose ``query`` raises ``NotUpdatedError``).
    """
    problem = _problem(initial_pose)
    dim = 2 if isinstance(problem, _Problem2D) else 3
    if not callable(getattr(map, "query", None)):
        raise TypeError(f"map: expected an object with query(points) -> (sdf, grad, var), got {type(map).__name__}")
    opts = _settings(dim, max_iterations, min_points, tolerance, robust, robust_scale, sigma, max_variance,
                     max_step, max_correction)
    min_range = as_positive_float(min_range, "min_range", allow_zero=True)
    max_range = as_positive_float(max_range, "max_range")
    n_points = (600 if dim == 3 else 200) if n_points is None else as_int(n_points, "n_points", minimum=1)
    if dim == 2:
        pts, n_valid = _points_2d(map, scan, sensor_offset, min_range, max_range, n_points)
    else:
        pts = scan3d_points(scan, pixel_stride=as_int(pixel_stride, "pixel_stride", minimum=1),
                            min_range=min_range, max_range=max_range)
        n_valid = len(pts)
        if len(pts) > n_points:
            pts = pts[np.round(np.linspace(0, len(pts) - 1, n_points)).astype(int)]
    info = {"status": "ok", "iterations": 0, "n_valid": n_valid, "n_points": 0, "rmse": float("nan"),
            "cost": float("nan"), "n_queried": 0, "reason": ""}
    if len(pts) < opts.min_points:
        # Still touch the map once, so that an empty map is an error whatever the scan.
        _query(map, problem.world(np.zeros((1, dim))), dim)
        info.update(status="no_data", n_queried=1, reason=f"{len(pts)} valid points < min_points={opts.min_points}")
        return problem.x.copy(), _no_cov(problem), info
    pts = np.ascontiguousarray(pts, np.float64)
    native = getattr(map, "_register_native", None)
    run = native(pts, problem.x, opts) if callable(native) else None
    if run is None:
        run = _gauss_newton(map, problem, pts, opts)
    else:
        run = _Run(*run)
    return _finish(run, problem, opts, info)


def _problem(initial_pose):
    """The pose to estimate: 2D for (x, y, theta), 3D for a 4x4 transform."""
    pose_arr = as_float_array(initial_pose, "initial_pose")
    if pose_arr.shape == (3,):
        return _Problem2D(as_pose2d(pose_arr, "initial_pose"))
    if pose_arr.shape == (4, 4):
        return _Problem3D(as_pose(pose_arr, "initial_pose"))
    raise ValueError(f"initial_pose: expected (x, y, theta) or a 4x4 pose, got shape {pose_arr.shape}")


def _settings(*args):
    """The solver's settings, checked; memoised when every argument is a plain number, string,
    None or tuple of them (the same arguments come with every scan)."""
    if not all(_plain(a) for a in args):
        return _check_settings(*args)
    key = repr(args)                  # repr, not ==: True == 1 == 1.0 must not share an entry
    out = _SETTINGS.get(key)
    if out is None:
        out = _check_settings(*args)
        if len(_SETTINGS) < 64:
            _SETTINGS[key] = out
    return out


def _plain(a):
    if isinstance(a, tuple):
        return all(_plain(x) for x in a)
    return a is None or type(a) in (bool, int, float, str)


_SETTINGS = {}


def _check_settings(dim, max_iterations, min_points, tolerance, robust, robust_scale, sigma, max_variance,
                    max_step, max_correction):
    """The solver's settings, checked (``ValueError``/``TypeError`` naming the argument)."""
    check_choice(robust, ROBUST_KERNELS, "robust")
    sigma = as_positive_float(sigma, "sigma")
    return _Settings(
        max_iterations=as_int(max_iterations, "max_iterations", minimum=1),
        min_points=as_int(min_points, "min_points", minimum=dim + 1),
        tolerance=as_positive_float(tolerance, "tolerance"),
        kind=KERNEL_CODES[robust],
        scale=DEFAULT_SCALE[robust] if robust_scale is None else as_positive_float(robust_scale, "robust_scale"),
        sigma2=sigma * sigma,
        max_variance=as_positive_float(max_variance, "max_variance"),
        step=tuple(as_positive_float(v, "max_step") for v in _pair(max_step, "max_step")),
        corr=tuple(as_positive_float(v, "max_correction") for v in _pair(max_correction, "max_correction")))


def _points_2d(map, scan, sensor_offset, min_range, max_range, n_points):
    """Base-frame end points of the valid beams, subsampled in arc length, and the valid count."""
    if not (isinstance(scan, (tuple, list)) and len(scan) == 2):
        raise TypeError("scan: expected a tuple (angles, ranges)")
    angles, ranges = as_scan2d(*scan)
    if sensor_offset is None:
        sensor_offset = getattr(map, "sensor_offset", None)
    off = as_sensor_offset((0.0, 0.0) if sensor_offset is None else sensor_offset)
    ok = valid_beams(ranges, min_range, max_range)
    pts = beam_points(angles[ok], ranges[ok], off)
    return pts[arc_length_subsample(pts, n_points)], int(ok.sum())


def _no_cov(problem):
    """The covariance of no estimate: an infinite diagonal."""
    return np.diag(np.full(problem.dof, np.inf))


#: How a Gauss-Newton run ended (the ``status`` of ``info``).
STATUS = ("ok", "no_data", "diverged", "max_iter")

#: What a Gauss-Newton run returns (both the Python loop and a map's compiled one): its status
#: (an index into STATUS), the last iteration, the points and the RMS residual and objective of
#: the last accepted step (or, on "no_data", the points found), the points queried, the final
#: correction (on "diverged"), the pose reached, and the accepted step's normal equations
#: (H, sum w r^2, points; ``has_best`` False when no step was accepted). The iteration is the
#: one the run ended on, except for "max_iter": the last accepted step's.
_Run = namedtuple("_Run", "status iterations n_points rmse cost n_queried ct cr x H wrr n has_best")


def _gauss_newton(map, problem, pts, opts):
    """Gauss-Newton with backtracking from ``problem.x`` on any map; returns a :data:`_Run`."""
    x0 = problem.x.copy()
    dim = pts.shape[1]
    n_queried = 0
    last = (0, 0, float("nan"), float("nan"))   # iteration, points, rmse, cost of the last accepted step
    best = None  # the last accepted pose (lowest objective so far), its normal equations and step

    def run(status, it, x, n_points=None, ct=0.0, cr=0.0):
        k, rmse, cost = last[1:] if n_points is None else (n_points, last[2], last[3])
        if best is None:
            return _Run(status, it, k, rmse, cost, n_queried, ct, cr, x, None, 0.0, 0, False)
        return _Run(status, it, k, rmse, cost, n_queried, ct, cr, x, best["H"], best["wrr"], best["n"], True)

    for it in range(1, opts.max_iterations + 1):
        q = problem.world(pts)
        d, g, v = _query(map, q, dim)
        n_queried += len(pts)
        H = np.empty((problem.dof, problem.dof))
        b = np.empty(problem.dof)
        used, cost_sum, wrr, r2 = linearise(q, d, g, v, np.ascontiguousarray(problem.centre()),
                                             opts.max_variance, opts.sigma2, opts.kind, opts.scale, H, b)
        if used < opts.min_points:
            if best is None:
                return run(1, it, x0, n_points=used)
            problem.x = best["x"].copy()  # the last step left the mapped area: retreat
            best["step"] = best["step"] * 0.5
            problem.apply(best["step"])
            continue
        cost = float(cost_sum / used)
        if best is not None and cost > best["cost"]:
            # The last step made things worse (a learned field is not smooth everywhere, e.g. where
            # a GPIS blends clusters, and plain Gauss-Newton can cycle there): retry half of it.
            problem.x = best["x"].copy()
            best["step"] = best["step"] * 0.5
            dt, dr = problem.split(best["step"])
            if dt < opts.tolerance and dr < opts.tolerance:
                return run(0, it, problem.x)
            problem.apply(best["step"])
            continue
        delta = np.empty(problem.dof)
        gauss_newton_step(H, b, delta)
        last = (it, used, float(np.sqrt(r2 / used)), cost)
        dt, dr = problem.split(delta)
        delta = delta * min(1.0, opts.step[0] / max(dt, 1e-300), opts.step[1] / max(dr, 1e-300))
        best = {"x": problem.x.copy(), "cost": cost, "H": H, "wrr": wrr, "n": used, "step": delta}
        problem.apply(delta)
        ct, cr = problem.correction(x0)
        if ct > opts.corr[0] or cr > opts.corr[1]:
            return run(2, it, x0, ct=ct, cr=cr)
        dt, dr = problem.split(delta)
        if dt < opts.tolerance and dr < opts.tolerance:
            return run(0, it, problem.x)
    return run(3, last[0], problem.x)     # "iterations": the last accepted step's


def _finish(run, problem, opts, info):
    """(pose, cov, info) of a Gauss-Newton run."""
    status = STATUS[run.status]
    info.update(status=status, iterations=int(run.iterations), n_points=int(run.n_points),
                n_queried=info["n_queried"] + int(run.n_queried))
    if run.status != 1:
        info.update(rmse=float(run.rmse), cost=float(run.cost))
    if status == "no_data":
        info["reason"] = f"{int(run.n_points)} points where the map has data < min_points={opts.min_points}"
    elif status == "diverged":
        info["reason"] = f"moved {run.ct:.3f} m / {np.degrees(run.cr):.1f} deg from the prior"
        logger.debug("register_sdf diverged after %d iterations: %s", run.iterations, info["reason"])
    elif status == "max_iter":
        info["reason"] = f"no convergence in {opts.max_iterations} iterations"
        logger.debug("register_sdf: %s", info["reason"])
    cov = _no_cov(problem) if (status in ("no_data", "diverged") or not run.has_best) else \
        run.wrr / max(run.n - run.H.shape[0], 1) * np.linalg.inv(run.H)
    return np.array(run.x, dtype=np.float64), cov, info


def _pair(v, name):
    a = as_float_array(v, name)
    if a.shape != (2,):
        raise ValueError(f"{name}: expected (metres, radians), got {v!r}")
    return float(a[0]), float(a[1])
