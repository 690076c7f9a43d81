"""A complete ``localizer2d`` plug-in: run your own localiser in polar_sim's experiments.

The protocol (``polar_sim.runner.methods``): a factory taking keyword parameters returns an object
with ``fit(angles, ranges, poses)`` (a mapping drive: scans and their sensor poses), ``reset(pose2d)``
(the initial estimate) and ``step(angles, ranges, odometry_delta) -> pose2d``.

Two plug-ins here:

- ``DeadReckoning``: integrates the odometry and ignores the scans, the floor any localiser should beat.
- ``GridICP``: scan-to-map point-to-point ICP against the mapping drive's end points (a KD-tree),
  with scipy only; an honest, simple baseline.

Run them beside the built-in methods, scored the same way::

    PYTHONPATH=examples polar-sim run localisation --quick --set method=[icpg,my_localizer:DeadReckoning]
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def _compose(p, d):
    """Pose ``p`` (x, y, theta) moved by ``d`` expressed in p's frame."""
    c, s = np.cos(p[2]), np.sin(p[2])
    return np.array([p[0] + c * d[0] - s * d[1], p[1] + s * d[0] + c * d[1], p[2] + d[2]])


def _points(angles, ranges, pose):
    ok = np.isfinite(ranges)
    a, r = angles[ok], ranges[ok]
    c, s = np.cos(pose[2] + a), np.sin(pose[2] + a)
    return np.c_[pose[0] + r * c, pose[1] + r * s]


class DeadReckoning:
    """Odometry only: the estimate is the initial pose moved by every odometry increment."""

    def fit(self, angles, ranges, poses):
        return self

    def reset(self, pose2d):
        self.pose_ = np.asarray(pose2d, float).copy()
        return self

    def step(self, angles, ranges, odometry_delta):
        self.pose_ = _compose(self.pose_, np.asarray(odometry_delta, float))
        return self.pose_.copy()


class GridICP:
    """Point-to-point ICP of each scan against the mapping drive's end points.

    Parameters
    ----------
    iterations : int, default 20
    max_distance : float, default 0.3
        Correspondences farther than this (m) are dropped.
    stride : int, default 4
        Every stride-th beam is used.
    """

    def __init__(self, *, iterations=20, max_distance=0.3, stride=4):
        self.iterations = iterations
        self.max_distance = max_distance
        self.stride = stride

    def fit(self, angles, ranges, poses):
        pts = [_points(np.asarray(angles, float), np.asarray(r, float), p) for r, p in zip(ranges, poses)]
        self.tree_ = cKDTree(np.vstack(pts))
        return self

    def reset(self, pose2d):
        self.pose_ = np.asarray(pose2d, float).copy()
        return self

    def step(self, angles, ranges, odometry_delta):
        pose = _compose(self.pose_, np.asarray(odometry_delta, float))
        angles = np.asarray(angles, float)[:: self.stride]
        ranges = np.asarray(ranges, float)[:: self.stride]
        for _ in range(self.iterations):
            src = _points(angles, ranges, pose)
            d, j = self.tree_.query(src, distance_upper_bound=self.max_distance)
            ok = np.isfinite(d)
            if ok.sum() < 10:
                break
            a, b = src[ok], self.tree_.data[j[ok]]
            ca, cb = a.mean(0), b.mean(0)
            u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
            R = (u @ vt).T
            if np.linalg.det(R) < 0:
                vt[-1] *= -1
                R = (u @ vt).T
            t = cb - R @ ca
            dth = np.arctan2(R[1, 0], R[0, 0])
            pose = np.array([*(R @ pose[:2] + t), pose[2] + dth])
            if np.hypot(*t) < 1e-4 and abs(dth) < 1e-5:
                break
        self.pose_ = pose
        return pose.copy()
