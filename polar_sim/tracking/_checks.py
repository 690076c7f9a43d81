"""Input checks of the tracking package (on top of :mod:`polar_sim._validation`).

Candidates for the shared module: :func:`as_normals`, :func:`as_rgbd`.
"""

from __future__ import annotations

import numpy as np

from polar_sim._validation import as_image, as_points

__all__ = ["as_model_points", "as_normals", "as_rgbd"]


def as_model_points(x, name="model_points"):
    """Object-frame model points (M, 3), finite, at least 4 and not all on one line."""
    P = as_points(x, 3, name)
    if len(P) < 4:
        raise ValueError(f"{name}: expected at least 4 points, got {len(P)}")
    s = np.linalg.svd(P - P.mean(axis=0), compute_uv=False)
    if s[1] <= 1e-9 * max(s[0], 1e-300):
        raise ValueError(f"{name}: points are collinear or coincident; a 3D shape is needed")
    return P


def as_normals(x, n, name="model_normals"):
    """Normals (n, 3), finite and non-zero; returned unit length."""
    N = as_points(x, 3, name)
    if len(N) != n:
        raise ValueError(f"{name}: expected {n} normals to match the model points, got {len(N)}")
    norm = np.linalg.norm(N, axis=1)
    if (norm < 1e-12).any():
        raise ValueError(f"{name}: contains zero-length normals")
    return N / norm[:, None]


def as_rgbd(rgb, depth, *, shape=None):
    """Check one RGB-D frame: rgb (H, W, 3) uint8, depth (H, W) metres, same size (and ``shape``).

    Returns ``(rgb, depth)`` with depth as float32 in which missing values (0, NaN, inf) are 0.
    Raises ``ValueError`` when the depth has no valid (finite, positive) value at all.
    """
    rgb = as_image(rgb, "rgb", channels=3, dtype=np.uint8, shape=shape)
    if not isinstance(depth, np.ndarray):
        raise TypeError(f"depth: expected a numpy array, got {type(depth).__name__}")
    if depth.ndim != 2 or depth.shape != rgb.shape[:2]:
        raise ValueError(f"depth: expected shape {rgb.shape[:2]} to match rgb, got {depth.shape}")
    if not np.issubdtype(depth.dtype, np.number) or np.issubdtype(depth.dtype, np.complexfloating):
        raise TypeError(f"depth: expected a real numeric array, got dtype {depth.dtype}")
    d = depth.astype(np.float32, copy=False)
    with np.errstate(invalid="ignore"):
        if (d < 0).any():
            raise ValueError("depth: contains negative depths (use 0 or NaN for missing)")
        good = np.isfinite(d) & (d > 0)
    if not good.any():
        raise ValueError("depth: no valid value (all NaN, inf, zero or negative)")
    if not good.all():
        d = np.where(good, d, np.float32(0.0))
    return rgb, d
