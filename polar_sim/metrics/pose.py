"""Pose metrics: ADD, ADD-S, 5 cm / 5 deg, AUC, success rates and the BOP errors VSD, MSSD, MSPD.
The rates of a run over selected frames, their pooling over runs, and a rank correlation are at the end.

Conventions: poses are 4x4 ``T_cam_obj`` (object to camera), one pose (4, 4) or a stack (n, 4, 4);
model points (m, 3) in the object frame, metres; errors in metres (ADD, ADD-S, MSSD), pixels
(MSPD), radians (rotation), or unitless (VSD). Rates are fractions in [0, 1] (multiply by 100 for
the YCB-Video / BOP tables). Definitions: Hinterstoisser et al. (ADD, ADD-S and the 0.1 d
criterion), PoseCNN / YCB-Video (AUC of ADD up to 10 cm), and the BOP toolkit (Hodan et al.: VSD
with BOP19 visibility, MSSD, MSPD and their thresholds), re-implemented from the definitions.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from polar_sim.geometry import diameter
from polar_sim._validation import as_float, as_float_array, as_int, as_intrinsics, as_points, as_pose, as_positive_float

__all__ = [
    "object_diameter",
    "add",
    "adds",
    "rotation_error",
    "translation_error",
    "success_5cm5deg",
    "add_success",
    "success_rate",
    "success_curve",
    "pose_auc",
    "frames_until_loss",
    "rotation_drift",
    "static_segments",
    "static_rotation_drift",
    "StaticDrift",
    "pose_frame_errors",
    "mssd",
    "mspd",
    "vsd",
    "render_depth",
    "bop_recall",
    "ar_vsd",
    "ar_mssd",
    "ar_mspd",
    "BOP_VSD_TAUS",
    "BOP_VSD_THETAS",
    "BOP_MSSD_FRACTIONS",
    "BOP_MSPD_PIXELS",
    "add_success_rate",
    "success_5cm5deg_rate",
    "pooled_rate",
    "spearman",
]

#: BOP19 VSD misalignment tolerances tau (fractions of the diameter) and correctness thresholds.
BOP_VSD_TAUS = np.arange(0.05, 0.51, 0.05)
BOP_VSD_THETAS = np.arange(0.05, 0.51, 0.05)
#: BOP19 MSSD thresholds (fractions of the diameter) and MSPD thresholds (pixels at 640 wide).
BOP_MSSD_FRACTIONS = np.arange(0.05, 0.51, 0.05)
BOP_MSPD_PIXELS = np.arange(5, 51, 5).astype(float)
#: The largest image side :func:`render_depth` renders, pixels.
MAX_IMAGE_SIDE = 16384


def _as_poses(T, name):
    """(n, 4, 4) stack of checked poses and whether the input was a single pose."""
    a = as_float_array(T, name)  # refuses strings, bools, complex and object arrays by name
    if a.ndim == 2:
        return as_pose(a, name)[None], True
    if a.ndim != 3 or a.shape[1:] != (4, 4):
        raise ValueError(f"{name}: expected a 4x4 pose or a stack (n, 4, 4), got shape {a.shape}")
    return np.stack([as_pose(t, f"{name}[{i}]") for i, t in enumerate(a)]) if len(a) else a, False


def _pair(T_gt, T_est):
    G, single_g = _as_poses(T_gt, "T_gt")
    E, single_e = _as_poses(T_est, "T_est")
    if len(G) != len(E):
        raise ValueError(f"T_gt and T_est: expected the same number of poses, got {len(G)} and {len(E)}")
    return G, E, single_g and single_e


def _out(x, single):
    return float(x[0]) if single else x


def _as_errors(e, name="errors"):
    a = as_float_array(e, name).ravel()
    if a.size == 0:
        raise ValueError(f"{name}: expected at least one error value")
    if np.isnan(a).any() or (a < 0).any():
        raise ValueError(f"{name}: expected non-negative errors (inf allowed), got NaN or negatives")
    return a


def object_diameter(points):
    """Largest distance between two model points (m, 3), metres (exact, through the convex hull)."""
    return diameter(as_points(points, 3, "points"))


def add(model_points, T_gt, T_est):
    """ADD: mean distance between model points under the true and the estimated pose, metres.

    One pose pair gives a float; stacks (n, 4, 4) give (n,).
    """
    P = as_points(model_points, 3, "model_points")
    G, E, single = _pair(T_gt, T_est)
    out = np.empty(len(G))
    for i, (g, e) in enumerate(zip(G, E)):
        out[i] = np.linalg.norm(P @ (e[:3, :3] - g[:3, :3]).T + (e[:3, 3] - g[:3, 3]), axis=1).mean()
    return _out(out, single)


def adds(model_points, T_gt, T_est):
    """ADD-S (ADI): mean over estimated points of the distance to the closest true point, metres."""
    P = as_points(model_points, 3, "model_points")
    G, E, single = _pair(T_gt, T_est)
    tree = cKDTree(P)
    out = np.empty(len(G))
    for i, (g, e) in enumerate(zip(G, E)):
        # estimated points expressed in the true object frame, matched against the model itself
        Q = (P @ e[:3, :3].T + e[:3, 3] - g[:3, 3]) @ g[:3, :3]
        out[i] = tree.query(Q, k=1)[0].mean()
    return _out(out, single)


def rotation_error(T_gt, T_est):
    """Angle of R_est R_gt^T, radians (float or (n,))."""
    G, E, single = _pair(T_gt, T_est)
    c = (np.einsum("nij,nij->n", E[:, :3, :3], G[:, :3, :3]) - 1.0) / 2.0
    return _out(np.arccos(np.clip(c, -1.0, 1.0)), single)


def translation_error(T_gt, T_est):
    """Distance between the translations, metres (float or (n,))."""
    G, E, single = _pair(T_gt, T_est)
    return _out(np.linalg.norm(E[:, :3, 3] - G[:, :3, 3], axis=1), single)


def success_5cm5deg(T_gt, T_est, *, max_translation=0.05, max_rotation=np.deg2rad(5.0)):
    """Fraction of poses with translation error < 5 cm and rotation error < 5 deg (radians given)."""
    te = np.atleast_1d(translation_error(T_gt, T_est))
    re = np.atleast_1d(rotation_error(T_gt, T_est))
    max_translation, max_rotation = _limits(max_translation, max_rotation)
    return float(np.mean((te < max_translation) & (re < max_rotation)))


def _limits(max_translation, max_rotation):
    """The 5 cm / 5 deg limits, m and rad: numbers >= 0 (inf: no limit)."""
    return (as_float(max_translation, "max_translation", minimum=0.0, allow_inf=True),
            as_float(max_rotation, "max_rotation", minimum=0.0, allow_inf=True))


def add_success(errors, diameter, k=0.1):
    """Fraction of ADD (or ADD-S) errors below k * diameter (headline k = 0.1)."""
    e = _as_errors(errors)
    d = as_positive_float(diameter, "diameter")
    as_positive_float(k, "k")
    return float(np.mean(e < k * d))


def success_rate(errors, threshold):
    """SR(theta) = fraction of errors <= threshold."""
    e = _as_errors(errors)
    return float(np.mean(e <= as_float(threshold, "threshold", allow_inf=True)))


def success_curve(errors, thresholds):
    """Success rate (len(thresholds),) at each threshold (errors <= threshold)."""
    e = np.sort(_as_errors(errors))
    th = _thresholds(thresholds, "thresholds")
    return np.searchsorted(e, th, side="right") / len(e)


def pose_auc(errors, max_threshold=0.10):
    """Area under the success-rate curve over [0, max_threshold], normalised to [0, 1].

    The YCB-Video convention (PoseCNN's VOC-style integral of the accuracy-threshold curve of ADD
    or ADD-S up to 10 cm). The integral of the empirical success curve has the closed form
    ``mean(max(0, 1 - e / max_threshold))``.
    """
    e = _as_errors(errors)
    m = as_positive_float(max_threshold, "max_threshold")
    return float(np.mean(np.clip(1.0 - e / m, 0.0, 1.0)))


def frames_until_loss(errors, threshold, patience=10):
    """Index of the first frame of the first run of ``patience`` frames with error > threshold
    (the number of frames tracked before the loss); len(errors) if the track is never lost.

    The tracking protocol of the spec uses ADD > 0.3 d for 10 frames."""
    e = _as_errors(errors)
    bad = e > as_float(threshold, "threshold", allow_inf=True)
    patience = as_int(patience, "patience", minimum=1)
    run = 0
    for i, b in enumerate(bad):
        run = run + 1 if b else 0
        if run >= patience:
            return i - patience + 1
    return len(e)


# -- drift of objects at rest --------------------------------------------------------------
def rotation_drift(T_gt, T_est, start=0):
    """Rotation drift (n - start,) in radians from frame ``start`` on: the angle between the
    estimate's rotation since ``start``, ``R_est(k) R_est(start)^T``, and the object's true one,
    ``R_gt(k) R_gt(start)^T`` (both in the camera frame, so a constant error of the estimate's
    orientation is not drift). For an object at rest it is how far the estimate has turned.

    The full rotation counts, including the turn about a symmetry axis that ADD-S cannot see."""
    G, E, _ = _pair(T_gt, T_est)
    s = as_int(start, "start")
    if not 0 <= s < len(G):
        raise ValueError(f"start: expected a frame index in [0, {len(G)}), got {start!r}")
    Rg = np.einsum("nij,kj->nik", G[s:, :3, :3], G[s, :3, :3])  # R_gt(k) R_gt(s)^T
    Re = np.einsum("nij,kj->nik", E[s:, :3, :3], E[s, :3, :3])
    c = (np.einsum("nij,nij->n", Rg, Re) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def static_segments(T_gt, *, max_rotation=np.deg2rad(1.0), max_translation=0.002, min_frames=30):
    """Runs of frames in which the true pose stays at rest: ``[(start, stop), ...]`` (stop exclusive).

    A run grows while every frame's true pose is within ``max_rotation`` (rad) and
    ``max_translation`` (m) of the run's first frame; runs shorter than ``min_frames`` are dropped.
    The poses are camera-frame: with a moving camera nothing is at rest."""
    G, _ = _as_poses(T_gt, "T_gt")
    as_positive_float(max_rotation, "max_rotation")
    as_positive_float(max_translation, "max_translation")
    min_frames = as_int(min_frames, "min_frames", minimum=1)
    out, s = [], 0
    n = len(G)
    while s < n:
        c = (np.einsum("ij,nij->n", G[s, :3, :3], G[s:, :3, :3]) - 1.0) / 2.0
        far = (np.arccos(np.clip(c, -1.0, 1.0)) > max_rotation) | \
              (np.linalg.norm(G[s:, :3, 3] - G[s, :3, 3], axis=1) > max_translation)
        e = s + (int(np.argmax(far)) if far.any() else n - s)
        if e - s >= min_frames:
            out.append((s, e))
        s = max(e, s + 1)
    return out


@dataclasses.dataclass(frozen=True)
class StaticDrift:
    """Rotation drift of an object at rest (:func:`static_rotation_drift`).

    Attributes
    ----------
    segments : list of (start, stop) runs of frames at rest.
    drift : (len(segments),) largest drift within the first ``horizon`` frames of each run, rad.
    end_drift : (len(segments),) drift at the last of those frames, rad.
    frames : (len(segments),) frames scored per run (at most ``horizon``).
    max_drift : largest of ``drift`` (NaN without a run at rest), rad.
    """

    segments: list
    drift: np.ndarray
    end_drift: np.ndarray
    frames: np.ndarray
    max_drift: float


def static_rotation_drift(T_gt, T_est, *, horizon=300, **segment_kw):
    """How far the estimated rotation of an object at rest drifts: for every run at rest
    (:func:`static_segments`, keyword arguments passed on), the largest :func:`rotation_drift`
    within its first ``horizon`` frames. The issue-13 target is 2 deg over 300 frames."""
    G, E, _ = _pair(T_gt, T_est)
    horizon = as_int(horizon, "horizon", minimum=2)
    segs = static_segments(G, **segment_kw)
    drift, end, frames = [], [], []
    for s, e in segs:
        e = min(e, s + int(horizon))
        d = rotation_drift(G[s:e], E[s:e])
        drift.append(float(d.max()))
        end.append(float(d[-1]))
        frames.append(e - s)
    drift = np.array(drift)
    return StaticDrift(segs, drift, np.array(end), np.array(frames, dtype=np.int64),
                       float(drift.max()) if len(drift) else float("nan"))


def pose_frame_errors(model_points, K, T_gt, T_est):
    """Per-frame pose errors of a track, stacks (n, 4, 4): dict of (n,) arrays ``add``, ``adds``
    (m), ``rot`` (rad), ``trans`` (m), ``mssd`` (m) and ``mspd`` (px)."""
    return dict(add=np.atleast_1d(add(model_points, T_gt, T_est)), adds=np.atleast_1d(adds(model_points, T_gt, T_est)),
                rot=np.atleast_1d(rotation_error(T_gt, T_est)), trans=np.atleast_1d(translation_error(T_gt, T_est)),
                mssd=np.atleast_1d(mssd(model_points, T_gt, T_est)),
                mspd=np.atleast_1d(mspd(model_points, K, T_gt, T_est)))


# -- BOP ------------------------------------------------------------------------------------
def _symmetries(symmetries):
    if symmetries is None:
        return np.eye(4)[None]
    S, _ = _as_poses(symmetries, "symmetries")
    return S


def mssd(model_points, T_gt, T_est, symmetries=None):
    """Maximum Symmetry-aware Surface Distance, metres: min over symmetry transforms S (object
    frame, (k, 4, 4); identity if None) of max_x |T_est x - T_gt S x|."""
    P = as_points(model_points, 3, "model_points")
    G, E, single = _pair(T_gt, T_est)
    S = _symmetries(symmetries)
    out = np.empty(len(G))
    for i, (g, e) in enumerate(zip(G, E)):
        pe = P @ e[:3, :3].T + e[:3, 3]
        best = np.inf
        for s in S:
            gs = g @ s
            best = min(best, float(np.linalg.norm(pe - (P @ gs[:3, :3].T + gs[:3, 3]), axis=1).max()))
        out[i] = best
    return _out(out, single)


def _project(K, X):
    return np.stack([K[0, 0] * X[:, 0] / X[:, 2] + K[0, 2], K[1, 1] * X[:, 1] / X[:, 2] + K[1, 2]], 1)


def mspd(model_points, K, T_gt, T_est, symmetries=None):
    """Maximum Symmetry-aware Projection Distance, pixels: min_S max_x |pi(T_est x) - pi(T_gt S x)|."""
    P = as_points(model_points, 3, "model_points")
    K = as_intrinsics(K, "K")
    G, E, single = _pair(T_gt, T_est)
    S = _symmetries(symmetries)
    out = np.empty(len(G))
    for i, (g, e) in enumerate(zip(G, E)):
        ue = _project(K, P @ e[:3, :3].T + e[:3, 3])
        best = np.inf
        for s in S:
            gs = g @ s
            ug = _project(K, P @ gs[:3, :3].T + gs[:3, 3])
            best = min(best, float(np.linalg.norm(ue - ug, axis=1).max()))
        out[i] = best
    return _out(out, single)


def render_depth(model_points, K, T, shape, *, radius_px=None):
    """Depth image (H, W) float32 of model points under pose T (4, 4) by z-buffered point splats.

    Each point is a disc of ``radius_px`` pixels (default: half the mean point spacing at the
    points' median depth, at least 1). 0 where nothing projects. A stand-in for a mesh renderer,
    good for VSD when points are dense (the tolerances are centimetres).
    """
    import cv2

    P = as_points(model_points, 3, "model_points")
    K = as_intrinsics(K, "K")
    T = as_pose(T, "T")
    H, W = _image_shape(shape)
    if radius_px is not None:
        radius_px = as_int(radius_px, "radius_px", minimum=0, maximum=1000)
    X = P @ T[:3, :3].T + T[:3, 3]
    X = X[X[:, 2] > 1e-6]
    out = np.zeros((H, W), np.float32)
    if len(X) == 0:
        return out
    if radius_px is None:
        d, _ = cKDTree(P).query(P, k=2) if len(P) > 1 else (np.zeros((1, 2)), None)
        spacing = 2.0 * float(np.mean(d[:, 1]))
        radius_px = max(1, int(np.ceil(K[0, 0] * spacing / (2.0 * float(np.median(X[:, 2]))))))
    r = int(radius_px)
    uv = np.rint(_project(K, X)).astype(np.int64) + r
    ok = (uv[:, 0] >= 0) & (uv[:, 0] < W + 2 * r) & (uv[:, 1] >= 0) & (uv[:, 1] < H + 2 * r)
    buf = np.full((H + 2 * r, W + 2 * r), np.inf, np.float32)
    np.minimum.at(buf, (uv[ok, 1], uv[ok, 0]), X[ok, 2].astype(np.float32))
    ker = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    buf = cv2.erode(np.where(np.isfinite(buf), buf, 1e9).astype(np.float32), ker)[r : r + H, r : r + W]
    out[buf < 1e8] = buf[buf < 1e8]
    return out


def _dist_image(depth, K):
    H, W = depth.shape
    u = (np.arange(W) - K[0, 2]) / K[0, 0]
    v = (np.arange(H) - K[1, 2]) / K[1, 1]
    return depth * np.sqrt(u[None, :] ** 2 + v[:, None] ** 2 + 1.0)


def _image_shape(shape):
    """(H, W) of an image to render: two integers in 1..MAX_IMAGE_SIDE."""
    if shape is None or isinstance(shape, (str, bytes)):
        raise TypeError(f"shape: expected (H, W), got {type(shape).__name__}")
    if np.shape(shape) != (2,):
        raise ValueError(f"shape: expected (H, W), got shape {np.shape(shape)}")
    return tuple(as_int(v, "shape", minimum=1, maximum=MAX_IMAGE_SIDE) for v in shape)


def _as_depth_image(d, name, shape=None):
    a = as_float_array(d, name)
    if a.ndim != 2 or (shape is not None and a.shape != shape):
        raise ValueError(f"{name}: expected a depth image of shape {shape or '(H, W)'}, got {a.shape}")
    a = np.where(np.isfinite(a), a, 0.0)
    if (a < 0).any():
        raise ValueError(f"{name}: contains negative depths")
    return a


def vsd(depth_est, depth_gt, depth_test, K, diameter, *, taus=BOP_VSD_TAUS, delta=0.015,
        normalized_by_diameter=True, cost="step"):
    """Visible Surface Discrepancy (BOP19) for each misalignment tolerance tau: array (len(taus),).

    Parameters
    ----------
    depth_est, depth_gt : (H, W) depth of the model rendered at the estimated / true pose, metres
        (0 where the model is absent), e.g. from :func:`render_depth` or the simulator.
    depth_test : (H, W) the test (sensor) depth image, metres, 0 = missing.
    K : (3, 3) intrinsics (depths are converted to distances from the camera centre, as BOP does).
    diameter : object diameter, metres.
    taus : tolerances, fractions of the diameter when ``normalized_by_diameter`` else metres.
    delta : visibility tolerance, metres (15 mm in BOP19).
    cost : "step" (BOP) or "tlinear".

    Notes
    -----
    Visibility (BOP19): a rendered pixel is visible if it has depth and the test depth is missing
    or not more than ``delta`` in front of it; the estimate's visible mask also includes the pixels
    where the true model is visible and the estimate has depth. The error is the mean cost over the
    union of both masks, cost 0 where both are visible and their distances differ by < tau.
    """
    K = as_intrinsics(K, "K")
    de = _as_depth_image(depth_est, "depth_est")
    dg = _as_depth_image(depth_gt, "depth_gt", de.shape)
    dt = _as_depth_image(depth_test, "depth_test", de.shape)
    d = as_positive_float(diameter, "diameter")
    delta = as_float(delta, "delta", minimum=0.0)
    if cost not in ("step", "tlinear"):
        raise ValueError(f"cost: unknown value {cost!r}; expected 'step' or 'tlinear'")
    de, dg, dt = _dist_image(de, K), _dist_image(dg, K), _dist_image(dt, K)
    vis_gt = (dg > 0) & ((dg - dt <= delta) | (dt == 0))
    vis_est = ((de > 0) & ((de - dt <= delta) | (dt == 0))) | (vis_gt & (de > 0))
    inter = vis_gt & vis_est
    union = int((vis_gt | vis_est).sum())
    taus = _thresholds(taus, "taus")
    if union == 0:
        return np.ones(len(taus))
    diff = np.abs(dg[inter] - de[inter])
    if normalized_by_diameter:
        diff = diff / d
    n_outside = union - int(inter.sum())
    out = np.empty(len(taus))
    for i, tau in enumerate(taus):
        c = (diff >= tau).astype(float) if cost == "step" else np.minimum(diff / tau, 1.0)
        out[i] = (c.sum() + n_outside) / union
    return out


def bop_recall(errors, thresholds):
    """Mean over thresholds of the fraction of errors strictly below each threshold.

    ``errors`` (n,) for MSSD / MSPD, or (n, n_tau) for VSD (averaged over tau too)."""
    return _recall(errors, "errors", _thresholds(thresholds, "thresholds"))


def _thresholds(x, name):
    """Thresholds (k,), k >= 1, without NaN (inf allowed), from a number or any array."""
    th = as_float_array(x, name).ravel()
    if th.size == 0 or np.isnan(th).any():
        raise ValueError(f"{name}: expected at least one threshold, none NaN")
    return th


def _recall(errors, name, th):
    """:func:`bop_recall` of ``errors`` (named ``name``) at checked thresholds ``th`` (k,)."""
    e = as_float_array(errors, name)
    if e.size == 0 or np.isnan(e).any():
        raise ValueError(f"{name}: expected a non-empty array without NaN")
    return float(np.mean([(e < t).mean() for t in th]))


def ar_vsd(vsd_errors, thetas=BOP_VSD_THETAS):
    """AR_VSD: recall averaged over the VSD thresholds theta and the tolerances (n, n_tau)."""
    return _recall(vsd_errors, "vsd_errors", _thresholds(thetas, "thetas"))


def ar_mssd(mssd_errors, diameter, fractions=BOP_MSSD_FRACTIONS):
    """AR_MSSD: recall averaged over thresholds fractions * diameter (metres)."""
    return _recall(mssd_errors, "mssd_errors", _thresholds(fractions, "fractions") * as_positive_float(diameter, "diameter"))


def ar_mspd(mspd_errors, image_width, pixels=BOP_MSPD_PIXELS):
    """AR_MSPD: recall averaged over thresholds pixels * image_width / 640."""
    return _recall(mspd_errors, "mspd_errors",
                   _thresholds(pixels, "pixels") * as_positive_float(image_width, "image_width") / 640.0)


# -- rates of a run, pooled over runs -------------------------------------------------------
def _selected(flags, where, name):
    """Boolean flags (n,) of the frames selected by ``where`` (n,) bool (every frame if None)."""
    f = np.asarray(flags)
    if f.dtype != bool or f.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D boolean array, got {f.dtype} {f.shape}")
    if where is None:
        return f
    w = np.asarray(where)
    if w.dtype != bool:
        raise TypeError(f"where: expected a boolean array, got dtype {w.dtype}")
    if w.shape != f.shape:
        raise ValueError(f"where: expected a boolean array of shape {f.shape}, got {w.shape}")
    return f[w]


def _rate(flags):
    return float(flags.mean()) if flags.size else float("nan")


def add_success_rate(errors, diameter, k=0.1, *, where=None):
    """Fraction of the frames selected by ``where`` (n,) bool (all if None) whose ADD or ADD-S
    error (n,) m is below ``k * diameter``; NaN when no frame is selected.

    As :func:`add_success`, for a subset of a run's frames, e.g. those of occlusion by touch."""
    e = as_float_array(errors, "errors")
    if e.ndim != 1 or np.isnan(e).any() or (e < 0).any():
        raise ValueError(f"errors: expected a 1-D array of non-negative errors (inf allowed), got shape {e.shape}")
    d = as_positive_float(diameter, "diameter")
    as_positive_float(k, "k")
    return _rate(_selected(e < k * d, where, "errors"))


def success_5cm5deg_rate(rotation, translation, *, where=None, max_translation=0.05, max_rotation=np.deg2rad(5.0)):
    """Fraction of the frames selected by ``where`` with translation error (n,) m below 5 cm and
    rotation error (n,) rad below 5 deg (:func:`success_5cm5deg` from per-frame errors); NaN
    when no frame is selected."""
    r, t = as_float_array(rotation, "rotation"), as_float_array(translation, "translation")
    if r.ndim != 1 or t.shape != r.shape:
        raise ValueError(f"rotation, translation: expected two 1-D arrays of one length, got {r.shape} and {t.shape}")
    max_translation, max_rotation = _limits(max_translation, max_rotation)
    return _rate(_selected((t < max_translation) & (r < max_rotation), where, "rotation"))


def pooled_rate(rates, weights):
    """Weighted mean of per-run rates (k,): the rate over every frame of the runs when ``weights``
    (k,) are their frame counts. Runs with a NaN rate or a weight of 0 are left out; NaN if none
    is left."""
    v, w = as_float_array(rates, "rates"), as_float_array(weights, "weights")
    if v.ndim != 1 or w.shape != v.shape:
        raise ValueError(f"rates, weights: expected two 1-D arrays of one length, got {v.shape} and {w.shape}")
    if not (np.isfinite(w) & (w >= 0)).all():
        raise ValueError("weights: expected finite weights >= 0")
    ok = np.isfinite(v) & (w > 0)
    return float((v[ok] * w[ok]).sum() / w[ok].sum()) if ok.any() else float("nan")


def spearman(x, y):
    """Spearman rank correlation of x and y (n,) (ties take their mean rank); NaN for fewer than
    3 pairs or a constant input, where it is undefined."""
    from scipy.stats import spearmanr

    a, b = as_float_array(x, "x"), as_float_array(y, "y")
    if a.ndim != 1 or b.shape != a.shape:
        raise ValueError(f"x, y: expected two 1-D arrays of one length, got {a.shape} and {b.shape}")
    if not np.isfinite(a).all():
        raise ValueError("x: contains NaN or inf")
    if not np.isfinite(b).all():
        raise ValueError("y: contains NaN or inf")
    if len(a) < 3 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return float("nan")
    return float(spearmanr(a, b).statistic)
