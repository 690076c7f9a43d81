"""Calibration of probability maps: expected calibration error and reliability diagrams.

A probability is calibrated when, among the pixels given P = p, a fraction p are positive. The
modules' P(ground) and P(target) are scored this way against the true masks.

Probabilities and labels are arrays of the same shape (any, e.g. (H, W) or (n, H, W)); a
``valid`` mask, if given, selects the pixels that count (e.g. only those in the image's region of
interest).
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["reliability", "Reliability", "expected_calibration_error", "plot_reliability"]


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


def reliability(prob, labels, *, n_bins=15, valid=None) -> Reliability:
    """Reliability statistics of ``prob`` against boolean ``labels`` over ``n_bins`` equal bins.

    Bins are [0, 1/n), [1/n, 2/n), ..., [(n-1)/n, 1]: p = 1 falls in the last bin.
    """
    if isinstance(n_bins, bool) or not isinstance(n_bins, (int, np.integer)) or n_bins < 1:
        raise ValueError(f"n_bins: expected an integer >= 1, got {n_bins!r}")
    p, y = _inputs(prob, labels, valid)
    edges = np.linspace(0.0, 1.0, int(n_bins) + 1)
    idx = np.minimum((p * n_bins).astype(np.int64), n_bins - 1)
    count = np.bincount(idx, minlength=n_bins).astype(np.int64)
    psum = np.bincount(idx, weights=p, minlength=n_bins)
    ysum = np.bincount(idx, weights=y.astype(np.float64), minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        conf = np.where(count > 0, psum / np.maximum(count, 1), np.nan)
        freq = np.where(count > 0, ysum / np.maximum(count, 1), np.nan)
    gap = np.abs(freq - conf)
    nz = count > 0
    ece = float(np.sum(count[nz] * gap[nz]) / p.size)
    return Reliability(edges, count, conf, freq, ece, float(gap[nz].max()), int(p.size))


def expected_calibration_error(prob, labels, *, n_bins=15, valid=None) -> float:
    """Expected calibration error (ECE) with ``n_bins`` equal-width bins (15 by default)."""
    return reliability(prob, labels, n_bins=n_bins, valid=valid).ece


def plot_reliability(rels, labels=None, *, ax=None, title="reliability diagram"):
    """Draw one or more :class:`Reliability` curves with the diagonal and per-bin counts.

    ``rels``: a Reliability or a list of them; ``labels``: their legend names. Returns the axes.
    """
    import matplotlib.pyplot as plt

    if isinstance(rels, Reliability):
        rels = [rels]
    labels = list(labels) if labels is not None else [f"curve {i}" for i in range(len(rels))]
    if len(labels) != len(rels):
        raise ValueError(f"labels: expected {len(rels)} names, got {len(labels)}")
    if ax is None:
        _, ax = plt.subplots(figsize=(4.6, 4.2))
    ax.plot([0, 1], [0, 1], c="0.6", ls="--", lw=1, label="calibrated")
    for r, name in zip(rels, labels):
        nz = r.count > 0
        ax.plot(r.confidence[nz], r.frequency[nz], marker="o", ms=3, label=f"{name} (ECE {r.ece:.3f})")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_xlabel("predicted probability (bin mean)")
    ax.set_ylabel("observed frequency of the class")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    return ax
