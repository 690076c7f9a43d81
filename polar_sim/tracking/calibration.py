"""Online calibration of the prediction map: P(target) that means what it says (issue 13 item 3).

The fused log-odds of spec 3.4 (prior x depth x appearance) ranks pixels well but is not a
probability: its terms are not independent, and each is a modelling guess. :class:`OnlineCalibration`
maps it to a calibrated probability by histogram binning, learned online from the tracker's own
self-supervised labels O (1 target, 0 not target; undecided pixels are not used), never from truth:

* the log-odds range [-8, 8] is cut into ``n_bins`` equal bins; each keeps fading counts of the
  labelled pixels that fell in it, ``n_k = decay n_{k-1} + n_new``, target and not target;
* a Beta prior of ``prior_strength`` pseudo-pixels at the uncalibrated probability sigmoid(bin
  centre) keeps an empty or young bin at the identity;
* the bins' posterior means are made non-decreasing by pool-adjacent-violators (isotonic
  regression, weighted by the counts), and the map is linear between bin centres.

Only frames the drift guard accepts update it (the same frames that train the appearance model).
"""

from __future__ import annotations

import numpy as np

__all__ = ["OnlineCalibration", "isotonic"]

LOGIT_RANGE = 8.0


def isotonic(y, w):
    """Weighted least-squares non-decreasing fit of ``y`` (n,) with weights ``w`` (n,) > 0
    (pool-adjacent-violators)."""
    vals, wts, sizes = [], [], []
    for yi, wi in zip(np.asarray(y, float), np.asarray(w, float)):
        vals.append(yi)
        wts.append(wi)
        sizes.append(1)
        while len(vals) > 1 and vals[-2] > vals[-1]:
            wsum = wts[-2] + wts[-1]
            v = (vals[-2] * wts[-2] + vals[-1] * wts[-1]) / wsum
            vals[-2:], wts[-2:], sizes[-2:] = [v], [wsum], [sizes[-2] + sizes[-1]]
    return np.repeat(vals, sizes)


class OnlineCalibration:
    """Histogram-binning calibration of a log-odds map, updated online.

    Parameters
    ----------
    n_bins : int, default=32
        Equal bins over the log-odds range [-8, 8].
    decay : float, default=0.9
        Fading of the counts per update (about 10 frames of memory).
    prior_strength : float, default=50
        Pseudo-pixels per bin at the uncalibrated probability.
    """

    def __init__(self, *, n_bins=32, decay=0.9, prior_strength=50.0):
        self.n_bins = int(n_bins)
        self.decay = float(decay)
        self.prior_strength = float(prior_strength)
        self.edges = np.linspace(-LOGIT_RANGE, LOGIT_RANGE, self.n_bins + 1)
        self.centres = 0.5 * (self.edges[:-1] + self.edges[1:])
        self.pos = np.zeros(self.n_bins)
        self.neg = np.zeros(self.n_bins)
        self.n_updates = 0
        self._table = self._fit()

    def _bin(self, z):
        k = ((np.asarray(z, np.float64) + LOGIT_RANGE) * (self.n_bins / (2 * LOGIT_RANGE))).astype(np.int64)
        return np.clip(k, 0, self.n_bins - 1)

    def _fit(self):
        p0 = 1.0 / (1.0 + np.exp(-self.centres))
        a = self.pos + self.prior_strength * p0
        b = self.neg + self.prior_strength * (1.0 - p0)
        return isotonic(a / (a + b), a + b)

    def update(self, z, labels):
        """Add labelled pixels: log-odds ``z`` (n,) and boolean target labels (n,)."""
        k = self._bin(z)
        y = np.asarray(labels, bool)
        self.pos = self.decay * self.pos + np.bincount(k[y], minlength=self.n_bins)
        self.neg = self.decay * self.neg + np.bincount(k[~y], minlength=self.n_bins)
        self._table = self._fit()
        self.n_updates += 1
        return self

    def __call__(self, z):
        """Calibrated probability (same shape as ``z``) float32."""
        z = np.asarray(z, np.float32)
        return np.interp(z, self.centres, self._table).astype(np.float32)
