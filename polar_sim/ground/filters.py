"""Adaptive 1-D Kalman filter with a random-walk model (spec §4.7)."""

from __future__ import annotations

import math

__all__ = ["KF1D"]


class KF1D:
    """Scalar random-walk Kalman filter: predict ``P += q``, update ``x += P/(P+r) (z-x)``.

    Parameters
    ----------
    x0, P0 : float
        Prior mean and variance (units of x and x²).
    q : float
        Process noise added per predict (units of x²).
    r : float
        Nominal measurement noise (units of x²).
    adaptive : {None, "code", "innovation"}
        Outlier handling. ``"code"`` is the published rule: if ``|z - x| > sqrt(r)`` then the
        measurement noise becomes ``(z - x)²``. ``"innovation"`` (the fixed default for the speed
        filter) matches the innovation variance instead: if ``(z - x)² > P + r`` then
        ``r' = (z - x)² - P``, which equals the published rule at steady state (P small) and does not
        freeze a filter whose prior is still wide.
    """

    def __init__(self, x0, P0, q, r, adaptive=None):
        self.x = float(x0)
        self.P = float(P0)
        self.q = float(q)
        self.r = float(r)
        self.adaptive = adaptive

    def predict(self):
        """Random-walk prediction: the variance grows by q."""
        self.P += self.q

    def gain(self, z, var=0.0):
        """Kalman gain and the measurement noise the update would use for measurement ``z`` whose own
        variance is ``var`` (the nominal noise ``r`` is the floor)."""
        innov = float(z) - self.x
        r = max(self.r, float(var))
        if self.adaptive == "code":
            if abs(innov) > math.sqrt(r):
                r = innov * innov
        elif self.adaptive == "innovation":
            if innov * innov > self.P + r:
                r = innov * innov - self.P
        return self.P / (self.P + r), r

    def update(self, z, var=0.0):
        """Fuse measurement ``z`` (its variance ``var``, if larger than the nominal ``r``, is used);
        returns the gain used."""
        k, r = self.gain(z, var)
        self.x = (r * self.x + self.P * float(z)) / (self.P + r)
        self.P = r * self.P / (self.P + r)
        return k

    def reset(self, x, P):
        """Set the state (static scene: x = 0)."""
        self.x = float(x)
        self.P = float(P)

    def __repr__(self):
        return f"KF1D(x={self.x:.4g}, P={self.P:.4g}, q={self.q}, r={self.r}, adaptive={self.adaptive!r})"
