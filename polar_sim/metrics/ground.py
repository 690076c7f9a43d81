"""Ground-module metrics (spec ``ground.md`` §8.2–8.5): RANSAC success rate ps with precision and F1,
the exponential fit of ps against RANSAC iterations, the Laplace scale of the raw speed error, and the
classifier's IoU and ROC AUC against a true ground mask."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import rankdata

__all__ = [
    "GroundSuccess",
    "ground_success",
    "SuccessCurve",
    "fit_success_curve",
    "laplace_scale",
    "classifier_iou",
    "classifier_auc",
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
    e = np.asarray(errors, dtype=np.float64).ravel()
    if e.size == 0:
        raise ValueError("errors: expected at least one value")
    if not np.isfinite(e).all():
        raise ValueError("errors: contains NaN or inf (drop frames without a scale fit first)")
    return float(np.mean(np.abs(e)))


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
