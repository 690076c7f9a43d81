"""Robust (IRLS) kernels of the registration residuals: Huber, Tukey's biweight, plain squares."""

from __future__ import annotations

import numpy as np

__all__ = ["ROBUST_KERNELS", "DEFAULT_SCALE", "robust_weight", "robust_cost"]

ROBUST_KERNELS = ("huber", "tukey", "none")
DEFAULT_SCALE = {"huber": 0.1, "tukey": 0.5, "none": np.inf}   # metres


def robust_weight(r, kind, scale):
    """IRLS weight ``rho'(r) / r`` (same shape as the residuals ``r``, metres).

    ``kind`` is one of :data:`ROBUST_KERNELS`; ``scale`` the Huber threshold or Tukey cut-off (m).
    """
    a = np.abs(r)
    if kind == "huber":
        return np.where(a <= scale, 1.0, scale / np.maximum(a, scale))
    if kind == "tukey":
        u = np.minimum(a / scale, 1.0)
        return (1.0 - u * u) ** 2
    return np.ones_like(r)


def robust_cost(r, kind, scale):
    """The kernel ``rho(r)`` itself (m^2), whose weighted mean the registration minimises."""
    a = np.abs(r)
    if kind == "huber":
        return np.where(a <= scale, 0.5 * a * a, scale * (a - 0.5 * scale))
    if kind == "tukey":
        u = np.minimum(a / scale, 1.0)
        return scale * scale / 6.0 * (1.0 - (1.0 - u * u) ** 3)
    return 0.5 * a * a
