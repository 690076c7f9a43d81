"""Segmentation metrics: IoU and its success rate, precision/recall, occluder-as-target fraction,
ROC AUC of probability maps; the rates of a run from per-frame scores (:func:`mask_frame_scores`),
and the calibration error of a run's probability maps from per-frame reliability counts.

Masks are boolean arrays (H, W) or stacks (n, H, W). Rates are fractions in [0, 1].
"""

from __future__ import annotations

import numpy as np

from polar_sim._validation import as_float, as_float_array, as_int

__all__ = [
    "iou",
    "iou_success",
    "iou_success_curve",
    "precision_recall",
    "occluder_as_target",
    "roc_auc",
    "near_mask",
    "mask_frame_scores",
    "iou_success_rate",
    "pooled_precision_recall",
    "pooled_occluder_as_target",
    "pooled_ece",
]


def _as_bool_array(m, name):
    """``m`` as a boolean ndarray of any shape: booleans, or integers that are all 0 or 1.

    Strings, complex numbers, objects and None are the wrong kind (``TypeError``); other numbers
    the wrong value (``ValueError``)."""
    if m is None or isinstance(m, (str, bytes)):
        raise TypeError(f"{name}: expected a boolean mask, got {type(m).__name__}")
    if not isinstance(m, np.ndarray):
        try:
            m = np.asarray(m)
        except ValueError as exc:  # ragged: "inhomogeneous shape"
            raise ValueError(f"{name}: expected a rectangular boolean mask, got a ragged {type(m).__name__}") from exc
    if m.dtype == bool:
        return m
    if m.dtype.kind not in "iuf":
        raise TypeError(f"{name}: expected a boolean mask (or 0/1 integers), got dtype {m.dtype}")
    if not (m.dtype.kind in "iu" and np.isin(m, (0, 1)).all()):
        raise ValueError(f"{name}: expected a boolean mask (or 0/1 integers), got dtype {m.dtype}")
    return m.astype(bool)


def _as_mask(m, name, like=None, like_name=None):
    """A mask (H, W) or stack (n, H, W); given ``like`` (the mask it is compared with, named
    ``like_name``), of its shape."""
    m = _as_bool_array(m, name)
    if m.ndim not in (2, 3):
        raise ValueError(f"{name}: expected shape (H, W) or (n, H, W), got {m.shape}")
    if like is not None and m.shape != like.shape:
        # which of the two is wrong is the caller's to say: name both
        raise ValueError(f"{like_name}, {name}: expected one shape, got {like.shape} and {m.shape}")
    return m


def iou(mask_a, mask_b):
    """Intersection over union of two masks; (n, H, W) stacks give (n,). Two empty masks give 1."""
    a = _as_mask(mask_a, "mask_a")
    b = _as_mask(mask_b, "mask_b", a, "mask_a")
    ax = (-2, -1)
    inter = np.logical_and(a, b).sum(axis=ax)
    union = np.logical_or(a, b).sum(axis=ax)
    out = np.where(union > 0, inter / np.maximum(union, 1), 1.0)
    return float(out) if a.ndim == 2 else out.astype(float)


def iou_success(ious, threshold=0.5):
    """Fraction of frames whose IoU exceeds ``threshold`` (headline 0.5)."""
    v = _ious(ious)
    return float(np.mean(v > as_float(threshold, "threshold")))


def _ious(x):
    """IoUs (n,), n >= 1, without NaN, from any array."""
    v = as_float_array(x, "ious").ravel()
    if v.size == 0 or np.isnan(v).any():
        raise ValueError("ious: expected a non-empty array without NaN")
    return v


def iou_success_curve(ious, thresholds=None):
    """Success curve over IoU thresholds (default 101 from 0 to 1) and its mean (the AUC).

    Returns ``(thresholds, rates, auc)``."""
    v = _ious(ious)
    th = np.linspace(0.0, 1.0, 101) if thresholds is None else as_float_array(thresholds, "thresholds").ravel()
    if th.size == 0 or np.isnan(th).any():
        raise ValueError("thresholds: expected at least one threshold, none NaN")
    rates = np.array([np.mean(v > t) for t in th])
    return th, rates, float(rates.mean())


def precision_recall(pred, gt):
    """Pooled precision and recall of a predicted mask (or stack) against the truth.

    Precision is 1 when nothing is predicted; recall is 1 when the truth is empty."""
    p = _as_mask(pred, "pred")
    g = _as_mask(gt, "gt", p, "pred")
    tp = int(np.logical_and(p, g).sum())
    npred, ngt = int(p.sum()), int(g.sum())
    return (tp / npred if npred else 1.0), (tp / ngt if ngt else 1.0)


def occluder_as_target(pred, occluder, within=None):
    """Fraction of occluder (hand) pixels labelled as target, pooled over a stack.

    ``within`` (same shape, optional) restricts the count to occluder pixels inside it, e.g. the
    target's amodal silhouette, dilated: the hand pixels that actually touch or cover the object,
    so a large hand elsewhere in the image does not dilute the figure. NaN if no occluder pixel
    is counted."""
    p = _as_mask(pred, "pred")
    o = _as_mask(occluder, "occluder", p, "pred")
    if within is not None:
        o = o & _as_mask(within, "within", p, "pred")
    n = int(o.sum())
    return float(np.logical_and(p, o).sum() / n) if n else float("nan")


def roc_auc(scores, labels):
    """Area under the ROC curve of per-pixel scores against boolean labels (ties count one half).

    Computed from ranks (Mann-Whitney U); raises if one class is absent."""
    s = as_float_array(scores, "scores").ravel()
    y = _as_bool_array(labels, "labels").ravel()
    if s.shape != y.shape:
        raise ValueError(f"scores, labels: expected one value per label, got {s.shape[0]} scores and {y.shape[0]} labels")
    if not np.isfinite(s).all():
        raise ValueError("scores: contains NaN or inf")
    npos, nneg = int(y.sum()), int((~y).sum())
    if npos == 0 or nneg == 0:
        raise ValueError("labels: both classes are needed for a ROC AUC")
    order = np.argsort(s, kind="mergesort")
    ss = s[order]
    ranks = np.empty(len(s))
    # average ranks over ties
    _, first, counts = np.unique(ss, return_index=True, return_counts=True)
    avg = first + (counts - 1) / 2.0 + 1.0
    ranks[order] = np.repeat(avg, counts)
    return float((ranks[y].sum() - npos * (npos + 1) / 2.0) / (npos * nneg))


def near_mask(mask, radius_px):
    """Pixels (H, W) within ``radius_px`` (Euclidean) of a mask: the mask dilated by a disc.

    Used to count the hand pixels that touch or cover an object (its amodal mask, dilated)."""
    from scipy.ndimage import distance_transform_edt

    m = _as_mask(mask, "mask")
    if m.ndim != 2:
        raise ValueError(f"mask: expected shape (H, W), got {m.shape}")
    radius_px = as_int(radius_px, "radius_px", minimum=0)
    out = np.zeros(m.shape, bool)
    ys, xs = np.nonzero(m)
    if not len(ys):
        return out
    r = int(radius_px)
    y0, y1 = max(ys.min() - r, 0), min(ys.max() + r + 1, m.shape[0])
    x0, x1 = max(xs.min() - r, 0), min(xs.max() + r + 1, m.shape[1])
    out[y0:y1, x0:x1] = distance_transform_edt(~m[y0:y1, x0:x1]) <= r
    return out


def mask_frame_scores(pred, truth, occluder=None, within=None):
    """Per-frame counts of a predicted mask (H, W) against the true visible mask: a dict with
    ``iou``, ``n_pred``, ``n_gt``, ``n_tp`` and, given an ``occluder`` mask, ``hand_all`` /
    ``hand_all_tgt`` (occluder pixels, and those labelled target) and ``hand_near`` /
    ``hand_near_tgt`` (the same inside ``within``, e.g. :func:`near_mask` of the amodal mask).

    Pooled rates follow from the sums: precision = sum n_tp / sum n_pred, the occluder-as-target
    fraction = sum hand_near_tgt / sum hand_near."""
    p = _as_mask(pred, "pred")
    g = _as_mask(truth, "truth", p, "pred")
    if p.ndim != 2:
        raise ValueError(f"pred: expected one frame (H, W), got {p.shape}")
    out = {"iou": iou(p, g), "n_pred": int(p.sum()), "n_gt": int(g.sum()), "n_tp": int(np.logical_and(p, g).sum())}
    if occluder is not None:
        o = _as_mask(occluder, "occluder", p, "pred")
        out["hand_all"], out["hand_all_tgt"] = int(o.sum()), int(np.logical_and(p, o).sum())
        near = o & _as_mask(within, "within", p, "pred") if within is not None else o
        out["hand_near"], out["hand_near_tgt"] = int(near.sum()), int(np.logical_and(p, near).sum())
    return out


# -- rates of a run from per-frame scores ---------------------------------------------------
def _where(where, n):
    if where is None:
        return np.ones(n, bool)
    w = np.asarray(where)
    if w.dtype != bool:
        raise TypeError(f"where: expected a boolean array, got dtype {w.dtype}")
    if w.shape != (n,):
        raise ValueError(f"where: expected a boolean array of shape ({n},), got {w.shape}")
    return w


def _counts(x, name):
    if x is None or isinstance(x, (str, bytes)):
        raise TypeError(f"{name}: expected a 1-D array of pixel counts, got {type(x).__name__}")
    c = np.asarray(x)
    if c.dtype.kind not in "iu":
        raise TypeError(f"{name}: expected integer pixel counts, got dtype {c.dtype}")
    if c.ndim != 1 or (c < 0).any():
        raise ValueError(f"{name}: expected a 1-D array of pixel counts >= 0, got {c.dtype} {c.shape}")
    return c.astype(np.int64, copy=False)


def iou_success_rate(ious, threshold=0.5, *, where=None):
    """Fraction of the frames selected by ``where`` (n,) bool (all if None) whose IoU (n,) exceeds
    ``threshold``; NaN when no frame is selected (:func:`iou_success` for a subset of a run)."""
    v = as_float_array(ious, "ious")
    if v.ndim != 1 or np.isnan(v).any():
        raise ValueError(f"ious: expected a 1-D array without NaN, got shape {v.shape}")
    ok = (v > as_float(threshold, "threshold"))[_where(where, len(v))]
    return float(ok.mean()) if ok.size else float("nan")


def pooled_precision_recall(n_tp, n_pred, n_gt):
    """Precision and recall pooled over frames from per-frame pixel counts (n,) of true
    positives, predicted and true pixels: sum n_tp / sum n_pred and sum n_tp / sum n_gt; 1 when
    nothing is predicted, or nothing is true (as :func:`precision_recall`)."""
    tp, npred, ngt = _counts(n_tp, "n_tp"), _counts(n_pred, "n_pred"), _counts(n_gt, "n_gt")
    if npred.shape != tp.shape or ngt.shape != tp.shape:
        raise ValueError(f"n_tp, n_pred, n_gt: expected one length, got {tp.shape}, {npred.shape}, {ngt.shape}")
    if (tp > npred).any() or (tp > ngt).any():
        raise ValueError("n_tp: more true positives than predicted or true pixels")
    t, p, g = tp.sum(), npred.sum(), ngt.sum()
    return (float(t / p) if p else 1.0), (float(t / g) if g else 1.0)


def pooled_occluder_as_target(n_occluder, n_occluder_target, *, where=None):
    """Fraction of occluder (hand) pixels labelled target, pooled over the frames (or runs)
    selected by ``where``: sum n_occluder_target / sum n_occluder from counts (n,) such as
    :func:`mask_frame_scores`' ``hand_near`` and ``hand_near_tgt``. NaN if no occluder pixel is
    counted (as :func:`occluder_as_target`)."""
    n, nt = _counts(n_occluder, "n_occluder"), _counts(n_occluder_target, "n_occluder_target")
    if nt.shape != n.shape or (nt > n).any():
        raise ValueError(f"n_occluder_target: expected {n.shape} counts <= n_occluder, got {nt.shape}")
    w = _where(where, len(n))
    h = n[w].sum()
    return float(nt[w].sum() / h) if h else float("nan")


def pooled_ece(counts):
    """Expected calibration error of probability maps pooled over frames (and runs).

    ``counts`` (..., 3, n_bins): per-frame reliability counts (pixel count, sum of p, sum of labels
    per bin, as :func:`polar_sim.metrics.reliability_counts` gives them), added over the leading
    axes; the ECE of the sums is :func:`polar_sim.metrics.pooled_reliability`'s. NaN when no pixel
    is counted (a method without a probability map).
    """
    from polar_sim.metrics import pooled_reliability   # where the reliability statistics live

    c = as_float_array(counts, "counts")     # strings, complex numbers, None: TypeError
    if c.ndim < 2 or c.shape[-2] != 3 or c.shape[-1] < 1:
        raise ValueError(f"counts: expected an array of reliability counts of shape (..., 3, n_bins), got {c.shape}")
    c, p, y = c.reshape(-1, 3, c.shape[-1]).sum(axis=0)
    if not (np.isfinite(c).all() and np.isfinite(p).all() and np.isfinite(y).all()) or (c < 0).any():
        raise ValueError("counts: expected finite counts and sums, counts >= 0")
    return pooled_reliability(c, p, y).ece if c.sum() else float("nan")
