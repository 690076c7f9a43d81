"""Scan-to-map ICP baselines: ICP-D on a discrete SDF, and point-to-point ICP on a KD-tree."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from polar_sim._validation import (
    as_float_array,
    as_int,
    as_points,
    as_pose,
    as_pose2d,
    as_positive_float,
    check_choice,
    check_updated,
)
from polar_sim.baselines.discrete_sdf import DiscreteSDF2D
from polar_sim.geometry import matrix_to_pose2d, pose2d_to_matrix, so3_log
from polar_sim.registration import (
    arc_length_subsample,
    as_scan2d,
    as_sensor_offset,
    beam_points,
    kabsch,
    point_to_point_covariance,
    register_sdf,
    scan3d_points,
    valid_beams,
)
from polar_sim.params import Parameterised, Tags

__all__ = ["ICPLocalizer"]

_METHODS = ("sdf", "point")


class ICPLocalizer(Parameterised):
    """Scan-to-map registration baselines.

    - ``method="sdf"`` ("ICP-D"): Gauss-Newton on a discrete signed distance field, each end point
      pulled along the EDT gradient by its distance. This is exactly ICP-G
      (:func:`polar_sim.registration.register_sdf`, which ``polar_sim.gpis.localize.localize``
      is) run on a :class:`DiscreteSDF2D` instead of a GPIS.
    - ``method="point"``: classic point-to-point ICP (Besl & McKay): nearest map points from a
      KD-tree, pairs farther than ``max_correspondence_distance`` rejected, closed-form (SVD)
      alignment, repeated until the update is below ``tolerance``.

    Parameters
    ----------
    method : {"sdf", "point"}, default="sdf"
    sensor_offset : (x, y) or (x, y, yaw), default=(0.0, 0.0)
        2D sensor mounting in the robot base frame (m, rad).
    n_points : int, optional
        Point budget per scan (default 200 in 2D, 600 in 3D), spread evenly in arc length (2D).
    max_iterations : int, default=50
    tolerance : float, default=1e-4
        Converged when an update moves less than this (m and rad). Tighter than ICP-G's default:
        point-to-point ICP converges linearly (it slides along walls in small steps), so a looser
        tolerance stops it early.
    max_correspondence_distance : float, default=1.0
        ``"point"`` only: farthest accepted nearest neighbour, metres.
    min_range, max_range : float, default=0.0, 30.0
        Valid ranges / depths lie strictly between these.
    max_correction : (m, rad), default=(1.5, 0.6)
        Moving further than this from the initial pose counts as divergence.

    Attributes
    ----------
    map_ : object
        ``"sdf"``: the distance field queried (a :class:`DiscreteSDF2D` built from a grid, or the
        map given to :meth:`fit`).
    points_ : ndarray of shape (m, dim)
        ``"point"``: the map points.
    tree_ : scipy.spatial.cKDTree
        ``"point"``: KD-tree over ``points_``.
    """

    TAGS = Tags(update="fit", query="localize", data="polar_sim.baselines.examples:icp")

    def __init__(
        self,
        *,
        method: str = "sdf",
        sensor_offset=(0.0, 0.0),
        n_points: int | None = None,
        max_iterations: int = 50,
        tolerance: float = 1e-4,
        max_correspondence_distance: float = 1.0,
        min_range: float = 0.0,
        max_range: float = 30.0,
        max_correction=(1.5, 0.6),
    ):
        self.method = method
        self.sensor_offset = sensor_offset
        self.n_points = n_points
        self.max_iterations = max_iterations
        self.tolerance = tolerance
        self.max_correspondence_distance = max_correspondence_distance
        self.min_range = min_range
        self.max_range = max_range
        self.max_correction = max_correction

    def _check_params(self):
        """Refuse a bad method or correspondence gate before any map is set (the other parameters
        are checked where the solver reads them)."""
        check_choice(self.method, _METHODS, "method")
        as_positive_float(self.max_correspondence_distance, "max_correspondence_distance")

    def fit(self, target):
        """Set the map.

        Parameters
        ----------
        target : OccupancyGrid2D, a map with ``query``, or ndarray of shape (m, 2|3)
            ``"sdf"``: an :class:`OccupancyGrid2D` (its signed EDT is built) or any map with
            ``query(points) -> (sdf, grad, var)``. ``"point"``: map points, or an object with
            ``surface_points()`` (an occupancy grid or a discrete SDF).

        Returns
        -------
        self
        """
        self._check_params()
        self.reset()
        if self.method == "sdf":
            if hasattr(target, "occupied_mask"):
                self.map_ = DiscreteSDF2D.from_grid(target)
            elif callable(getattr(target, "query", None)):
                self.map_ = target
            else:
                raise TypeError("target: method='sdf' needs an OccupancyGrid2D or a map with query(), "
                                f"got {type(target).__name__}")
            return self
        pts = target.surface_points() if hasattr(target, "surface_points") else target
        arr = as_float_array(pts, "target")
        dim = arr.shape[1] if arr.ndim == 2 and arr.shape[1] in (2, 3) else 2
        self.points_ = as_points(arr, dim, "target")
        self.tree_ = cKDTree(self.points_)
        return self

    def localize(self, scan, initial_pose):
        """Register one scan; same scan forms, outputs and statuses as :func:`polar_sim.registration.register_sdf`.

        Parameters
        ----------
        scan : tuple
            2D ``(angles, ranges)``; 3D ``(depth, K)`` or ``(directions, ranges)``.
        initial_pose : (x, y, theta) or ndarray of shape (4, 4)
            2D robot base pose, or 3D sensor -> world.

        Returns
        -------
        pose, cov, info
        """
        check_choice(self.method, _METHODS, "method")
        if self.method == "sdf":
            check_updated(self, "map_")
            return register_sdf(
                self.map_, scan, initial_pose, sensor_offset=self.sensor_offset, n_points=self.n_points,
                max_iterations=self.max_iterations, tolerance=self.tolerance, min_range=self.min_range,
                max_range=self.max_range, max_correction=self.max_correction,
            )
        check_updated(self, "tree_")
        return self._point_to_point(scan, initial_pose)

    # ------------------------------------------------------------------ point-to-point
    def _point_to_point(self, scan, initial_pose):
        dim = self.points_.shape[1]
        pose_arr = as_float_array(initial_pose, "initial_pose")
        prior = as_pose2d(pose_arr, "initial_pose") if dim == 2 else as_pose(pose_arr, "initial_pose")
        T0 = pose2d_to_matrix(prior) if dim == 2 else prior.copy()
        max_it = as_int(self.max_iterations, "max_iterations", minimum=1)
        tol = as_positive_float(self.tolerance, "tolerance")
        max_d = as_positive_float(self.max_correspondence_distance, "max_correspondence_distance")
        corr = as_float_array(self.max_correction, "max_correction")
        n_budget = (200 if dim == 2 else 600) if self.n_points is None else as_int(self.n_points, "n_points", minimum=1)
        if dim == 2:
            if not (isinstance(scan, (tuple, list)) and len(scan) == 2):
                raise TypeError("scan: expected a tuple (angles, ranges)")
            angles, ranges = as_scan2d(*scan)
            ok = valid_beams(ranges, self.min_range, self.max_range)
            P = beam_points(angles[ok], ranges[ok], as_sensor_offset(self.sensor_offset))
            n_valid = len(P)
            P = P[arc_length_subsample(P, n_budget)]
        else:
            P = scan3d_points(scan, pixel_stride=4, min_range=self.min_range, max_range=self.max_range)
            n_valid = len(P)
            if len(P) > n_budget:
                P = P[np.round(np.linspace(0, len(P) - 1, n_budget)).astype(int)]
        out_pose = (lambda T: matrix_to_pose2d(T)) if dim == 2 else (lambda T: T.copy())
        dof = 3 if dim == 2 else 6
        no_cov = np.diag(np.full(dof, np.inf))
        info = {"status": "ok", "iterations": 0, "n_valid": n_valid, "n_points": 0, "rmse": float("nan"),
                "reason": ""}
        min_pts = dof + 1
        if len(P) < min_pts:
            info.update(status="no_data", reason=f"{len(P)} valid points")
            return prior.copy(), no_cov, info
        T = T0.copy()
        for it in range(1, max_it + 1):
            R, t = T[:dim, :dim], T[:dim, dim]
            Q = P @ R.T + t
            dist, idx = self.tree_.query(Q, distance_upper_bound=max_d)
            m = np.isfinite(dist)
            if m.sum() < min_pts:
                status = "no_data" if it == 1 else "diverged"
                info.update(status=status, iterations=it, reason="too few correspondences")
                return prior.copy(), no_cov, info
            Pm, M = P[m], self.points_[idx[m]]
            T_new = kabsch(Pm, M)
            step = np.linalg.inv(T) @ T_new
            dt = np.linalg.norm(step[:dim, dim])
            dr = abs(np.arctan2(step[1, 0], step[0, 0])) if dim == 2 else np.linalg.norm(so3_log(step[:3, :3]))
            T = T_new
            e = Pm @ T[:dim, :dim].T + T[:dim, dim] - M
            info.update(iterations=it, n_points=int(m.sum()), rmse=float(np.sqrt(np.mean(np.sum(e * e, axis=1)))))
            ct = np.linalg.norm(T[:dim, dim] - T0[:dim, dim])
            cr = np.linalg.norm(so3_log(_as3(T0[:dim, :dim]).T @ _as3(T[:dim, :dim])))
            if ct > corr[0] or cr > corr[1]:
                info.update(status="diverged", reason="moved too far from the prior")
                return prior.copy(), no_cov, info
            if dt < tol and dr < tol:
                return out_pose(T), point_to_point_covariance(Pm @ T[:dim, :dim].T + T[:dim, dim], T, e), info
        info.update(status="max_iter", reason=f"no convergence in {max_it} iterations")
        Qm = Pm @ T[:dim, :dim].T + T[:dim, dim]
        return out_pose(T), point_to_point_covariance(Qm, T, e), info


def _as3(R):
    if R.shape == (3, 3):
        return R
    out = np.eye(3)
    out[:2, :2] = R
    return out
