"""Procedural pixels of the rover appearance families: seamless ground textures and skybox images.

Every generator takes a ``numpy.random.Generator`` and returns uint8 RGB; the same generator state
gives the same pixels. Ground textures tile seamlessly (noise is blurred with wrap-around, stones and
tiles wrap across the edges). Nothing here is a shipped asset: every pixel is generated.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

from polar_sim.sim.builders.textures import _noise

__all__ = ["GROUND_GENERATORS", "ground_family_texture", "sky_cube", "SKY_FACE_AZIMUTH"]


def _rgb(c):
    return np.asarray(c, dtype=np.float32).reshape(1, 1, 3)


def _speckle(rng, size, colour, colour2, contrast, density=0.03):
    img = _rgb(colour) + (contrast * 90.0 * _noise(rng, size, 0.6))[..., None]
    specks = rng.random((size, size)) < density
    img[specks] = 0.35 * img[specks] + 0.65 * np.asarray(colour2, np.float32)
    return img


def _gravel(rng, size, colour, colour2, contrast, stone_px=(4, 10)):
    img = np.empty((size, size, 3), np.float32)
    img[:] = _rgb(colour)
    lo, hi = int(stone_px[0]), int(stone_px[1])
    n_stones = int(size * size / (0.9 * (0.5 * (lo + hi)) ** 2))
    xs, ys = rng.integers(0, size, n_stones), rng.integers(0, size, n_stones)
    rs = rng.integers(lo, hi + 1, n_stones)
    mix = rng.random(n_stones)
    tone = rng.uniform(-1.0, 1.0, n_stones) * contrast * 150.0
    c1, c2 = np.asarray(colour, np.float32), np.asarray(colour2, np.float32)
    for x, y, r, m, t in zip(xs, ys, rs, mix, tone):
        col = tuple(float(v) for v in (1 - m) * c1 + m * c2 + t)
        for dx in (-size, 0, size):  # draw the wrapped copies too: the texture tiles
            for dy in (-size, 0, size):
                cx, cy = int(x) + dx, int(y) + dy
                if -r <= cx < size + r and -r <= cy < size + r:
                    cv2.circle(img, (cx, cy), int(r), col, -1, lineType=cv2.LINE_AA)
    return img + (contrast * 25.0 * _noise(rng, size, 0.7))[..., None]


def _grass(rng, size, colour, colour2, contrast):
    blades = gaussian_filter(rng.standard_normal((size, size)).astype(np.float32), (2.5, 0.6), mode="wrap")
    blades /= blades.std() + 1e-9
    dry = np.clip(0.5 + 0.6 * _noise(rng, size, 18.0), 0.0, 1.0)[..., None]
    base = (1 - dry) * _rgb(colour) + dry * _rgb(colour2)
    lum = 1.0 + contrast * (0.7 * blades + 0.3 * _noise(rng, size, 3.0))
    return base * lum[..., None]


def _uniform(rng, size, colour, colour2, contrast):
    return _rgb(colour) + (contrast * 90.0 * _noise(rng, size, 0.8))[..., None]


def _stripes(rng, size, colour, colour2, contrast, stripes=2, width=0.05):
    img = _rgb(colour) + (contrast * 90.0 * _noise(rng, size, 0.7))[..., None]
    x = (np.arange(size) + 0.5) / size * stripes % 1.0
    paint = (np.abs(x - 0.5) < width / 2).astype(np.float32)[None, :]  # centred: the tile edge is base
    wear = np.clip(0.85 + 0.25 * _noise(rng, size, 1.5), 0.0, 1.0)  # worn paint shows the base through
    a = (paint * wear)[..., None]
    return (1 - a) * img + a * _rgb(colour2)


def _checker(rng, size, colour, colour2, contrast, tiles=8, grout=0.04):
    t = (np.arange(size) * tiles) // size
    board = ((t[:, None] + t[None, :]) % 2).astype(np.float32)[..., None]
    shade = rng.uniform(-1.0, 1.0, (tiles, tiles)).astype(np.float32) * contrast * 20.0  # tile-to-tile tone
    img = (1 - board) * _rgb(colour) + board * _rgb(colour2) + shade[t[:, None], t[None, :]][..., None]
    img += (contrast * 60.0 * _noise(rng, size, 0.7))[..., None]
    f = (np.arange(size) + 0.5) * tiles / size % 1.0
    g = ((f < grout / 2) | (f > 1 - grout / 2)).astype(np.float32)
    gmask = np.maximum(g[:, None], g[None, :])[..., None]
    return (1 - gmask) * img + gmask * 0.55 * img


def _pavers(rng, size, colour, colour2, contrast, courses=8, ratio=2, joint=0.06):
    # Running bond: ``courses`` rows of bricks ``ratio`` times as long as wide, each row offset by
    # half a brick; each brick of either colour (at random) with its own small tone, dark joints.
    h = size / courses
    y = (np.arange(size) + 0.5) / h
    row = np.floor(y).astype(int) % courses
    x = (np.arange(size)[None, :] + 0.5) / (h * ratio) + 0.5 * (row[:, None] % 2)
    n_per_row = courses // ratio
    brick = row[:, None] * n_per_row + (np.floor(x).astype(int) % n_per_row)
    mix = (rng.random(courses * n_per_row) < 0.5).astype(np.float32)  # two-tone, laid at random
    tone = rng.uniform(-1.0, 1.0, courses * n_per_row).astype(np.float32) * contrast * 30.0
    m = mix[brick][..., None]
    img = (1 - m) * _rgb(colour) + m * _rgb(colour2) + tone[brick][..., None]
    img += (contrast * 60.0 * _noise(rng, size, 0.7))[..., None]
    fy, fx = (y % 1.0)[:, None], x % 1.0
    # Joint half-widths across a course and along a brick, at least half a texel so that no joint
    # falls between texel centres.
    jy, jx = max(joint / 2, 0.5 / h), max(joint / 2, 0.5 / h) / ratio
    gmask = ((fy <= jy) | (fy >= 1 - jy) | (fx <= jx) | (fx >= 1 - jx)).astype(np.float32)[..., None]
    return (1 - gmask) * img + gmask * 0.5 * img


def _blotches(rng, size, colour, colour2, contrast, blotch=0.08):
    field = _noise(rng, size, blotch * size)
    m = 1.0 / (1.0 + np.exp(-3.0 * field))[..., None]  # soft-edged patches of either colour
    img = (1 - m) * _rgb(colour) + m * _rgb(colour2)
    return img + (contrast * 90.0 * _noise(rng, size, 0.7))[..., None]


#: Generators by family: ``f(rng, size, colour, colour2, contrast, **family_options)`` -> float image.
GROUND_GENERATORS = {"speckle": _speckle, "gravel": _gravel, "grass": _grass, "uniform": _uniform,
                     "stripes": _stripes, "checker": _checker, "blotches": _blotches,
                     "pavers": _pavers}


def ground_family_texture(family, rng, *, size=512, colour, colour2, contrast, **options):
    """A seamless (size, size, 3) uint8 ground texture of one family (see ``rover_appearance``)."""
    img = GROUND_GENERATORS[family](rng, size, colour, colour2, contrast, **options)
    return np.clip(img, 0, 255).astype(np.uint8)


#: Azimuth (deg, MuJoCo's free-camera convention) at the centre of each side face of a skybox image
#: of six stacked square faces; face 2 looks up and face 3 down (measured by rendering).
SKY_FACE_AZIMUTH = {0: 0.0, 5: 90.0, 1: 180.0, 4: 270.0}


def _face_angles(face, n):
    """Azimuth and elevation (rad) of every texel (n, n) of a skybox face."""
    c = (2 * np.arange(n) + 1) / n - 1.0  # -1..1 across the face
    x, y = np.meshgrid(c, -c)  # columns, rows (row 0 at the top)
    if face in SKY_FACE_AZIMUTH:
        az = np.radians(SKY_FACE_AZIMUTH[face]) + np.arctan(x)
        el = np.arctan2(y, np.sqrt(1.0 + x * x))
    else:
        az = np.arctan2(y, x)
        el = np.arctan2(1.0, np.hypot(x, y)) * (1.0 if face == 2 else -1.0)
    return az, el


def sky_cube(rng, *, colour, colour2, clutter_colour, clutter_deg, size=256):
    """Skybox image (6 size, size, 3) uint8: a gradient from ``colour2`` at the horizon to ``colour``
    at the zenith, with a seeded silhouette of trees and buildings up to ``clutter_deg`` above the
    horizon in ``clutter_colour``, continued darker below the horizon."""
    k = np.arange(1, 7)
    amp = rng.uniform(0.2, 1.0, 6) / k
    phase = rng.uniform(0, 2 * np.pi, 6)
    # Buildings: blocks of random width (deg of azimuth) and height.
    n_b = int(rng.integers(6, 14))
    b_az = rng.uniform(0, 2 * np.pi, n_b)
    b_w = np.radians(rng.uniform(2.0, 10.0, n_b))
    b_h = rng.uniform(0.5, 1.0, n_b)
    c_top, c_hor = np.asarray(colour, np.float32), np.asarray(colour2, np.float32)
    c_clut = np.asarray(clutter_colour, np.float32)
    faces = []
    for face in range(6):
        az, el = _face_angles(face, size)
        trees = 0.55 + 0.35 * sum(a * np.sin(kk * az + p) for a, kk, p in zip(amp, k, phase)) / amp.sum()
        trees += 0.08 * np.sin(40 * az)  # crowns
        prof = trees
        for a0, w, h in zip(b_az, b_w, b_h):
            d = np.abs((az - a0 + np.pi) % (2 * np.pi) - np.pi)
            prof = np.where(d < w / 2, np.maximum(prof, h), prof)
        height = np.radians(clutter_deg) * np.clip(prof, 0.0, 1.0)
        s = np.clip(el / (np.pi / 2), 0.0, 1.0)[..., None]
        img = (1 - s) * c_hor + s * c_top
        shade = 1.0 + 0.12 * np.sin(7 * az + 3 * el)[..., None]
        img = np.where(((el >= 0) & (el < height))[..., None], c_clut * shade, img)
        # Below the horizon (seen past the terrain's edge) the clutter continues, darker.
        img = np.where((el < 0)[..., None], 0.75 * c_clut * shade, img)
        faces.append(img)
    return np.clip(np.concatenate(faces, axis=0), 0, 255).astype(np.uint8)
