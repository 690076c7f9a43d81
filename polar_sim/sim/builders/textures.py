"""Procedural, seeded textures for ground surfaces and obstacles (uint8 RGB arrays).

Ground textures carry high-frequency detail so that corner detectors and KLT find features at
every scale a rover camera sees, and each ground type has colour statistics unlike the obstacle
colours, which is what the ground classifier learns to exploit.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

__all__ = ["GROUND_TYPES", "ground_texture", "obstacle_texture", "OBSTACLE_COLOURS"]

#: Ground appearances available along a route, in the order the terrain builder cycles them.
GROUND_TYPES = ("asphalt", "gravel", "grass", "dirt")

#: Saturated obstacle colours (RGB 0..255): unlike any ground type in hue or saturation.
OBSTACLE_COLOURS = {
    "red": (200, 30, 35),
    "blue": (30, 70, 210),
    "yellow": (235, 200, 20),
    "orange": (245, 120, 20),
    "white": (235, 235, 240),
    "magenta": (190, 40, 170),
    "cyan": (20, 190, 200),
}


def _noise(rng, size, sigma):
    """Zero-mean, unit-variance seamless noise of blur ``sigma`` texels, (size, size) float32."""
    n = rng.standard_normal((size, size)).astype(np.float32)
    if sigma > 0:
        # Wrap-around blur keeps the texture seamless when it repeats across the ground.
        n = gaussian_filter(n, sigma, mode="wrap")
    return n / (n.std() + 1e-9)


def _finish(img):
    return np.clip(img, 0, 255).astype(np.uint8)


def ground_texture(kind: str, rng: np.random.Generator, size: int = 512) -> np.ndarray:
    """A seamless (size, size, 3) uint8 RGB texture of one ground type.

    Parameters
    ----------
    kind : {"asphalt", "gravel", "grass", "dirt"}
    rng : numpy.random.Generator
        Source of all randomness; the same generator state gives the same texture.
    size : int
        Texture side in texels.
    """
    fine = _noise(rng, size, 0.7)
    mid = _noise(rng, size, 3.0)
    coarse = _noise(rng, size, 14.0)
    if kind == "asphalt":
        base = np.array([68.0, 68.0, 72.0]) + rng.uniform(-6, 6)
        lum = 22 * fine + 8 * mid + 6 * coarse
        speck = (rng.random((size, size)) > 0.985).astype(np.float32) * 70
        img = base + (lum + speck)[..., None]
    elif kind == "gravel":
        img = np.empty((size, size, 3), np.float32)
        img[:] = np.array([118.0, 108.0, 96.0])
        n_stones = size * size // 40
        xs = rng.integers(0, size, n_stones)
        ys = rng.integers(0, size, n_stones)
        rs = rng.integers(2, 6, n_stones)
        tone = rng.uniform(-45, 55, n_stones)
        warm = rng.uniform(-12, 12, n_stones)
        for x, y, r, t, w in zip(xs, ys, rs, tone, warm):
            col = (118 + t + w, 108 + t, 96 + t - w)
            cv2.circle(img, (int(x), int(y)), int(r), col, -1, lineType=cv2.LINE_AA)
        img += (10 * fine)[..., None]
    elif kind == "grass":
        blades = gaussian_filter(rng.standard_normal((size, size)).astype(np.float32), (2.5, 0.6),
                                 mode="wrap")
        blades /= blades.std() + 1e-9
        g = 118 + 26 * blades + 14 * mid + 12 * coarse
        img = np.stack([0.45 * g + 4 * fine, g, 0.28 * g + 6 * fine], axis=-1)
    elif kind == "dirt":
        lum = 16 * fine + 14 * mid + 12 * coarse
        img = np.array([138.0, 100.0, 66.0]) + lum[..., None] * np.array([1.0, 0.85, 0.7])
        pebbles = (rng.random((size, size)) > 0.99).astype(np.float32)
        img -= (gaussian_filter(pebbles, 1.0, mode="wrap") * 400)[..., None]
    else:
        raise ValueError(f"kind: unknown ground type {kind!r}; expected one of {GROUND_TYPES}")
    return _finish(img)


def obstacle_texture(colour, rng: np.random.Generator, size: int = 128) -> np.ndarray:
    """A (size, size, 3) uint8 texture of a saturated colour with a mild panel pattern.

    The pattern gives obstacles features for visual odometry while the colour stays far from
    every ground type.
    """
    base = np.array(colour, dtype=np.float32)
    img = np.empty((size, size, 3), np.float32)
    img[:] = base
    step = size // 4
    for k in range(0, size, step):
        img[k : k + 2, :] *= 0.7
        img[:, k : k + 2] *= 0.7
    img *= (1.0 + 0.06 * _noise(rng, size, 1.0))[..., None]
    return _finish(img)
