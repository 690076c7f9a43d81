"""Ground-module metrics (spec ``ground.md`` §8.2–8.5): RANSAC success rate ps with precision and F1,
the exponential fit of ps against RANSAC iterations, the Laplace scale of the raw speed error, and the
classifier's IoU and ROC AUC against a true ground mask."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import rankdata

from polar_sim._validation import as_float_array
from polar_sim.metrics.calibration import _inputs

__all__ = [
    "GroundSuccess",
    "ground_success",
    "SuccessCurve",
    "fit_success_curve",
    "laplace_scale",
    "speed_error_scales",
    "iou_summary",
    "classifier_iou",
    "classifier_auc",
    "labels_at",
    "oracle_step_speeds",
    "class_prob_sums",
    "class_mean_prob_bounds",
    "pool_by_family",
    "kitti_scores",
    "kitti_scores_pooled",
]


@dataclass(frozen=True)
class GroundSuccess:
    """ps (recall), precision and F1 of RANSAC ground inliers against true ground candidates.

    ps = Σ|I ∩ G| / Σ|G|, precision = Σ|I ∩ G| / Σ|I|, pooled over frames (NaN when a denominator is 0).
    """

    ps: float
    precision: float
    f1: float
    n_ground: int
    n_inliers: int
    n_true_inliers: int


def _bool_list(x, name):
    if isinstance(x, np.ndarray) and x.dtype != object and x.ndim == 1:
        x = [x]
    out = []
    for i, a in enumerate(x):
        a = np.asarray(a)
        if a.ndim != 1:
            raise ValueError(f"{name}[{i}]: expected a 1-D boolean mask, got shape {a.shape}")
        if a.dtype != bool:
            if not np.isin(a, (0, 1)).all():
                raise ValueError(f"{name}[{i}]: expected booleans (or 0/1), got values outside 0/1")
            a = a.astype(bool)
        out.append(a)
    return out


def ground_success(is_ground, is_inlier):
    """ps, precision and F1 (spec §8.2) from per-frame masks over the RANSAC candidates.

    Parameters
    ----------
    is_ground : (m,) bool or a sequence of them (one per frame)
        The true ground mask at each candidate's middle-frame pixel.
    is_inlier : same shapes
        RANSAC inliers among the candidates.
    """
    g = _bool_list(is_ground, "is_ground")
    i = _bool_list(is_inlier, "is_inlier")
    if len(g) != len(i):
        raise ValueError(f"expected one inlier mask per ground mask: is_ground has {len(g)}, is_inlier has {len(i)}")
    for k, (a, b) in enumerate(zip(g, i)):
        if a.shape != b.shape:
            raise ValueError(f"is_inlier[{k}]: expected shape {a.shape} like is_ground[{k}], got {b.shape}")
    n_g = int(sum(a.sum() for a in g))
    n_i = int(sum(b.sum() for b in i))
    n_gi = int(sum((a & b).sum() for a, b in zip(g, i)))
    ps = n_gi / n_g if n_g else float("nan")
    prec = n_gi / n_i if n_i else float("nan")
    f1 = 2 * ps * prec / (ps + prec) if n_g and n_i and (ps + prec) > 0 else float("nan")
    return GroundSuccess(ps, prec, f1, n_g, n_i, n_gi)


@dataclass(frozen=True)
class SuccessCurve:
    """Fit of ps(N) = p_max - (p_max - p_0) p^N (spec Eq. 4.14).

    ``n95``: iterations to reach 95 % of p_max (inf if p_0 >= 0.95 p_max is not the case and p >= 1;
    0 if p_0 already reaches it). ``cost``: half the sum of squared residuals.
    """

    p_max: float
    p_0: float
    p: float
    n95: float
    cost: float

    def __call__(self, n_iter):
        """Fitted ps at iteration counts ``n_iter``."""
        n = np.asarray(n_iter, dtype=np.float64)
        return self.p_max - (self.p_max - self.p_0) * self.p**n


def fit_success_curve(n_iter, ps):
    """Least-squares fit of ps(N) = p_max - (p_max - p_0) p^N over all (N, ps) pairs (spec §8.3).

    Bounds 0 <= p_0 <= p_max <= 1 and 0 < p < 1 (p_0 is fitted as r p_max with r in [0, 1]).
    n_iter, ps : (k,) iteration counts (>= 0) and success rates in [0, 1], one pair per repetition.
    """
    N = np.asarray(n_iter, dtype=np.float64).ravel()
    y = np.asarray(ps, dtype=np.float64).ravel()
    if N.shape != y.shape or len(N) < 3:
        raise ValueError(f"expected at least 3 (n_iter, ps) pairs of equal length, got {N.shape} and {y.shape}")
    if not (np.isfinite(N).all() and np.isfinite(y).all()):
        raise ValueError("n_iter, ps: contain NaN or inf")
    if (N < 0).any() or (y < 0).any() or (y > 1).any():
        raise ValueError("n_iter must be >= 0 and ps in [0, 1]")

    def resid(x):
        pmax, r, p = x
        return pmax - (pmax - r * pmax) * p**N - y

    eps = 1e-9
    x0 = [min(max(y.max(), 0.05), 1.0), 0.5, 0.8]
    sol = least_squares(resid, x0, bounds=([0.0, 0.0, eps], [1.0, 1.0, 1.0 - eps]))
    pmax, r, p = (float(v) for v in sol.x)
    p0 = r * pmax
    if pmax <= 0 or p0 >= 0.95 * pmax:
        n95 = 0.0
    else:
        n95 = math.log(0.05 * pmax / (pmax - p0)) / math.log(p)
    return SuccessCurve(pmax, p0, p, n95, float(sol.cost))


def laplace_scale(errors):
    """Maximum-likelihood scale b of a zero-mean Laplace law: mean |e| (ΔV_mean of spec §8.4).

    errors : (n,) finite, e.g. raw RANSAC speed minus true speed (m/s) over frames with a fit.
    """
    e = as_float_array(errors, "errors").ravel()    # strings and complex numbers: TypeError
    if e.size == 0:
        raise ValueError("errors: expected at least one value")
    if not np.isfinite(e).all():
        raise ValueError("errors: contains NaN or inf (drop frames without a scale fit first)")
    return float(np.mean(np.abs(e)))


def speed_error_scales(speed_raw, speed, speed_true):
    """ΔV_mean (Laplace scale, m/s) of a VO's raw and filtered speeds against the truth.

    ``speed_raw``, ``speed`` (n,): the values reported with image k, which describe the middle frame
    k - 1 (central-difference flow), so they are compared with ``speed_true[k - 1]`` (n,); raw speeds
    that are NaN (no ground fit) are left out. Returns (dv_raw, dv_filtered); dv_raw is NaN when no
    image has a raw speed.
    """
    raw, filt, true = (np.asarray(a, dtype=np.float64) for a in (speed_raw, speed, speed_true))
    n = len(true)
    if raw.shape != (n,) or filt.shape != (n,) or n < 2:
        raise ValueError(f"speed_raw, speed, speed_true: expected equal shapes (n,), n >= 2; got {raw.shape}, "
                         f"{filt.shape}, {true.shape}")
    mid, ok = np.arange(n) - 1, np.isfinite(raw) & (np.arange(n) >= 1)
    dv_raw = laplace_scale(raw[ok] - true[mid[ok]]) if ok.any() else float("nan")
    return dv_raw, laplace_scale(filt[1:] - true[:-1])


def iou_summary(iou, settled, scored, target):
    """Per-route statistics of a per-frame IoU series (n,): over the ``settled`` frames (n,) bool the
    mean, 10th percentile and share >= ``target``; the mean over the ``scored`` frames (n,) bool that
    are not settled (transitions), and over all ``scored`` frames. NaN where a set is empty; NaN IoUs
    (no ground and no prediction) are left out."""
    iou = np.asarray(iou, dtype=np.float64)
    s = np.asarray(settled, bool) & np.isfinite(iou)
    scored = np.asarray(scored, bool)
    trans = scored & ~np.asarray(settled, bool)
    nan = float("nan")
    return {"n_settled": int(s.sum()), "iou_settled_mean": float(np.mean(iou[s])) if s.any() else nan,
            "iou_settled_p10": float(np.percentile(iou[s], 10)) if s.any() else nan,
            "share_settled_ge_target": float(np.mean(iou[s] >= target)) if s.any() else nan,
            "iou_transition_mean": float(np.mean(iou[trans])) if trans.any() else nan,
            "iou_all_mean": float(np.nanmean(iou[scored])) if np.isfinite(iou[scored]).any() else nan}


def _maps(prob, gt_mask, valid):
    p = np.asarray(prob, dtype=np.float64)
    g = np.asarray(gt_mask)
    if p.shape != g.shape:
        raise ValueError(f"gt_mask: expected shape {p.shape} like prob, got {g.shape}")
    if g.dtype != bool:
        raise ValueError(f"gt_mask: expected a boolean mask, got dtype {g.dtype}")
    if not np.isfinite(p).all():
        raise ValueError("prob: contains NaN or inf")
    if valid is not None:
        v = np.asarray(valid)
        if v.shape != p.shape or v.dtype != bool:
            raise ValueError(f"valid: expected a boolean mask of shape {p.shape}, got {v.dtype} {v.shape}")
        return p[v], g[v]
    return p.ravel(), g.ravel()


def classifier_iou(prob, gt_mask, *, threshold=0.5, valid=None):
    """IoU of the thresholded ground probability (prob > threshold) with the true ground mask.

    prob : (H, W) P(ground); gt_mask : (H, W) bool; valid : optional (H, W) bool of pixels to score.
    NaN when both masks are empty.
    """
    p, g = _maps(prob, gt_mask, valid)
    pred = p > threshold
    union = np.count_nonzero(pred | g)
    return float(np.count_nonzero(pred & g) / union) if union else float("nan")


def classifier_auc(prob, gt_mask, *, valid=None):
    """Pixel ROC AUC of the ground probability against the true mask (ties count one half).

    Mann–Whitney form: AUC = (Σ ranks of ground pixels - n_g (n_g + 1)/2) / (n_g n_ng), with average
    ranks over ties. NaN when one class is absent.
    """
    p, g = _maps(prob, gt_mask, valid)
    n_g = int(g.sum())
    n_ng = g.size - n_g
    if n_g == 0 or n_ng == 0:
        return float("nan")
    ranks = rankdata(p)
    return float((ranks[g].sum() - n_g * (n_g + 1) / 2.0) / (n_g * n_ng))


def labels_at(mask, xy):
    """The boolean ``mask`` (H, W) at pixel positions ``xy`` (m, 2) (column, row), rounded to the
    nearest pixel and clamped to the image: e.g. the true ground label of RANSAC candidates."""
    m = np.asarray(mask)
    if m.ndim != 2 or m.dtype != bool:
        raise ValueError(f"mask: expected a 2-D boolean mask, got {m.dtype} {m.shape}")
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if not np.isfinite(p).all():
        raise ValueError("xy: contains NaN or inf")
    if len(p) == 0:
        return np.zeros(0, dtype=bool)
    H, W = m.shape
    c = np.clip(np.rint(p[:, 0]).astype(np.intp), 0, W - 1)
    r = np.clip(np.rint(p[:, 1]).astype(np.intp), 0, H - 1)
    return m[r, c]


def oracle_step_speeds(times, step_lengths):
    """Per-image speeds that make every integration step exactly as long as the true step.

    With the B27 convention of :func:`polar_sim.ground.integration.integrate` the step k-1 -> k uses
    ``speeds[k]``, so ``speeds[k] = step_lengths[k] / (t_k - t_{k-1})`` (m/s); the step 0 -> 1 reuses
    ``speeds[2]`` there, the one compromise. ``times`` (n,) s, ``step_lengths`` (n,) m (entry 0 unused).
    """
    t = np.asarray(times, dtype=np.float64)
    s = np.asarray(step_lengths, dtype=np.float64)
    if t.ndim != 1 or s.shape != t.shape:
        raise ValueError(f"times, step_lengths: expected equal 1-D shapes, got {t.shape} and {s.shape}")
    dt = np.r_[1.0, np.diff(t)]
    if (dt[1:] <= 0).any():
        raise ValueError("times: must increase strictly")
    return s / dt


def class_prob_sums(prob, labels, *, valid=None):
    """(sum of p on true ground, ground pixel count, sum of p on non-ground, non-ground count), (4,)
    float64: add over frames; ``sums[0] / sums[1]`` is the mean P(ground) on ground pixels."""
    p, y = _inputs(prob, labels, valid)
    y = y.astype(bool)
    return np.array([p[y].sum(dtype=np.float64), y.sum(), p[~y].sum(dtype=np.float64), (~y).sum()], np.float64)


def class_mean_prob_bounds(count, prob_sum, label_sum):
    """Mean P(ground) on ground and on non-ground pixels from summed
    :func:`~polar_sim.metrics.calibration.reliability_counts` alone.

    The bins hold no per-class sum of p, so each class's mean is estimated with the bin's mean
    confidence, and bounded by the bin edges (every pixel of bin k has p in [k/n, (k+1)/n]).
    Returns ``{"ground": (estimate, low, high), "nonground": (...)}``; NaN for an empty class.
    """
    c = np.asarray(count, dtype=np.float64)
    ps, ys = np.asarray(prob_sum, dtype=np.float64), np.asarray(label_sum, dtype=np.float64)
    n = len(c)
    lo, hi = np.arange(n) / n, np.arange(1, n + 1) / n
    conf = np.where(c > 0, ps / np.maximum(c, 1), 0.0)
    out = {}
    for name, w in (("ground", ys), ("nonground", c - ys)):
        tot = w.sum()
        out[name] = tuple(float(np.sum(w * x) / tot) if tot > 0 else float("nan") for x in (conf, lo, hi))
    return out


def pool_by_family(series):
    """Pool per-frame scores of routes by ground family (the settled frames of every zone).

    ``series``: an iterable of mappings with ``families`` (zone family names), ``settled`` (n,) bool,
    ``zone`` (n,) zone index, ``iou`` (n,) and ``bins`` (n, 3, n_bins) per-frame
    :func:`~polar_sim.metrics.calibration.reliability_counts`; optionally ``psums`` (n, 4) per-frame
    :func:`class_prob_sums`. Returns ``{family: dict(frames, iou_mean, bins (3, n_bins), psums (4,) or
    None, p_ground, p_nonground)}``, sorted by name: ``p_ground``/``p_nonground`` are the mean P(ground)
    on true ground / non-ground pixels, exact from ``psums`` or, without them, the bins' estimate
    (:func:`class_mean_prob_bounds`, within one bin width).
    """
    fam = {}
    for a in series:
        for k, name in enumerate(a["families"]):
            m = np.asarray(a["settled"], bool) & (np.asarray(a["zone"]) == k) & np.isfinite(a["iou"])
            if m.sum():
                f = fam.setdefault(str(name), {"iou": [], "bins": 0.0, "psums": 0.0, "has_psums": "psums" in a})
                f["iou"].append(np.asarray(a["iou"])[m])
                f["bins"] = f["bins"] + np.asarray(a["bins"])[m].sum(axis=0)
                f["has_psums"] &= "psums" in a
                if "psums" in a:
                    f["psums"] = f["psums"] + np.asarray(a["psums"])[m].sum(axis=0)
    out = {}
    for k, v in sorted(fam.items()):
        ps = v["psums"] if v["has_psums"] else None
        pm = (ps[0] / ps[1], ps[2] / ps[3]) if ps is not None else \
            tuple(class_mean_prob_bounds(*v["bins"])[c][0] for c in ("ground", "nonground"))
        out[k] = dict(frames=int(sum(len(i) for i in v["iou"])), iou_mean=float(np.mean(np.concatenate(v["iou"]))),
                      bins=v["bins"], psums=ps, p_ground=pm[0], p_nonground=pm[1])
    return out


def kitti_scores(gt, est, prefix=""):
    """The ground chapter's odometry scores of one route (a dict, keys prefixed with ``prefix``):
    KITTI devkit ``t_pct`` (%) / ``r_degm`` (deg/m) over 100-800 m segments (NaN under 100 m), the same
    over the non-standard scaled segments (``*_scaled``, L_j = j L_max / 8), ``n_segments`` and ``ate_m``."""
    from polar_sim import metrics

    t, r = metrics.kitti_errors(gt, est)
    ts, rs = metrics.kitti_errors(gt, est, lengths=metrics.scaled_lengths(gt))
    return {f"{prefix}t_pct": t, f"{prefix}r_degm": r, f"{prefix}n_segments": len(metrics.kitti_segment_errors(gt, est)),
            f"{prefix}t_pct_scaled": ts, f"{prefix}r_degm_scaled": rs, f"{prefix}ate_m": metrics.ate(gt, est)}


def kitti_scores_pooled(pairs):
    """Scores pooled over all segments of all routes: ``pairs`` [(gt, est), ...] -> dict(routes, t_pct,
    r_degm (100-800 m segments), t_pct_scaled, r_degm_scaled (each route's scaled segments))."""
    from polar_sim import metrics

    t, r = metrics.kitti_errors_pooled(pairs)
    rec = np.concatenate([metrics.kitti_segment_errors(g, e, lengths=metrics.scaled_lengths(g)) for g, e in pairs])
    return dict(routes=len(pairs), t_pct=t, r_degm=r, t_pct_scaled=100 * float(np.mean(rec["t_err"])),
                r_degm_scaled=float(np.degrees(np.mean(rec["r_err"]))))
