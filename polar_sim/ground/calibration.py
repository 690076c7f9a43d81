"""Online calibration of the ground probability from the module's own self-supervised labels.

The Naive Bayes posterior ranks pixels well but its probability is off: its prior is fixed, its
likelihoods are learned from feature windows rather than from all pixels, and they lag a changing
ground. :class:`PlattCalibrator` maps a score z (the log-odds of the smoothed posterior) to
P = σ(a·z + b), with (a, b) fitted by weighted logistic regression on recent self-labelled pixels:
the windows around the RANSAC ground inliers (label 1) and around the points the classifier learns
as non-ground (label 0), scored with the map of the image *before* the classifier learned from
them (out of sample). Ground truth is never used.

The map is kept monotone increasing in z: self-labels that rank against the classifier (ground labels
on pixels the classifier scores low, as when a ground's only texture is paint the colour of the sky)
would fit a negative slope and invert the map (sky P ≈ 1, the ground P ≈ 0). When the fitted slope is
not positive the calibrator falls back to the identity map σ(z), the classifier's own posterior, and
says so in ``fallback_``; it returns to the fit as soon as the labels rank with the classifier again.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PlattCalibrator", "logit", "sigmoid"]

_EPS = 1e-6


def logit(p):
    """log(p / (1 - p)) with p clipped to [1e-6, 1 - 1e-6]; float32 in, float32 out."""
    p = np.clip(p, _EPS, 1.0 - _EPS)
    return np.log(p / (1.0 - p))


def sigmoid(z):
    """1 / (1 + exp(-z)), without overflow for large |z| (as 0.5 (1 + tanh(z / 2)))."""
    return 0.5 * (1.0 + np.tanh(0.5 * z))


def _penalised_nll(X, Y, W, c, prior, lam):
    z = X @ c
    return float(W @ (np.logaddexp(0.0, z) - Y * z) + 0.5 * lam * np.sum((c - prior) ** 2))


def _fit_logistic(X, Y, W, c, prior, lam, iterations=8):
    """Weighted logistic regression of Y (m,) on X (m, 2), penalised by lam/2 |c - prior|², from c: damped
    Newton (the step halved until the cost does not rise). A full Newton step from far off, as after
    the labels turn, overshoots and can run away (slopes of 10⁴ or of the wrong sign)."""
    c = np.array(c, dtype=np.float64)
    f = _penalised_nll(X, Y, W, c, prior, lam)
    for _ in range(iterations):
        p = sigmoid(X @ c)
        g = X.T @ (W * (p - Y)) + lam * (c - prior)
        H = (X * (W * p * (1 - p))[:, None]).T @ X + lam * np.eye(2)
        step = np.linalg.solve(H, g)
        t = 1.0
        while t > 1e-4:
            f_new = _penalised_nll(X, Y, W, c - t * step, prior, lam)
            if f_new <= f:
                break
            t *= 0.5
        else:
            break  # no descent along the Newton direction: at the optimum to round-off
        c, f = c - t * step, f_new
        if np.abs(t * step).max() < 1e-6:
            break
    return c


class PlattCalibrator:
    """P = σ(a z + b) fitted online by L2-regularised weighted logistic regression.

    The samples are kept as two exponentially decayed histograms of z (one per label, bins of
    ``bin_width`` over [-z_max, z_max]), so the fit's cost does not grow with the number of labelled
    pixels: a few Newton steps on 2 x ``n_bins`` weighted points per image.

    Parameters
    ----------
    decay : float
        Per-update weight decay of old samples (the ground changes along a route).
    prior_weight : float
        Weight of the Gaussian prior pulling (a, b) toward the identity (1, 0), in samples.
    balance : bool
        Weigh each update's two classes equally (the self-labels' class ratio is not the pixels').
    z_max, bin_width : float
        Range and resolution of the score histograms (log-odds units).

    Attributes
    ----------
    coef_ : ndarray (2,)
        (a, b) of the map in use: the fit, or the identity (1, 0) while the fit's slope is not positive.
    fit_ : ndarray (2,)
        The last fitted (a, b), whatever its sign (the next fit starts from it).
    fallback_ : str or None
        Why the map in use is not the fit (``"slope_not_positive"``), or None.
    n_updates_ : int
    """

    def __init__(self, decay=0.85, prior_weight=50.0, balance=True, z_max=14.0, bin_width=0.25):
        self.decay = float(decay)
        self.prior_weight = float(prior_weight)
        self.balance = bool(balance)
        self.z_max = float(z_max)
        self.bin_width = float(bin_width)
        n = int(round(2 * self.z_max / self.bin_width))
        self.centres_ = -self.z_max + self.bin_width * (np.arange(n) + 0.5)
        self.hist_ = np.zeros((2, n))  # decayed weights of label 0 and label 1 per bin
        self.coef_ = np.array([1.0, 0.0])
        self.fit_ = self.coef_.copy()
        self.fallback_ = None
        self.n_updates_ = 0

    def update(self, z, y):
        """Add one image's samples (scores z (n,), labels y (n,) bool) and refit (a, b)."""
        z = np.asarray(z, dtype=np.float64).ravel()
        y = np.asarray(y, dtype=bool).ravel()
        if len(z) == 0:
            return self
        n = len(self.centres_)
        k = np.clip(((z + self.z_max) / self.bin_width).astype(np.intp), 0, n - 1)
        new = np.stack([np.bincount(k[~y], minlength=n), np.bincount(k[y], minlength=n)]).astype(np.float64)
        if self.balance and y.any() and (~y).any():
            new *= (0.5 * len(z) / np.array([(~y).sum(), y.sum()]))[:, None]
        self.hist_ = self.decay * self.hist_ + new
        X = np.stack([np.r_[self.centres_, self.centres_], np.ones(2 * n)], axis=1)
        Y = np.r_[np.zeros(n), np.ones(n)]
        c = self.fit_ = _fit_logistic(X, Y, self.hist_.ravel(), self.fit_, np.array([1.0, 0.0]), self.prior_weight)
        # A map that decreases in z would rank the pixels against the classifier: keep the identity.
        self.fallback_ = None if c[0] > 0 else "slope_not_positive"
        self.coef_ = c.copy() if self.fallback_ is None else np.array([1.0, 0.0])
        self.n_updates_ += 1
        return self

    def transform(self, z):
        """Calibrated probabilities of scores z (any shape), float32."""
        a, b = self.coef_
        return sigmoid(a * np.asarray(z, dtype=np.float32) + np.float32(b)).astype(np.float32)
