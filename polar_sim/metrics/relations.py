"""The relation metric of the SLAM benchmark of Kümmerle et al. (Autonomous Robots 27, 2009).

A *relation* is a pair of poses (i, j) with a reference relative pose delta*_ij = x*_j (-) x*_i
(pose j in the frame of pose i, from manually checked scan matches). An estimated trajectory
gives delta_ij = x_j (-) x_i; the error of the relation is epsilon_ij = delta_ij (-) delta*_ij,
and the benchmark reports its translation ``|trans(epsilon)|`` (m) and rotation ``|rot(epsilon)|``
(deg), each as a mean (with standard deviation) of the absolute and of the squared values, and
the maximum. Unlike the absolute trajectory error, it is independent of where global errors
occur along the trajectory, and needs no common world frame.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from polar_sim.geometry import between2d

__all__ = ["RelationErrors", "relation_errors"]


@dataclasses.dataclass(frozen=True)
class RelationErrors:
    """Per-relation errors and their statistics (translation in m, rotation in deg)."""

    trans: np.ndarray           # (k,) |trans(epsilon)|, m
    rot_deg: np.ndarray         # (k,) |rot(epsilon)|, deg
    n: int
    trans_mean: float
    trans_std: float
    trans_sq_mean: float        # m^2
    trans_sq_std: float
    trans_max: float
    rot_mean_deg: float
    rot_std_deg: float
    rot_sq_mean_deg2: float     # deg^2
    rot_sq_std_deg2: float
    rot_max_deg: float


def relation_errors(poses, pairs, reference) -> RelationErrors:
    """Errors of an estimated 2D trajectory on reference relations.

    Parameters
    ----------
    poses : (n, 3) estimated poses (x, y, theta), m and rad.
    pairs : (k, 2) int, indices (i, j) into ``poses`` of each relation.
    reference : (k, 3) reference relative poses (dx, dy, dtheta): pose j in the frame of pose i.
    """
    P = np.asarray(poses, float)
    if P.ndim != 2 or P.shape[1] != 3 or not np.isfinite(P).all():
        raise ValueError(f"poses: expected finite (n, 3) poses, got shape {P.shape}")
    ij = np.asarray(pairs)
    if ij.ndim != 2 or ij.shape[1] != 2 or ij.dtype.kind not in "iu" or len(ij) == 0:
        raise ValueError(f"pairs: expected a non-empty (k, 2) integer array, got shape {ij.shape}, dtype {ij.dtype}")
    if ij.min() < 0 or ij.max() >= len(P):
        raise ValueError(f"pairs: indices must lie in [0, {len(P)}), got [{ij.min()}, {ij.max()}]")
    R = np.asarray(reference, float)
    if R.shape != (len(ij), 3) or not np.isfinite(R).all():
        raise ValueError(f"reference: expected finite shape ({len(ij)}, 3), got {R.shape}")
    est = between2d(P[ij[:, 0]], P[ij[:, 1]])
    eps = between2d(R, est)   # delta (-) delta*: the estimated relation in the reference's frame
    t = np.hypot(eps[:, 0], eps[:, 1])
    r = np.degrees(np.abs((eps[:, 2] + np.pi) % (2 * np.pi) - np.pi))
    return RelationErrors(t, r, len(t), float(t.mean()), float(t.std()), float((t * t).mean()), float((t * t).std()),
                          float(t.max()), float(r.mean()), float(r.std()), float((r * r).mean()), float((r * r).std()),
                          float(r.max()))
