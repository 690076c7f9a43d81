"""Planar poses one at a time, for an environment's per-step loop.

:func:`polar_sim.geometry.compose2d`, ``inv2d`` and ``between2d`` work on stacks of poses; on a
single pose their array machinery costs ten times the arithmetic, every step. These are the same
formulas on Python floats, in the same order and with numpy's ``cos``/``sin`` and its
remainder, so the results are the same bit for bit (``tests/envs/test_pose2d.py``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["compose", "inverse", "between", "wrap"]

_PI = np.pi
_TWO_PI = 2.0 * np.pi


def wrap(a):
    """An angle (rad, a float) wrapped to [-pi, pi): ``geometry.wrap_angle``."""
    # geometry.wrap_angle: (a + pi) % (2 pi) - pi; Python's float remainder is numpy's (the sign of
    # the divisor, fmod then one correction).
    return (a + _PI) % _TWO_PI - _PI


def compose(a, b):
    """``a ∘ b`` of poses (x, y, theta) (any length-3 sequences): b expressed in a's frame; (3,)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    c, s = float(np.cos(a2)), float(np.sin(a2))
    return np.array([a0 + c * b0 - s * b1, a1 + s * b0 + c * b1, wrap(a2 + b2)])


def inverse(a):
    """The inverse (3,) of a pose (x, y, theta)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    c, s = float(np.cos(a2)), float(np.sin(a2))
    return np.array([-c * a0 - s * a1, s * a0 - c * a1, wrap(-a2)])


def between(a, b):
    """``a^-1 ∘ b`` (3,): pose b expressed in a's frame."""
    return compose(inverse(a), b)
