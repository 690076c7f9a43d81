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

from polar_sim._validation import as_float_array, as_int
from polar_sim.geometry import between2d

__all__ = ["RelationErrors", "relation_errors", "relation_scores"]


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
    P = as_float_array(poses, "poses")
    if P.ndim != 2 or P.shape[1] != 3 or not np.isfinite(P).all():
        raise ValueError(f"poses: expected finite (n, 3) poses, got shape {P.shape}")
    if pairs is None or isinstance(pairs, (str, bytes)):
        raise TypeError(f"pairs: expected a (k, 2) integer array, got {type(pairs).__name__}")
    ij = np.asarray(pairs)
    if ij.dtype.kind not in "iu":
        raise TypeError(f"pairs: expected integer indices, got dtype {ij.dtype}")
    if ij.ndim != 2 or ij.shape[1] != 2 or ij.dtype.kind not in "iu" or len(ij) == 0:
        raise ValueError(f"pairs: expected a non-empty (k, 2) integer array, got shape {ij.shape}, dtype {ij.dtype}")
    if ij.min() < 0 or ij.max() >= len(P):
        raise ValueError(f"pairs: indices must lie in [0, {len(P)}), got [{ij.min()}, {ij.max()}]")
    R = as_float_array(reference, "reference")
    if R.shape != (len(ij), 3) or not np.isfinite(R).all():
        raise ValueError(f"reference: expected finite shape ({len(ij)}, 3), got {R.shape}")
    est = between2d(P[ij[:, 0]], P[ij[:, 1]])
    eps = between2d(R, est)   # delta (-) delta*: the estimated relation in the reference's frame
    t = np.hypot(eps[:, 0], eps[:, 1])
    r = np.degrees(np.abs((eps[:, 2] + np.pi) % (2 * np.pi) - np.pi))
    return RelationErrors(t, r, len(t), float(t.mean()), float(t.std()), float((t * t).mean()), float((t * t).std()),
                          float(t.max()), float(r.mean()), float(r.std()), float((r * r).mean()), float((r * r).std()),
                          float(r.max()))


def relation_scores(trajectories, t_abs, relations, *, local_gap=5):
    """Relation errors of each trajectory on the benchmark relations among its poses.

    Parameters
    ----------
    trajectories : dict
        ``{name: poses (n, 3)}``: estimated poses (x, y, theta), m and rad, at the times ``t_abs``.
    t_abs : (n,) times of the poses, s, each time once (in any order: the Intel Lab log's
        timestamps step back four times).
    relations : (r, 5) rows ``(t_a, t_b, dx, dy, dtheta)`` (Kümmerle et al. 2009); those whose two
        times are both in ``t_abs`` are scored.
    local_gap : int, default=5
        A relation is *local* when its two scans are at most ``local_gap`` apart in the log, else
        a *loop* (a place revisited).

    Returns
    -------
    dict
        ``{name}{part}_{trans_mean_m, trans_max_m, rot_mean_deg, rot_max_deg}`` for part in "",
        "_local", "_loop" (a part without relations is left out), and ``n_relations``,
        ``n_loop_relations``.
    """
    t = as_float_array(t_abs, "t_abs")
    if t.ndim != 1 or not np.isfinite(t).all():
        raise ValueError(f"t_abs: expected finite times of shape (n,), got shape {t.shape}")
    order = np.argsort(t, kind="stable")
    if (np.diff(t[order]) == 0).any():
        raise ValueError("t_abs: a time occurs twice, so a relation at it would name two scans")
    rel = as_float_array(relations, "relations")
    if rel.ndim != 2 or rel.shape[1] != 5 or not np.isfinite(rel).all():
        raise ValueError(f"relations: expected finite rows (t_a, t_b, dx, dy, dtheta) of shape (r, 5), got {rel.shape}")
    local_gap = as_int(local_gap, "local_gap", minimum=0)
    if not isinstance(trajectories, dict):
        raise TypeError(f"trajectories: expected a dict {{name: poses (n, 3)}}, got {type(trajectories).__name__}")
    ok = np.isin(rel[:, 0], t) & np.isin(rel[:, 1], t)
    pairs = order[np.column_stack([np.searchsorted(t[order], rel[ok, 0]), np.searchsorted(t[order], rel[ok, 1])])]
    loop = np.abs(pairs[:, 1] - pairs[:, 0]) > local_gap
    out = {}
    for name, P in trajectories.items():
        P = as_float_array(P, f"trajectories[{name!r}]")
        if P.shape != (len(t), 3):
            raise ValueError(f"trajectories[{name!r}]: expected one pose (x, y, theta) per time, shape ({len(t)}, 3), "
                             f"got {P.shape}")
        for part, sel in (("", np.ones(len(pairs), bool)), ("_local", ~loop), ("_loop", loop)):
            if not sel.any():
                continue
            e = relation_errors(P, pairs[sel], rel[ok, 2:][sel])
            out.update({f"{name}{part}_trans_mean_m": e.trans_mean, f"{name}{part}_trans_max_m": e.trans_max,
                        f"{name}{part}_rot_mean_deg": e.rot_mean_deg, f"{name}{part}_rot_max_deg": e.rot_max_deg})
    out.update(n_loop_relations=int(loop.sum()), n_relations=int(ok.sum()))
    return out
