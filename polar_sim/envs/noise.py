"""Sensor noise of the navigation environments: lidar range noise and wheel odometry.

Both are seeded from the episode (``reset(seed=...)``): the same seed gives the same noise, bit
for bit. Parameters that are negative or non-finite raise ``ValueError`` naming them.
"""

from __future__ import annotations

import dataclasses
import numbers

import numpy as np

__all__ = ["OdometryNoise", "WheelOdometry", "as_lidar_noise", "as_odometry_noise", "LIDAR_NOISE",
           "ODOMETRY_NOISE"]

#: Default lidar noise of the v1 environments: (range sigma in m, dropout probability per beam).
LIDAR_NOISE = (0.01, 0.01)


def _nonneg(value, name):
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name}: expected a finite number >= 0, got {value!r}")
    v = float(value)
    if not np.isfinite(v) or v < 0:
        raise ValueError(f"{name}: expected a finite number >= 0, got {value!r}")
    return v


@dataclasses.dataclass(frozen=True)
class OdometryNoise:
    """Wheel odometry noise, per step of ``dt`` seconds.

    The wheels measure the distance driven ``ds`` and the turn ``dtheta`` of every step:

    - ``ds_measured = (1 + e) ds + N(0, (distance |ds|)^2)``, with a scale error ``e ~ N(0,
      scale^2)`` drawn once per episode (a wheel radius that is not quite the nominal one);
    - ``dtheta_measured = dtheta + b dt + N(0, (yaw |dtheta|)^2 + (yaw_per_metre |ds|)^2)``, with
      a yaw drift ``b ~ N(0, yaw_drift^2)`` rad/s drawn once per episode (an uneven track width,
      a slipping wheel).

    Attributes
    ----------
    distance : float
        Per-step standard deviation of ``ds``, as a fraction of ``|ds|``.
    scale : float
        Standard deviation of the episode's scale error, as a fraction.
    yaw : float
        Per-step standard deviation of ``dtheta``, as a fraction of ``|dtheta|``.
    yaw_per_metre : float
        Per-step standard deviation of ``dtheta`` per metre driven, rad/m.
    yaw_drift : float
        Standard deviation of the episode's yaw drift, rad/s.
    """

    distance: float = 0.03
    scale: float = 0.02
    yaw: float = 0.03
    yaw_per_metre: float = 0.01
    yaw_drift: float = 0.01

    def __post_init__(self):
        for f in dataclasses.fields(self):
            _nonneg(getattr(self, f.name), f"odometry_noise.{f.name}")


#: Default wheel odometry noise of the v1 environments.
ODOMETRY_NOISE = OdometryNoise()


def as_odometry_noise(value, name="odometry_noise"):
    """``None`` (exact odometry), an :class:`OdometryNoise`, or a dict of its fields."""
    if value is None or isinstance(value, OdometryNoise):
        return value
    if isinstance(value, dict):
        unknown = set(value) - {f.name for f in dataclasses.fields(OdometryNoise)}
        if unknown:
            raise ValueError(f"{name}: unknown field(s) {sorted(unknown)}; valid: "
                             f"{[f.name for f in dataclasses.fields(OdometryNoise)]}")
        return OdometryNoise(**value)
    raise TypeError(f"{name}: expected None, an OdometryNoise or a dict of its fields, got {type(value).__name__}")


def as_lidar_noise(value, name="lidar_noise"):
    """``None`` (exact ranges) or ``(sigma, dropout)``: Gaussian range noise (m) and the
    probability that a beam returns nothing. Returns a ``polar_sim.sim.RangeNoise`` or None."""
    if value is None:
        return None
    from polar_sim.sim.sensors import RangeNoise

    if isinstance(value, RangeNoise):
        return value
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise TypeError(f"{name}: expected None or (sigma [m], dropout [probability]), got {value!r}")
    sigma = _nonneg(value[0], f"{name} sigma")
    dropout = _nonneg(value[1], f"{name} dropout")
    if dropout >= 1.0:
        raise ValueError(f"{name} dropout: expected a probability in [0, 1), got {value[1]!r}")
    return RangeNoise(sigma=sigma, dropout=dropout)


class WheelOdometry:
    """Measured wheel odometry from the true motion, with :class:`OdometryNoise`.

    ``reset(rng)`` starts an episode (draws its scale error and yaw drift); ``measure(ds,
    dtheta, dt)`` gives the measured ``(ds, dtheta)`` of one step (m, rad).
    """

    def __init__(self, noise):
        self.noise = noise

    def reset(self, rng):
        self._rng = rng
        n = self.noise
        if n is None:
            self.scale_error = self.yaw_bias = 0.0
        else:
            self.scale_error = float(rng.normal(0.0, n.scale)) if n.scale > 0 else 0.0
            self.yaw_bias = float(rng.normal(0.0, n.yaw_drift)) if n.yaw_drift > 0 else 0.0

    def measure(self, ds, dtheta, dt):
        n = self.noise
        if n is None:
            return float(ds), float(dtheta)
        z = self._rng.standard_normal(2)  # always two draws: the stream does not depend on the motion
        ds_m = (1.0 + self.scale_error) * ds + n.distance * abs(ds) * z[0]
        sd = np.hypot(n.yaw * abs(dtheta), n.yaw_per_metre * abs(ds))
        return float(ds_m), float(dtheta + self.yaw_bias * dt + sd * z[1])
