"""Input checks specific to :mod:`polar_sim.ground` (candidates for ``polar_sim._validation``)."""

from __future__ import annotations

import numbers

import numpy as np

__all__ = ["as_time", "as_unit_interval"]


def as_time(t, name="t"):
    """Return a timestamp (a real number or a 0-d numeric array) as a finite float (seconds)."""
    if isinstance(t, np.ndarray) and t.ndim == 0 and t.dtype.kind in "iuf":
        t = t.item()
    if isinstance(t, bool) or not isinstance(t, (numbers.Real, np.floating, np.integer)):
        raise TypeError(f"{name}: expected a real number of seconds, got {type(t).__name__}")
    v = float(t)
    if not np.isfinite(v):
        raise ValueError(f"{name}: expected a finite time in seconds, got {t!r}")
    return v


def as_unit_interval(x, name, *, open_low=False, open_high=False):
    """Return ``x`` as a float in [0, 1] (ends optionally open)."""
    if isinstance(x, bool) or not isinstance(x, numbers.Real):
        raise TypeError(f"{name}: expected a real number, got {type(x).__name__}")
    v = float(x)
    lo_bad = v <= 0 if open_low else v < 0
    hi_bad = v >= 1 if open_high else v > 1
    if not np.isfinite(v) or lo_bad or hi_bad:
        lo = "(0" if open_low else "[0"
        hi = "1)" if open_high else "1]"
        raise ValueError(f"{name}: expected a number in {lo}, {hi}, got {x!r}")
    return v
