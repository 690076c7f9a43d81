"""The tabletop scenes' procedural textures and colours: object and label textures, the wooden
table and the walls (RGB uint8 images, seeded by a ``numpy.random.Generator``), and the named
object colours. Kept apart from :mod:`polar_sim.sim.builders.tabletop` so that the appearance options
(:mod:`polar_sim.sim.builders.tabletop_appearance`) can use them without importing the scene builder."""

from __future__ import annotations

import numpy as np

from polar_sim.sim.actors.hand import HAND_SKIN

__all__ = ["COLOURS", "object_texture"]

#: Object colours (RGB 0..255): distinct hues. "skin" is the hand's colour.
COLOURS = {
    "red": (196, 36, 40), "blue": (36, 84, 200), "green": (40, 150, 70), "yellow": (232, 196, 30),
    "orange": (238, 120, 28), "purple": (120, 52, 160), "cyan": (30, 170, 190), "white": (228, 228, 222),
    "skin": tuple(int(round(255 * c)) for c in HAND_SKIN[:3]),
}


def _noise(rng, shape, sigma):
    from scipy.ndimage import gaussian_filter

    n = gaussian_filter(rng.standard_normal(shape), sigma, mode="wrap")
    return n / (n.std() + 1e-9)


def object_texture(base, accent, rng, size=256):
    """A 2x2 texture atlas (size, size, 3) uint8 for one object (tiles: see
    ``objects.ATLAS_TILES``): body (base colour, mottled, seeded stripes), accent, printed
    label (light ground, blocks of both colours, dark text-like bars), dark plastic/metal."""
    h = size // 2
    base, accent = np.asarray(base, float), np.asarray(accent, float)
    tiles = []
    body = np.ones((h, h, 3)) * base + 6 * _noise(rng, (h, h), 2)[..., None]
    for _ in range(rng.integers(0, 3)):
        r0 = rng.integers(8, h - 16)
        body[r0 : r0 + rng.integers(3, 9)] = 0.5 * base + 0.5 * accent
    tiles.append(body)
    tiles.append(np.ones((h, h, 3)) * accent + 5 * _noise(rng, (h, h), 2)[..., None])
    label = np.ones((h, h, 3)) * np.array([236.0, 232.0, 220.0])
    r0, r1 = sorted(rng.integers(10, h - 10, 2))
    label[max(r0 - 20, 0) : r1 + 4, :] = base
    c0 = rng.integers(5, h // 2)
    label[r0 : r0 + 22, c0 : c0 + rng.integers(20, h // 2)] = accent
    for _ in range(6):
        rr, cc = rng.integers(4, h - 8), rng.integers(4, h - 40)
        label[rr : rr + 4, cc : cc + rng.integers(12, 36)] = (30, 30, 34)
    tiles.append(label + 4 * _noise(rng, (h, h), 1)[..., None])
    tiles.append(np.ones((h, h, 3)) * 42.0 + 8 * _noise(rng, (h, h), 1.5)[..., None])
    img = np.zeros((size, size, 3))
    for k, t in enumerate(tiles):
        # Tile k covers u in [k%2, k%2+1]/2 and v in [k//2, k//2+1]/2; image rows run along v.
        img[(k // 2) * h : (k // 2 + 1) * h, (k % 2) * h : (k % 2 + 1) * h] = t
    return np.clip(img, 0, 255).astype(np.uint8)


def _wood_texture(rng, size=256):
    y = np.arange(size)[:, None] / size
    x = np.arange(size)[None, :] / size
    grain = np.sin(2 * np.pi * (14 * y + 1.5 * _noise(rng, (size, size), 12) * 0.3 + 0.05 * np.sin(6 * np.pi * x)))
    tone = np.array([168.0, 128.0, 88.0]) * rng.uniform(0.85, 1.1)
    img = tone + (12 * grain + 5 * _noise(rng, (size, size), 1.0))[..., None] * np.array([1.0, 0.8, 0.6])
    return np.clip(img, 0, 255).astype(np.uint8)


def _wall_texture(rng, size=128):
    tone = np.array([205.0, 203.0, 196.0]) + rng.uniform(-15, 10, 3)
    img = tone + 5 * _noise(rng, (size, size), 1.5)[..., None]
    return np.clip(img, 0, 255).astype(np.uint8)
