"""Calibration of probability maps: expected calibration error and reliability diagrams.

A probability is calibrated when, among the pixels given P = p, a fraction p are positive. The
modules' P(ground) and P(target) are scored this way against the true masks. One binning serves all:
:func:`reliability_counts` gives a frame's per-bin sums, which add over frames, and
:func:`pooled_reliability` turns (summed) counts into a :class:`Reliability`; :func:`reliability` is the
two in one. Drawing the diagram is the experiments' business (no plotting here).

Probabilities and labels are arrays of the same shape (any, e.g. (H, W) or (n, H, W)); a
``valid`` mask, if given, selects the pixels that count (e.g. only those in the image's region of
interest).
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["reliability", "Reliability", "expected_calibration_error", "reliability_counts", "pooled_reliability"]


@dataclasses.dataclass(frozen=True)
class Reliability:
    """Per-bin statistics of a reliability diagram (equal-width bins over [0, 1]).

    Attributes
    ----------
    edges : (n_bins + 1,) bin edges.
    count : (n_bins,) number of samples per bin.
    confidence : (n_bins,) mean predicted probability per bin (NaN for an empty bin).
    frequency : (n_bins,) fraction of positives per bin (NaN for an empty bin).
    ece : expected calibration error, sum over bins of count/N * |frequency - confidence|.
    mce : maximum calibration error over the non-empty bins.
    n : number of samples.
    """

    edges: np.ndarray
    count: np.ndarray
    confidence: np.ndarray
    frequency: np.ndarray
    ece: float
    mce: float
    n: int


def _inputs(prob, labels, valid):
    p = np.asarray(prob)
    if p.dtype.kind not in "fiu" or p.dtype == bool:
        raise TypeError(f"prob: expected a float array of probabilities, got dtype {p.dtype}")
    p = p.astype(np.float64, copy=False)
    y = np.asarray(labels)
    if y.dtype != bool:
        if y.dtype.kind not in "iu" or not np.isin(y, (0, 1)).all():
            raise ValueError(f"labels: expected a boolean array (or 0/1 integers), got dtype {y.dtype}")
        y = y.astype(bool)
    if y.shape != p.shape:
        raise ValueError(f"labels: expected shape {p.shape} to match prob, got {y.shape}")
    if valid is not None:
        v = np.asarray(valid)
        if v.dtype != bool or v.shape != p.shape:
            raise ValueError(f"valid: expected a boolean array of shape {p.shape}, got {v.dtype} {v.shape}")
        p, y = p[v], y[v]
    p, y = p.ravel(), y.ravel()
    if p.size == 0:
        raise ValueError("prob: no samples to score")
    if not np.isfinite(p).all() or p.min() < 0.0 or p.max() > 1.0:
        raise ValueError("prob: expected finite probabilities in [0, 1]")
    return p, y


def reliability_counts(prob, labels, *, n_bins=15, valid=None):
    """Per-bin sufficient statistics of a reliability diagram: (count, sum of p, sum of labels), each
    (n_bins,), over ``n_bins`` equal bins [0, 1/n), ..., [(n-1)/n, 1] (p = 1 in the last bin). Add them
    over frames and pass the sums to :func:`pooled_reliability`."""
    if isinstance(n_bins, bool) or not isinstance(n_bins, (int, np.integer)) or not 1 <= n_bins <= 10**6:
        raise ValueError(f"n_bins: expected an integer from 1 to 1000000, got {n_bins!r}")
    p, y = _inputs(prob, labels, valid)
    idx = np.minimum((p * n_bins).astype(np.int64), n_bins - 1)
    return (np.bincount(idx, minlength=n_bins).astype(np.int64), np.bincount(idx, weights=p, minlength=n_bins),
            np.bincount(idx, weights=y.astype(np.float64), minlength=n_bins))


def pooled_reliability(count, prob_sum, label_sum) -> Reliability:
    """The :class:`Reliability` of (summed) :func:`reliability_counts`: count, sum of p and sum of
    labels per bin, three (n_bins,) arrays."""
    c = np.asarray(count, dtype=np.int64)
    ps, ys = np.asarray(prob_sum, dtype=np.float64), np.asarray(label_sum, dtype=np.float64)
    if c.ndim != 1 or ps.shape != c.shape or ys.shape != c.shape or (c < 0).any():
        raise ValueError(f"count, prob_sum, label_sum: expected three (n_bins,) arrays, counts >= 0; got {c.shape}, "
                         f"{ps.shape}, {ys.shape}")
    n = int(c.sum())
    if n == 0:
        raise ValueError("count: no samples")
    nz = c > 0
    conf = np.where(nz, ps / np.maximum(c, 1), np.nan)
    freq = np.where(nz, ys / np.maximum(c, 1), np.nan)
    gap = np.abs(freq - conf)
    return Reliability(np.linspace(0.0, 1.0, len(c) + 1), c, conf, freq, float(np.sum(c[nz] * gap[nz]) / n),
                       float(gap[nz].max()), n)


def reliability(prob, labels, *, n_bins=15, valid=None) -> Reliability:
    """Reliability statistics of ``prob`` against boolean ``labels`` over ``n_bins`` equal bins.

    Bins are [0, 1/n), [1/n, 2/n), ..., [(n-1)/n, 1]: p = 1 falls in the last bin.
    """
    return pooled_reliability(*reliability_counts(prob, labels, n_bins=n_bins, valid=valid))


def expected_calibration_error(prob, labels, *, n_bins=15, valid=None) -> float:
    """Expected calibration error (ECE) with ``n_bins`` equal-width bins (15 by default)."""
    return reliability(prob, labels, n_bins=n_bins, valid=valid).ece
