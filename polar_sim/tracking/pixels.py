"""Per-pixel maps of one frame around a pose of the model (spec 3.3, 3.4, 3.6).

Everything here works on the ROI crop ``D`` (h, w) of the depth image (float32 metres, 0 =
missing) whose top-left pixel is ``(roi[0], roi[1])`` in the image, with the
:class:`~polar_sim.tracking.model.ShapeModel` ``m`` and the intrinsics ``K`` (3, 3): the depth
noise model, the distance of each pixel's point to the visible model surface, the prediction map
(prior x depth x appearance), the pixels seen in front of the model, the labels O, and the training
pixels drawn from the labels.
"""

from __future__ import annotations

import cv2
import numpy as np

from polar_sim.tracking._kernels import roi_distances
from polar_sim.tracking.visibility import disc, project_model, splat_depth, splat_silhouette

__all__ = ["LOGIT_CLIP", "KAPPA", "depth_sigma", "distances", "backproject", "prediction_map", "in_front",
           "labels", "training_pixels"]

#: Bound of the fused log-odds (spec 3.4).
LOGIT_CLIP = 8.0
#: Anisotropy of the depth likelihood's distance: the tangential offset counts 1/KAPPA.
KAPPA = 3.0


def depth_sigma(z):
    """Axial depth noise (m) at depth ``z`` (m), Kinect-like (Nguyen et al. 2012; spec 9.5); keeps the dtype."""
    return 0.0012 + 0.0019 * (z - 0.4) ** 2


def distances(m, K, D, roi, T, vis, kappa=1.0):
    """(h, w) float32: distance (m) of each pixel's point to the nearest visible model point at T_cam_cen
    ``T`` (4, 4), the tangential part divided by ``kappa``; inf without depth or candidate."""
    Ti = np.linalg.inv(T)
    D = np.ascontiguousarray(D, np.float32)  # one layout: a crop would compile the kernel twice
    out = np.empty(D.shape, np.float32)
    roi_distances(D, roi[0], roi[1], K[0, 0], K[1, 1], K[0, 2], K[1, 2],
                  np.ascontiguousarray(Ti[:3, :3]), np.ascontiguousarray(Ti[:3, 3]),
                  m.origin, m.inv_h, m.knn, m.P, m.N, vis, float(kappa), m.slack, out)
    return out


def backproject(K, D, roi, flat):
    """Camera-frame points (n, 3) of the crop's flat pixel indices ``flat`` (n,), and their depths (n,)."""
    w = D.shape[1]
    v, u = np.divmod(flat, w)
    z = D.ravel()[flat].astype(np.float64)
    x = (u + roi[0] - K[0, 2]) / K[0, 0] * z
    y = (v + roi[1] - K[1, 2]) / K[1, 1] * z
    return np.stack([x, y, z], axis=1), z


def prediction_map(m, K, D, roi, T, proj, sig_pos, lI, gamma, attention):
    """Prediction map P (h, w) float32, prior pi (h, w) and silhouette S (h, w) uint8 around pose T.

    ``proj``: the model's projection at T; ``sig_pos``: pose spread (m); ``lI``: appearance
    log-ratio (h, w) or None, weighted by ``gamma``; ``attention``: an
    :class:`~polar_sim.tracking.config.AttentionConfig`.
    """
    f = float(K[0, 0])
    zb = proj.z_mean
    S = splat_silhouette(proj.uv[proj.vis], zb, f, m.local_spacing[proj.vis], roi)
    if attention.spatial_prior:
        sigma_px = max(attention.sigma_min_px, f * sig_pos / zb)
        blur = cv2.GaussianBlur(S.astype(np.float32), (0, 0), sigma_px)
        pi = attention.epsilon + (1.0 - 2.0 * attention.epsilon) * blur
        logit = np.log(pi / (1.0 - pi))
    else:
        pi = np.full(D.shape, 0.5, np.float32)
        logit = np.zeros(D.shape, np.float32)
    # depth likelihood ratio against the visible surface at T: log of N(r; 0, sigma_r) / c_0,
    # with c_0 putting the ratio at 1 for r = 2.5 sigma_r
    dist = distances(m, K, D, roi, T, proj.vis, KAPPA)
    sig_d = depth_sigma(D).astype(np.float32)
    sr2 = sig_d * sig_d + np.float32(sig_pos * sig_pos)
    with np.errstate(invalid="ignore", over="ignore"):
        ld = np.float32(0.5 * 2.5**2) - dist * dist / (2.0 * sr2)
    ld = np.where(D > 0, np.nan_to_num(ld, nan=0.0, neginf=-2 * LOGIT_CLIP), 0.0)
    logit = logit + ld
    if lI is not None and gamma > 0:
        logit = logit + np.float32(gamma) * lI
    logit = np.clip(logit, -LOGIT_CLIP, LOGIT_CLIP).astype(np.float32)
    return (0.5 * (1.0 + np.tanh(0.5 * logit))).astype(np.float32), pi, S


def in_front(m, K, D, roi, proj, sig_pos):
    """(h, w) bool: valid depth nearer than the model's surface (splatted from the visible points
    of ``proj``, its projection at a pose) by more than 3 sigma of depth noise and pose spread
    ``sig_pos`` (m), and at least 1 cm."""
    f = float(K[0, 0])
    r = int(max(1, np.ceil(f * m.spacing / proj.z_mean)))
    Z = splat_depth(proj.uv[proj.vis], proj.Pc[proj.vis, 2], r, roi)
    sig_d = depth_sigma(D)
    band = np.maximum(3.0 * np.sqrt(sig_d * sig_d + sig_pos * sig_pos), 0.01)
    return (D > 0) & (D < Z - band)


def labels(m, K, shape, D, roi, T, vis=None):
    """Labels O (h, w) int8, silhouette (h, w) uint8 and distances (h, w) at pose T (spec 3.6).

    O is 1 inside the eroded silhouette within max(3 sigma_D, 6 mm) of the surface, 0 outside the
    dilated silhouette or more than 15 mm off it (a touching hand in front), -1 otherwise.
    ``vis``: the visibility at T if known (else a z-buffered projection); ``shape``: (H, W).
    """
    pr = project_model(m.P, m.N, T[:3, :3], T[:3, 3], K, shape, m.spacing, zbuffer=vis is None)
    if vis is not None:
        pr.vis = vis
    S = splat_silhouette(pr.uv[pr.vis], pr.z_mean, K[0, 0], m.local_spacing[pr.vis], roi)
    inner = cv2.erode(S, disc(1), borderType=cv2.BORDER_CONSTANT, borderValue=1) > 0
    outer = cv2.dilate(S, disc(2)) > 0
    # distances only where they can matter: inside the dilated silhouette's bounding box
    r = np.full(D.shape, np.inf, np.float32)
    ys, xs = np.nonzero(outer.any(axis=1))[0], np.nonzero(outer.any(axis=0))[0]
    if len(ys):
        a0, a1, b0, b1 = ys[0], ys[-1] + 1, xs[0], xs[-1] + 1
        sub = (roi[0] + b0, roi[1] + a0, roi[0] + b1, roi[1] + a1)
        r[a0:a1, b0:b1] = distances(m, K, np.ascontiguousarray(D[a0:a1, b0:b1]), sub, T, pr.vis)
    d1 = np.maximum(3.0 * depth_sigma(D), 0.006)
    O = np.full(D.shape, -1, np.int8)
    with np.errstate(invalid="ignore"):
        O[~outer | (r > 0.015)] = 0
        O[inner & (r < d1)] = 1
    return O, S, r


def training_pixels(O, S, r, D, n, rng):
    """Pixels to train a feature head on: (ys, xs, labels, weights), or None with fewer than 10 per class.

    Up to ``n`` positives (O = 1), weighted by their geometric confidence 1 - r / delta_1 (at least
    0.1), and up to ``n`` negatives (O = 0): two thirds from a band 30 px wide around the
    silhouette ``S`` (where a touching hand is), the rest from the remaining ROI; ``rng`` a Generator.
    """
    w = O.shape[1]
    pos = np.flatnonzero(O.ravel() == 1)
    # hard negatives: a band 30 px wide around the silhouette (square kernel: separable, fast)
    ring = (cv2.dilate(S, np.ones((61, 61), np.uint8)) > 0) & (S == 0)
    neg0 = O.ravel() == 0
    neg_ring = np.flatnonzero(neg0 & ring.ravel())
    neg_rest = np.flatnonzero(neg0 & ~ring.ravel())
    if len(pos) < 10 or len(neg_ring) + len(neg_rest) < 10:
        return None
    pos = rng.choice(pos, min(n, len(pos)), replace=False)
    k_ring = min(len(neg_ring), (2 * n) // 3)
    k_rest = min(len(neg_rest), n - k_ring)
    neg = np.concatenate([rng.choice(neg_ring, k_ring, replace=False),
                          rng.choice(neg_rest, k_rest, replace=False)])
    ys, xs = np.divmod(np.concatenate([pos, neg]), w)
    lab = np.concatenate([np.ones(len(pos), np.int8), np.zeros(len(neg), np.int8)])
    d1 = np.maximum(3.0 * depth_sigma(D.ravel()[pos]), 0.006)
    wpos = np.clip(1.0 - r.ravel()[pos] / d1, 0.1, 1.0)
    return ys, xs, lab, np.concatenate([wpos, np.ones(len(neg))])
