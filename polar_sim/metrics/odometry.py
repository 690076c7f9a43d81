"""Odometry metrics: KITTI segment errors (as the devkit), ATE, RPE, and KITTI/TUM trajectory files.

Poses are stacks (n, 4, 4) of camera-to-reference transforms (KITTI: camera k in camera 0's frame).

The KITTI metric follows the devkit's ``evaluate_odometry.cpp`` step for step: path lengths
accumulated in float32 from float32 frame-to-frame distances, first frames every 10 images, segment
lengths 100..800 m, the end frame the first whose path length exceeds start + L, errors of
``inv(inv(E_a) E_b) inv(G_a) G_b`` divided by the nominal L and stored in float32, and the mean taken
in float32 over all records. The trajectory writers are the only file I/O in :mod:`polar_sim.metrics`;
they exist so that ``evo`` (``evo_ape kitti``/``tum``) reads what the modules estimate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from polar_sim._validation import as_float_array, as_int, as_points, as_positive_float, check_choice
from polar_sim.fileio import atomic_write, check_source
from polar_sim.geometry import rigid_alignment

__all__ = [
    "KITTI_LENGTHS",
    "kitti_segment_errors",
    "kitti_errors",
    "kitti_errors_pooled",
    "scaled_lengths",
    "ate_errors",
    "ate",
    "rpe_errors",
    "rpe",
    "RPE",
    "umeyama",
    "write_kitti",
    "read_kitti",
    "write_tum",
    "read_tum",
]

#: Segment lengths of the KITTI odometry benchmark, m.
KITTI_LENGTHS = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)


def _as_poses(x, name, *, tol=1e-4):
    """Return a finite (n, 4, 4) float64 stack of rigid transforms (n >= 1)."""
    a = as_float_array(x, name)
    if a.ndim != 3 or a.shape[1:] != (4, 4) or a.shape[0] < 1:
        raise ValueError(f"{name}: expected shape (n, 4, 4) with n >= 1, got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: contains NaN or inf")
    if not np.allclose(a[:, 3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise ValueError(f"{name}: last row of every pose must be (0, 0, 0, 1)")
    R = a[:, :3, :3]
    err = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max()
    if err > tol or (np.linalg.det(R) < 0).any():
        raise ValueError(f"{name}: rotation blocks are not proper rotations (max |RᵀR - I| = {err:.2g})")
    return a


def _as_lengths(lengths):
    """Segment lengths (k,) in metres: a non-empty sequence of finite numbers > 0."""
    a = as_float_array(lengths, "lengths")
    if a.ndim != 1 or len(a) == 0:
        raise ValueError(f"lengths: expected a non-empty sequence of segment lengths (m), got shape {a.shape}")
    if not (np.isfinite(a) & (a > 0)).all():
        raise ValueError(f"lengths: expected finite lengths > 0 m, got {a.tolist()[:8]}")
    return tuple(float(x) for x in a)


def _pair(gt_poses, est_poses):
    gt = _as_poses(gt_poses, "gt_poses")
    est = _as_poses(est_poses, "est_poses")
    if len(gt) != len(est):
        raise ValueError(f"expected one estimated pose per ground-truth pose: gt_poses has {len(gt)}, "
                         f"est_poses has {len(est)}")
    return gt, est


def _inv(T):
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def _trajectory_distances(gt):
    """Devkit ``trajectoryDistances``: float32 cumulative path length (n,)."""
    d = (gt[1:, :3, 3] - gt[:-1, :3, 3]).astype(np.float32)
    step = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2], dtype=np.float32)
    return np.concatenate([np.zeros(1, np.float32), np.cumsum(step, dtype=np.float32)])


def scaled_lengths(gt_poses, n=8):
    """Non-standard segment lengths L_j = j L_max / n, j = 1..n, for routes shorter than 800 m (spec §8.1).

    L_max is the largest multiple of 10 m not above 90 % of the route length. Label results that use
    them as non-standard.
    """
    gt = _as_poses(gt_poses, "gt_poses")
    n = as_int(n, "n", minimum=1, maximum=10_000)
    total = float(_trajectory_distances(gt)[-1])
    lmax = np.floor(0.9 * total / 10.0) * 10.0
    if lmax <= 0:
        raise ValueError(f"gt_poses: route of {total:.3g} m is too short for segment errors")
    return tuple(lmax * j / n for j in range(1, n + 1))


def kitti_segment_errors(gt_poses, est_poses, *, lengths=KITTI_LENGTHS, step=10, frame_period=0.1):
    """Per-segment records of the KITTI devkit (``calcSequenceErrors``).

    Returns a structured array with fields ``first`` (start frame), ``r_err`` (rad/m), ``t_err``
    (m/m), ``length`` (m) and ``speed`` (m/s, = L / (frame_period (b - a + 1)) as in the devkit), all
    float32 like the devkit's records except ``first``.
    """
    gt, est = _pair(gt_poses, est_poses)
    lengths = _as_lengths(lengths)
    step = as_int(step, "step", minimum=1)
    frame_period = as_positive_float(frame_period, "frame_period")
    dist = _trajectory_distances(gt)
    recs = []
    n = len(gt)
    for a in range(0, n, step):
        for L in lengths:
            Lf = np.float32(L)
            target = np.float32(dist[a] + Lf)
            idx = np.flatnonzero(dist[a:] > target)
            if len(idx) == 0:
                continue
            b = a + int(idx[0])
            dgt = _inv(gt[a]) @ gt[b]
            dest = _inv(est[a]) @ est[b]
            E = _inv(dest) @ dgt
            # Devkit: float a, b, c (the diagonal), d = 0.5 (a + b + c - 1), acos(clamp(d, -1, 1)).
            tr = np.float32(E[0, 0]) + np.float32(E[1, 1]) + np.float32(E[2, 2])
            dd = np.float32(0.5) * (tr - np.float32(1.0))
            r = np.float32(np.arccos(np.clip(dd, np.float32(-1.0), np.float32(1.0))))
            tx, ty, tz = (np.float32(E[i, 3]) for i in range(3))
            t = np.float32(np.sqrt(tx * tx + ty * ty + tz * tz))
            num = b - a + 1
            recs.append((a, np.float32(r / Lf), np.float32(t / Lf), Lf, np.float32(Lf / (frame_period * num))))
    dtype = [("first", np.int64), ("r_err", np.float32), ("t_err", np.float32), ("length", np.float32),
             ("speed", np.float32)]
    return np.array(recs, dtype=dtype)


def _summarise(recs):
    if len(recs) == 0:
        return float("nan"), float("nan")
    t = np.float32(0.0)
    r = np.float32(0.0)
    for rec in recs:  # the devkit sums in float32, in record order
        t = np.float32(t + rec["t_err"])
        r = np.float32(r + rec["r_err"])
    num = np.float32(len(recs))
    return float(np.float32(t / num)) * 100.0, float(np.float32(r / num)) * 180.0 / np.pi


def kitti_errors(gt_poses, est_poses, *, lengths=KITTI_LENGTHS, step=10):
    """KITTI odometry error of one sequence: (translation %, rotation deg/m).

    Mean over all segments (first frames every ``step`` images, lengths ``lengths`` in m) as the
    KITTI devkit computes it. Returns (nan, nan) when the route is too short for any segment (see
    :func:`scaled_lengths` for a labelled non-standard variant).
    """
    return _summarise(kitti_segment_errors(gt_poses, est_poses, lengths=lengths, step=step))


def kitti_errors_pooled(sequences, *, lengths=KITTI_LENGTHS, step=10):
    """Pooled KITTI error over several sequences ``[(gt_poses, est_poses), ...]``: the mean over all
    segments of all sequences (the devkit's "all" average; long sequences weigh more)."""
    if isinstance(sequences, (str, bytes, dict)) or not hasattr(sequences, "__iter__"):
        raise TypeError(f"sequences: expected a list of (gt_poses, est_poses) pairs, got {type(sequences).__name__}")
    sequences = list(sequences)
    for i, pair in enumerate(sequences):
        if not isinstance(pair, (tuple, list)) or len(pair) != 2:
            raise ValueError(f"sequences: item {i} is not a (gt_poses, est_poses) pair")
    recs = [kitti_segment_errors(g, e, lengths=lengths, step=step) for g, e in sequences]
    if not recs:
        return float("nan"), float("nan")
    return _summarise(np.concatenate(recs))


# ---------------------------------------------------------------------------------------------------
# ATE / RPE


def umeyama(src, dst, *, with_scale=False):
    """Least-squares similarity (R (3, 3), t (3,), s) with dst ≈ s R src + t (Umeyama 1991); src, dst (n, 3)."""
    src = as_points(src, 3, "src")
    dst = as_points(dst, 3, "dst")
    if len(src) != len(dst):
        raise ValueError(f"src, dst: expected equal lengths, got {len(src)} and {len(dst)}")
    return rigid_alignment(src, dst, with_scale=with_scale)


def ate_errors(gt_poses, est_poses, *, align="se3"):
    """Absolute trajectory (position) error per frame (n,), m, after alignment.

    align : "se3" (rigid Umeyama), "sim3" (with scale) or "none" (poses compared as given, e.g. both
    relative to their own first frame).
    """
    gt, est = _pair(gt_poses, est_poses)
    check_choice(align, ("se3", "sim3", "none"), "align")
    p_gt, p_est = gt[:, :3, 3], est[:, :3, 3]
    if align != "none" and len(gt) >= 2:
        R, t, s = umeyama(p_est, p_gt, with_scale=align == "sim3")
        p_est = s * p_est @ R.T + t
    return np.linalg.norm(p_est - p_gt, axis=1)


def ate(gt_poses, est_poses, *, align="se3"):
    """Absolute trajectory error: RMSE of the per-frame position errors (m) after alignment."""
    e = ate_errors(gt_poses, est_poses, align=align)
    return float(np.sqrt(np.mean(e**2)))


def rpe_errors(gt_poses, est_poses, *, delta=1):
    """Relative pose errors over ``delta`` frames: translation (m) and rotation (deg), each (n - delta,).

    E_i = (G_i⁻¹ G_{i+δ})⁻¹ (P_i⁻¹ P_{i+δ}), as evo's RPE.
    """
    gt, est = _pair(gt_poses, est_poses)
    delta = as_int(delta, "delta", minimum=1)
    if len(gt) <= delta:
        raise ValueError(f"delta: {delta} frames needs at least {delta + 1} poses, got {len(gt)}")
    dg = _inv(gt[:-delta]) @ gt[delta:]
    de = _inv(est[:-delta]) @ est[delta:]
    E = _inv(dg) @ de
    t = np.linalg.norm(E[:, :3, 3], axis=1)
    c = np.clip((np.trace(E[:, :3, :3], axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return t, np.degrees(np.arccos(c))


@dataclass(frozen=True)
class RPE:
    """Relative pose error summary: RMSE and mean of translation (m) and rotation (deg) over pairs."""

    trans_rmse: float
    rot_rmse: float
    trans_mean: float
    rot_mean: float
    delta: int


def rpe(gt_poses, est_poses, delta=1):
    """Relative pose error over ``delta`` frames (see :func:`rpe_errors`); returns an :class:`RPE`."""
    t, r = rpe_errors(gt_poses, est_poses, delta=delta)
    return RPE(float(np.sqrt(np.mean(t**2))), float(np.sqrt(np.mean(r**2))), float(t.mean()), float(r.mean()),
               int(delta))


# ---------------------------------------------------------------------------------------------------
# trajectory files


def write_kitti(path, poses):
    """Write poses (n, 4, 4) as a KITTI pose file: 12 numbers (top 3x4 block, row-major) per line."""
    P = _as_poses(poses, "poses")
    with atomic_write(path, "path") as fh:
        np.savetxt(fh, P[:, :3, :].reshape(len(P), 12), fmt="%.17g", delimiter=" ")


def read_kitti(path):
    """Read a KITTI pose file into (n, 4, 4)."""
    a = _read_table(path)
    if a.shape[1] != 12:
        raise ValueError(f"path: expected 12 numbers per line in a KITTI pose file, got {a.shape[1]}")
    P = np.tile(np.eye(4), (len(a), 1, 1))
    P[:, :3, :] = a.reshape(-1, 3, 4)
    return P


def write_tum(path, timestamps, poses):
    """Write a TUM trajectory: ``timestamp tx ty tz qx qy qz qw`` per line (s, m, unit quaternion)."""
    P = _as_poses(poses, "poses")
    ts = as_float_array(timestamps, "timestamps")
    if ts.shape != (len(P),):
        raise ValueError(f"timestamps: expected shape ({len(P)},) to match the poses, got {ts.shape}")
    if not np.isfinite(ts).all():
        raise ValueError("timestamps: contains NaN or inf")
    q = Rotation.from_matrix(P[:, :3, :3]).as_quat()  # (x, y, z, w), TUM order
    with atomic_write(path, "path") as fh:
        np.savetxt(fh, np.column_stack([ts, P[:, :3, 3], q]), fmt="%.17g", delimiter=" ")


def read_tum(path):
    """Read a TUM trajectory; returns (timestamps (n,), poses (n, 4, 4)). Lines starting with # are skipped."""
    a = _read_table(path)
    if a.shape[1] != 8:
        raise ValueError(f"path: expected 8 numbers per line in a TUM file, got {a.shape[1]}")
    if not np.allclose(np.linalg.norm(a[:, 4:8], axis=1), 1.0, atol=1e-3):
        raise ValueError("path: the quaternions (qx qy qz qw) of a TUM file must have unit norm")
    P = np.tile(np.eye(4), (len(a), 1, 1))
    P[:, :3, :3] = Rotation.from_quat(a[:, 4:8]).as_matrix()
    P[:, :3, 3] = a[:, 1:4]
    return a[:, 0].copy(), P


def _read_table(path):
    """Rows of numbers of a whitespace-separated text file (# comments), as a finite (n, k) array."""
    p = check_source(path, "path")
    try:
        a = np.loadtxt(p, dtype=np.float64, ndmin=2, comments="#")
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"path: {str(p)[:200]!r} is not a table of numbers ({str(exc).splitlines()[0][:120]})") from None
    if a.size == 0:
        raise ValueError(f"path: {str(p)[:200]!r} holds no poses")
    if not np.isfinite(a).all():
        raise ValueError(f"path: {str(p)[:200]!r} contains NaN or inf")
    return a
