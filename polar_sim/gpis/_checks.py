"""Input checks specific to polar_sim.gpis (shared ones live in polar_sim._validation; the
parameters' in polar_sim.gpis.config)."""

from __future__ import annotations

import numpy as np

from polar_sim._validation import as_float_array

__all__ = ["as_vector2", "as_directions"]


def as_vector2(x, name):
    """Return ``x`` as 2 finite float64 numbers (an array of shape (2,))."""
    a = as_float_array(x, name)
    if a.shape != (2,) or not np.isfinite(a).all():
        raise ValueError(f"{name}: expected 2 finite numbers, got {x!r}")
    return a


def as_directions(x, name, *, n=None):
    """Return unit ray directions (n, 3) as float64; zero-length or non-finite rows raise."""
    a = as_float_array(x, name)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (n, 3), got {a.shape}")
    if n is not None and a.shape[0] != n:
        raise ValueError(f"{name}: expected {n} rows to match the ranges, got {a.shape[0]}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: contains NaN or inf")
    L = np.linalg.norm(a, axis=1)
    if (L < 1e-12).any():
        raise ValueError(f"{name}: contains zero-length directions")
    return a / L[:, None]
