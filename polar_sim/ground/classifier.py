"""Naive Bayes ground/non-ground colour classifier over 216 HSV labels (spec §5)."""

from __future__ import annotations

import numpy as np

from polar_sim.ground.image import N_LABELS

__all__ = ["GroundColourModel", "window_labels", "window_index"]


def window_index(shape, xy, half_window=1):
    """Flat indices of every in-image pixel in the (2w+1)² window around each point.

    shape : (H, W) of the image. xy : (n, 2) pixel coordinates (column, row), rounded to the
    nearest pixel. Returns a flat int array (pixels outside the image are skipped).
    """
    if len(xy) == 0:
        return np.zeros(0, dtype=np.intp)
    h, w = shape
    c = np.rint(xy[:, 0]).astype(np.intp)
    r = np.rint(xy[:, 1]).astype(np.intp)
    off = np.arange(-half_window, half_window + 1)
    dr, dc = np.meshgrid(off, off, indexing="ij")
    rr = (r[:, None] + dr.ravel()[None, :]).ravel()
    cc = (c[:, None] + dc.ravel()[None, :]).ravel()
    ok = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
    return rr[ok] * w + cc[ok]


def window_labels(labels, xy, half_window=1):
    """Labels of every in-image pixel in the (2w+1)² window around each point.

    labels : (H, W) uint8 label image. xy : (n, 2) pixel coordinates (column, row), rounded to the
    nearest pixel. Returns a flat int array (pixels outside the image are skipped).
    """
    return labels.ravel()[window_index(labels.shape, xy, half_window)].astype(np.intp)


class GroundColourModel:
    """Two decayed label histograms and the Naive Bayes posterior P(ground | label).

    Parameters
    ----------
    alpha : float
        Histogram decay per update, H <- alpha H + H_new (spec Eq. 4.13: 0.7).
    prior : float
        Class prior P(G) (0.2).
    pseudo_ground, pseudo_nonground : float
        Additive smoothing of the two likelihoods ([code]: 0.5 and 1, B12; fixed: 1 and 1).
    half_window : int
        Training window half-size (1 -> 3x3).
    decay_samples : float or None
        None: each update decays a histogram by alpha (spec Eq. 4.13). A number n: an update adding
        m samples to a histogram decays it by alpha ** min(1, m / n), so frames with few labels
        (a weakly textured ground) do not wash out what was learned.
    """

    def __init__(self, alpha=0.7, prior=0.2, pseudo_ground=1.0, pseudo_nonground=1.0, half_window=1,
                 decay_samples=None):
        self.alpha = float(alpha)
        self.prior = float(prior)
        self.pseudo_ground = float(pseudo_ground)
        self.pseudo_nonground = float(pseudo_nonground)
        self.half_window = int(half_window)
        self.decay_samples = None if decay_samples is None else float(decay_samples)
        self.hist_ground = np.zeros(N_LABELS)
        self.hist_nonground = np.zeros(N_LABELS)
        self.n_updates = 0

    def update(self, labels, ground_xy, nonground_xy):
        """Decay both histograms and add the window label counts of the two training sets."""
        hw = self.half_window
        new_g = np.bincount(window_labels(labels, ground_xy, hw), minlength=N_LABELS)
        new_ng = np.bincount(window_labels(labels, nonground_xy, hw), minlength=N_LABELS)
        ag, an = self.alpha, self.alpha
        if self.decay_samples is not None:
            # Evidence-weighted forgetting: an update with fewer samples than decay_samples forgets less.
            ag = self.alpha ** min(1.0, new_g.sum() / self.decay_samples)
            an = self.alpha ** min(1.0, new_ng.sum() / self.decay_samples)
        self.hist_ground = ag * self.hist_ground + new_g
        self.hist_nonground = an * self.hist_nonground + new_ng
        self.n_updates += 1

    def posterior_table(self):
        """P(G | label) for each of the 216 labels, float64 (216,)."""
        a, b = self.pseudo_ground, self.pseudo_nonground
        lg = (self.hist_ground + a) / (self.hist_ground.sum() + a * N_LABELS)
        lng = (self.hist_nonground + b) / (self.hist_nonground.sum() + b * N_LABELS)
        num = lg * self.prior
        return num / (num + lng * (1.0 - self.prior))

    def log_odds_table(self):
        """log(P / (1 - P)) of the posterior per label, float32 (216,)."""
        p = np.clip(self.posterior_table(), 1e-6, 1.0 - 1e-6)
        return np.log(p / (1.0 - p)).astype(np.float32)

    def predict(self, labels):
        """Single-pixel posterior map P(G | label) of a label image, float32 (H, W)."""
        return self.posterior_table().astype(np.float32)[labels]
