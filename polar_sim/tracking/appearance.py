"""Online appearance classifiers trained from the self-generated labels O (spec 4).

* :class:`ColourNB` ("h"): the ground chapter's 216-bin HSV Naive Bayes with fading histograms.
* :class:`FeatureHead` ("su", "sw", "wu", "ww"): a head on the multi-scale features of
  :mod:`polar_sim.tracking.features`, trained online with Adam. Upper-case letter: ``S`` one
  logistic layer on the stacked 48-D feature; ``W`` one logistic head per scale, fused by a learned
  weighted sum of their logits (HED-style side outputs, each with its own loss). Lower-case letter
  (spec 4.2, first reading): ``u`` uniform hard labels, ``w`` confidence-weighted positives.

Both return ``log Lambda_I``, the log likelihood ratio P(I | target) / P(I | not target), per ROI
pixel; a classifier trained on class-balanced samples has prior 0.5, so its logit *is* that ratio.
"""

from __future__ import annotations

from collections import deque

import cv2
import numpy as np

from polar_sim.tracking.features import N_CHANNELS, N_LEVELS, gather, level_features, upsample

__all__ = ["ColourNB", "FeatureHead", "make_appearance"]


class ColourNB:
    """216-bin HSV Naive Bayes (6 x 6 x 6), histograms ``H_k = decay H_{k-1} + H_new``.

    Laplace smoothing +0.5 on the target histogram and +1 on the background one, as in the ground
    chapter's code; the likelihood ratio needs no class prior.
    """

    name = "h"

    def __init__(self, *, decay=0.7):
        self.decay = decay
        self.pos = np.zeros(216)
        self.neg = np.zeros(216)
        self.n_updates = 0
        lut = np.minimum(np.arange(256) * 6 // 256, 5)
        self._lut_h = np.minimum(np.arange(256) * 6 // 180, 5).astype(np.int16)
        self._lut_sv = lut.astype(np.int16)
        self._table = np.zeros(216, np.float32)

    def prepare(self, rgb):
        """Bin index (h, w) int16 of an RGB uint8 crop."""
        hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
        return self._lut_h[hsv[..., 0]] + 6 * self._lut_sv[hsv[..., 1]] + 36 * self._lut_sv[hsv[..., 2]]

    def log_ratio(self, bins):
        """log P(bin | target) - log P(bin | background), (h, w) float32."""
        return self._table[bins]

    def update(self, bins, ys, xs, labels, weights, rng):
        """Fade the histograms and add the labelled pixels (labels 1/0, weights per pixel)."""
        b = bins[ys, xs]
        self.pos = self.decay * self.pos + np.bincount(b[labels == 1], weights[labels == 1], 216)
        self.neg = self.decay * self.neg + np.bincount(b[labels == 0], weights[labels == 0], 216)
        lp = np.log((self.pos + 0.5) / (self.pos.sum() + 0.5 * 216))
        ln = np.log((self.neg + 1.0) / (self.neg.sum() + 216.0))
        self._table = (lp - ln).astype(np.float32)
        self.n_updates += 1


class _Adam:
    """Adam on one flat parameter vector (in place)."""

    def __init__(self, n, lr):
        self.lr = lr
        self.m = np.zeros(n)
        self.v = np.zeros(n)
        self.t = 0

    def step(self, theta, g):
        self.t += 1
        b1, b2 = 0.9, 0.999
        self.m *= b1
        self.m += (1 - b1) * g
        self.v *= b2
        self.v += (1 - b2) * g * g
        lr = self.lr * np.sqrt(1 - b2**self.t) / (1 - b1**self.t)
        theta -= lr * self.m / (np.sqrt(self.v) + 1e-8)


def _sigmoid(z):
    return 0.5 * (1.0 + np.tanh(0.5 * z))


class FeatureHead:
    """Online head on multi-scale features: ``head`` "S" or "W", ``weighting`` "u" or "w".

    Training per accepted frame (spec 4.3): standardise (running mean/variance, frozen after
    ``freeze_after`` updates), mix the new samples 1:1 with a replay buffer of the last ``replay``
    frames, then ``epochs`` passes of Adam (``lr``, mini-batch ``batch``, L2 ``l2``).
    """

    def __init__(self, head="W", weighting="w", *, lr=1e-2, epochs=2, batch=256, l2=1e-4,
                 replay=10, freeze_after=10, side_weight=0.25):
        self.head = head
        self.weighting = weighting
        self.name = head.lower() + weighting
        self.lr, self.epochs, self.batch, self.l2 = lr, epochs, batch, l2
        self.buffer = deque(maxlen=replay)
        self.freeze_after = freeze_after
        self.side_weight = side_weight
        D = N_LEVELS * N_CHANNELS
        self.count = 0.0
        self.mean = np.zeros(D)
        self.m2 = np.zeros(D)
        self.n_updates = 0
        # all parameters live in one flat vector; ``params`` gives views into it
        if head == "S":
            self._shapes = [(D,), (1,)]
        else:
            self._shapes = [(N_LEVELS, N_CHANNELS), (N_LEVELS,), (N_LEVELS,), (1,)]
        self.theta = np.zeros(sum(int(np.prod(sh)) for sh in self._shapes))
        if head == "W":
            self.params[2][:] = 1.0 / N_LEVELS
        self.opt = _Adam(len(self.theta), lr)

    @property
    def params(self):
        """Views into ``theta``: [w (48,), b (1,)] for S; [W (4, 12), b (4,), alpha (4,), c (1,)] for W.

        Views are made on access (never stored), so a pickled head stays consistent."""
        out, a = [], 0
        for sh in self._shapes:
            n = int(np.prod(sh))
            out.append(self.theta[a : a + n].reshape(sh))
            a += n
        return out

    # -- features and inference -------------------------------------------------------------
    def prepare(self, rgb):
        """Per-level feature maps of an RGB uint8 crop (list of (h_s, w_s, 12) float32)."""
        return level_features(rgb, N_LEVELS)

    def _std(self):
        var = self.m2 / max(self.count - 1.0, 1.0)
        return np.sqrt(np.maximum(var, 1e-6))

    def _level_affine(self):
        """Per-level weights (12,) and bias of the logit contribution, standardisation folded in."""
        mu, sd = self.mean.reshape(N_LEVELS, N_CHANNELS), self._std().reshape(N_LEVELS, N_CHANNELS)
        out = []
        if self.head == "S":
            w = self.params[0].reshape(N_LEVELS, N_CHANNELS)
            for s in range(N_LEVELS):
                ws = w[s] / sd[s]
                out.append((ws, -float(ws @ mu[s]) + (float(self.params[1][0]) if s == 0 else 0.0)))
        else:
            W, b, alpha, c = self.params
            for s in range(N_LEVELS):
                ws = alpha[s] * W[s] / sd[s]
                bias = alpha[s] * (b[s] - float((W[s] / sd[s]) @ mu[s])) + (c[0] if s == 0 else 0.0)
                out.append((ws, bias))
        return out

    def log_ratio(self, feats):
        """Fused logit (h, w) float32 over the crop of the level-0 maps.

        Linear heads commute with bilinear upsampling, so each level's logit contribution is
        computed at its own resolution and only the scalar map is upsampled: exactly the logit of
        the stacked upsampled 48-D feature, at a fraction of the cost.
        """
        h, w = feats[0].shape[:2]
        z = np.zeros((h, w), np.float32)
        for F, (ws, b) in zip(feats, self._level_affine()):
            a = F.reshape(-1, N_CHANNELS) @ ws.astype(np.float32) + np.float32(b)
            z += upsample(a.reshape(F.shape[:2]), (h, w))
        return z

    # -- training ---------------------------------------------------------------------------
    def _standardise_update(self, X):
        if self.n_updates >= self.freeze_after:
            return
        # batch Welford update (Chan et al.): merge the batch's mean and sum of squares
        n = len(X)
        d = X.mean(axis=0) - self.mean
        tot = self.count + n
        self.mean = self.mean + d * n / tot
        self.m2 = self.m2 + X.var(axis=0) * n + d * d * self.count * n / tot
        self.count = tot

    def _grads(self, Xs, y, wt):
        """Loss gradients for standardised features Xs (b, 48), labels y, weights wt (sum 1)."""
        if self.head == "S":
            w, b = self.params
            z = Xs @ w + b[0]
            g = (_sigmoid(z) - y) * wt
            return np.concatenate([Xs.T @ g + self.l2 * w, [g.sum()]])
        W, b, alpha, c = self.params
        Xl = Xs.reshape(len(Xs), N_LEVELS, N_CHANNELS)
        a = np.einsum("nsc,sc->ns", Xl, W) + b
        z = a @ alpha + c[0]
        gz = (_sigmoid(z) - y) * wt
        ga = gz[:, None] * alpha[None, :] + self.side_weight * (_sigmoid(a) - y[:, None]) * wt[:, None]
        gW = np.einsum("ns,nsc->sc", ga, Xl) + self.l2 * W
        return np.concatenate([gW.ravel(), ga.sum(axis=0), a.T @ gz + self.l2 * (alpha - 1.0 / N_LEVELS),
                               [gz.sum()]])

    def update(self, feats, ys, xs, labels, weights, rng):
        """Train on pixels (ys, xs) of the crop with labels (n,) in {0, 1} and weights (n,)."""
        X = gather(feats, ys, xs, feats[0].shape[:2])
        y = labels.astype(np.float32)
        wt = weights.astype(np.float32) if self.weighting == "w" else np.ones(len(y), np.float32)
        self._standardise_update(X.astype(np.float64))
        new = (X, y, wt)
        if self.buffer:
            # replay: as many samples as the new frame gives, drawn uniformly from the buffer
            sizes = np.array([len(b[1]) for b in self.buffer])
            k = int(min(sizes.sum(), len(X)))
            j = rng.integers(0, sizes.sum(), k)
            which = np.searchsorted(np.cumsum(sizes), j, side="right")
            local = j - np.concatenate([[0], np.cumsum(sizes)[:-1]])[which]
            parts = [[], [], []]
            for f, b in enumerate(self.buffer):
                sel = local[which == f]
                for i in range(3):
                    parts[i].append(b[i][sel])
            X = np.concatenate([X] + parts[0])
            y = np.concatenate([y] + parts[1])
            wt = np.concatenate([wt] + parts[2])
        self.buffer.append(new)
        # class balance: both classes carry the same total weight (training prior 0.5)
        wt = wt.astype(np.float64)
        for c in (0, 1):
            s = wt[y == c].sum()
            if s > 0:
                wt[y == c] *= 0.5 * len(y) / s
        Xs = (X - self.mean) / self._std()
        y = y.astype(np.float64)
        n = len(y)
        for _ in range(self.epochs):
            order = rng.permutation(n)
            for i in range(0, n, self.batch):
                j = order[i : i + self.batch]
                self.opt.step(self.theta, self._grads(Xs[j], y[j], wt[j] / len(j)))
        self.n_updates += 1


def make_appearance(name, **kw):
    """Appearance model for a variant name: "h", "su", "sw", "wu", "ww" (case-insensitive), or None."""
    n = name.lower()
    if n == "none":
        return None
    if n == "h":
        return ColourNB(decay=kw.get("decay", 0.7))
    kw.pop("decay", None)
    return FeatureHead(n[0].upper(), n[1], **kw)
