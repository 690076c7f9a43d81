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

import numpy as np

from polar_sim._validation import as_float_array, as_int, as_pose, as_pose2d, as_positive_float, check_choice
from polar_sim.registration.robust import DEFAULT_SCALE, ROBUST_KERNELS, robust_cost, robust_weight
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
from polar_sim.geometry import se3_exp, so3_log, wrap_angle

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


class _Problem2D:
    dof = 2

    def __init__(self, pose):
        self.x = pose.copy()

    def world(self, p):
        return transform2d(self.x, p)

    def jacobian(self, q, n):
        # Parameters (x, y, theta) of the base; the rotation acts about the base position.
        lever = q - self.x[:2]
        return np.column_stack([n[:, 0], n[:, 1], n[:, 1] * lever[:, 0] - n[:, 0] * lever[:, 1]])

    @staticmethod
    def split(delta):
        return np.linalg.norm(delta[:2]), abs(delta[2])

    def apply(self, delta):
        self.x = self.x + delta
        self.x[2] = wrap_angle(self.x[2])

    def correction(self, x0):
        return np.linalg.norm(self.x[:2] - x0[:2]), abs(wrap_angle(self.x[2] - x0[2]))


class _Problem3D:
    dof = 3

    def __init__(self, T):
        self.x = T.copy()

    def world(self, p):
        return p @ self.x[:3, :3].T + self.x[:3, 3]

    def jacobian(self, q, n):
        # Twist (omega, v): rotation about the sensor position, then a world translation.
        return np.column_stack([np.cross(q - self.x[:3, 3], n), n])

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
    # ---- inputs
    pose_arr = as_float_array(initial_pose, "initial_pose")
    if pose_arr.shape == (3,):
        problem = _Problem2D(as_pose2d(pose_arr, "initial_pose"))
        dim = 2
    elif pose_arr.shape == (4, 4):
        problem = _Problem3D(as_pose(pose_arr, "initial_pose"))
        dim = 3
    else:
        raise ValueError(f"initial_pose: expected (x, y, theta) or a 4x4 pose, got shape {pose_arr.shape}")
    if not callable(getattr(map, "query", None)):
        raise TypeError(f"map: expected an object with query(points) -> (sdf, grad, var), got {type(map).__name__}")
    max_iterations = as_int(max_iterations, "max_iterations", minimum=1)
    min_points = as_int(min_points, "min_points", minimum=dim + 1)
    tolerance = as_positive_float(tolerance, "tolerance")
    check_choice(robust, ROBUST_KERNELS, "robust")
    scale = DEFAULT_SCALE[robust] if robust_scale is None else as_positive_float(robust_scale, "robust_scale")
    sigma = as_positive_float(sigma, "sigma")
    max_variance = as_positive_float(max_variance, "max_variance")
    min_range = as_positive_float(min_range, "min_range", allow_zero=True)
    max_range = as_positive_float(max_range, "max_range")
    step_t, step_r = (as_positive_float(v, "max_step") for v in _pair(max_step, "max_step"))
    corr_t, corr_r = (as_positive_float(v, "max_correction") for v in _pair(max_correction, "max_correction"))
    n_points = (600 if dim == 3 else 200) if n_points is None else as_int(n_points, "n_points", minimum=1)

    if dim == 2:
        if not (isinstance(scan, (tuple, list)) and len(scan) == 2):
            raise TypeError("scan: expected a tuple (angles, ranges)")
        angles, ranges = as_scan2d(*scan)
        if sensor_offset is None:
            sensor_offset = getattr(map, "sensor_offset", None)
        off = as_sensor_offset((0.0, 0.0) if sensor_offset is None else sensor_offset)
        ok = valid_beams(ranges, min_range, max_range)
        n_valid = int(ok.sum())
        pts = beam_points(angles[ok], ranges[ok], off)
        pts = pts[arc_length_subsample(pts, n_points)]
    else:
        pts = scan3d_points(scan, pixel_stride=as_int(pixel_stride, "pixel_stride", minimum=1),
                            min_range=min_range, max_range=max_range)
        n_valid = len(pts)
        if len(pts) > n_points:
            pts = pts[np.round(np.linspace(0, len(pts) - 1, n_points)).astype(int)]

    x0 = problem.x.copy()
    dof = 3 if dim == 2 else 6
    no_cov = np.diag(np.full(dof, np.inf))
    info = {"status": "ok", "iterations": 0, "n_valid": n_valid, "n_points": 0, "rmse": float("nan"),
            "cost": float("nan"), "n_queried": 0, "reason": ""}
    if len(pts) < min_points:
        # Still touch the map once, so that an empty map is an error whatever the scan.
        _query(map, problem.world(np.zeros((1, dim))), dim)
        info.update(status="no_data", n_queried=1, reason=f"{len(pts)} valid points < min_points={min_points}")
        return x0, no_cov, info

    # ---- Gauss-Newton with backtracking
    best = None  # the last accepted pose (lowest objective so far), its covariance and step
    for it in range(1, max_iterations + 1):
        q = problem.world(pts)
        d, g, v = _query(map, q, dim)
        info["n_queried"] += len(pts)
        gn = np.linalg.norm(g, axis=1)
        use = np.isfinite(d) & np.isfinite(gn) & (gn > 1e-9) & np.isfinite(v) & (v <= max_variance)
        if use.sum() < min_points:
            if best is None:
                info.update(status="no_data", iterations=it, n_points=int(use.sum()),
                            reason=f"{int(use.sum())} points where the map has data < min_points={min_points}")
                return x0, no_cov, info
            problem.x = best["x"].copy()  # the last step left the mapped area: retreat
            best["step"] = best["step"] * 0.5
            problem.apply(best["step"])
            continue
        r = d[use]
        iv = 1.0 / (np.maximum(v[use], 0.0) + sigma * sigma)
        cost = float(np.mean(robust_cost(r, robust, scale) * iv))
        if best is not None and cost > best["cost"]:
            # The last step made things worse (a learned field is not smooth everywhere, e.g. where
            # a GPIS blends clusters, and plain Gauss-Newton can cycle there): retry half of it.
            problem.x = best["x"].copy()
            best["step"] = best["step"] * 0.5
            dt, dr = problem.split(best["step"])
            if dt < tolerance and dr < tolerance:
                info["iterations"] = it
                return problem.x, best["cov"], info
            problem.apply(best["step"])
            continue
        n = g[use] / gn[use, None]
        J = problem.jacobian(q[use], n)
        w = robust_weight(r, robust, scale) * iv
        H = (J * w[:, None]).T @ J
        H += (1e-9 * np.trace(H) / dof + 1e-12) * np.eye(dof)  # keeps a degenerate scene solvable
        wrr = float(np.sum(w * r * r))
        delta = -np.linalg.solve(H, J.T @ (w * r))
        cov = wrr / max(len(r) - dof, 1) * np.linalg.inv(H)
        info.update(iterations=it, n_points=len(r), rmse=float(np.sqrt(np.mean(r * r))), cost=cost)
        dt, dr = problem.split(delta)
        delta = delta * min(1.0, step_t / max(dt, 1e-300), step_r / max(dr, 1e-300))
        best = {"x": problem.x.copy(), "cost": cost, "cov": cov, "step": delta}
        problem.apply(delta)
        ct, cr = problem.correction(x0)
        if ct > corr_t or cr > corr_r:
            info.update(status="diverged", reason=f"moved {ct:.3f} m / {np.degrees(cr):.1f} deg from the prior")
            logger.debug("register_sdf diverged after %d iterations: %s", it, info["reason"])
            return x0, no_cov, info
        dt, dr = problem.split(delta)
        if dt < tolerance and dr < tolerance:
            return problem.x, cov, info
    info.update(status="max_iter", reason=f"no convergence in {max_iterations} iterations")
    logger.debug("register_sdf: %s", info["reason"])
    return problem.x, (no_cov if best is None else best["cov"]), info


def _pair(v, name):
    a = as_float_array(v, name)
    if a.shape != (2,):
        raise ValueError(f"{name}: expected (metres, radians), got {v!r}")
    return float(a[0]), float(a[1])
