"""CPU-fast multi-scale appearance features (spec 4.3): the stand-in for CNN hypercolumns.

Gaussian pyramid levels s = 0..3 (factor 2) of the ROI; 12 channels per level: CIELab (3); hue as
(cos h, sin h) * saturation (2); gradient magnitude of L (1); oriented gradient energy at 0, 45, 90
and 135 deg, smoothed over 5 x 5 (4); local mean and standard deviation of L over 5 x 5 (2). All
channels are scaled to roughly unit range. Upsampling is bilinear with OpenCV's pixel-centre
convention; :func:`gather` samples the maps at full-resolution pixels with the same convention,
so a linear head trained on gathered samples gives exactly the map :func:`upsample` produces.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["N_LEVELS", "N_CHANNELS", "level_features", "gather", "upsample"]

N_LEVELS = 4
N_CHANNELS = 12


def _channels(img):
    """12 feature channels (h, w, 12) float32 of an RGB float32 image in [0, 1]."""
    lab = cv2.cvtColor(img, cv2.COLOR_RGB2Lab)
    hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV)
    L = lab[..., 0] * np.float32(0.01)
    h = hsv[..., 0] * np.float32(np.pi / 180.0)
    s = hsv[..., 1]
    gx = cv2.Sobel(L, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REFLECT)
    gy = cv2.Sobel(L, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REFLECT)
    k = (5, 5)
    gxx = cv2.blur(gx * gx, k)
    gyy = cv2.blur(gy * gy, k)
    gxy = cv2.blur(gx * gy, k)
    # directional energies E(theta) = cos^2 gxx + 2 cos sin gxy + sin^2 gyy
    e45 = 0.5 * (gxx + gyy) + gxy
    e135 = 0.5 * (gxx + gyy) - gxy
    mean = cv2.blur(L, k)
    var = cv2.blur(L * L, k) - mean * mean
    out = np.empty(L.shape + (N_CHANNELS,), np.float32)
    out[..., 0] = L
    out[..., 1] = lab[..., 1] * np.float32(1.0 / 128.0)
    out[..., 2] = lab[..., 2] * np.float32(1.0 / 128.0)
    out[..., 3] = s * np.cos(h)
    out[..., 4] = s * np.sin(h)
    out[..., 5] = np.sqrt(gx * gx + gy * gy)
    out[..., 6] = np.sqrt(np.maximum(gxx, 0))
    out[..., 7] = np.sqrt(np.maximum(e45, 0))
    out[..., 8] = np.sqrt(np.maximum(gyy, 0))
    out[..., 9] = np.sqrt(np.maximum(e135, 0))
    out[..., 10] = mean
    out[..., 11] = np.sqrt(np.maximum(var, 0))
    return out


def level_features(rgb, n_levels=N_LEVELS):
    """Feature maps of an RGB uint8 crop (h, w, 3): list of n_levels arrays (h_s, w_s, 12) float32."""
    img = rgb.astype(np.float32) * np.float32(1.0 / 255.0)
    feats = []
    for s in range(n_levels):
        if s > 0:
            if min(img.shape[:2]) < 2:
                feats.append(feats[-1])
                continue
            img = cv2.pyrDown(img)
        feats.append(_channels(img))
    return feats


def upsample(a, shape):
    """Bilinear upsampling of a map (h_s, w_s) to shape (h, w) (OpenCV pixel-centre convention)."""
    h, w = shape
    if a.shape == (h, w):
        return a
    return cv2.resize(a, (w, h), interpolation=cv2.INTER_LINEAR)


def gather(feats, ys, xs, shape):
    """Features (n, n_levels * 12) at full-resolution pixels (ys, xs) of a crop of ``shape``.

    Bilinear in each level with the coordinates ``(x + 0.5) * w_s / w - 0.5`` clamped to the
    level, which is what ``cv2.resize(..., INTER_LINEAR)`` does when upsampling.
    """
    h, w = shape
    out = []
    for F in feats:
        hs, ws = F.shape[:2]
        if (hs, ws) == (h, w):
            out.append(F[ys, xs])
            continue
        fx = np.clip((xs + 0.5) * (ws / w) - 0.5, 0, ws - 1)
        fy = np.clip((ys + 0.5) * (hs / h) - 0.5, 0, hs - 1)
        x0 = np.minimum(np.floor(fx).astype(np.int64), ws - 1)
        y0 = np.minimum(np.floor(fy).astype(np.int64), hs - 1)
        x1 = np.minimum(x0 + 1, ws - 1)
        y1 = np.minimum(y0 + 1, hs - 1)
        ax = (fx - x0)[:, None].astype(np.float32)
        ay = (fy - y0)[:, None].astype(np.float32)
        top = F[y0, x0] * (1 - ax) + F[y0, x1] * ax
        bot = F[y1, x0] * (1 - ax) + F[y1, x1] * ax
        out.append(top * (1 - ay) + bot * ay)
    return np.concatenate(out, axis=1)
