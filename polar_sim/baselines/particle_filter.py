"""Monte Carlo localisation on a likelihood field: the "PF" baseline of the GPIS papers."""

from __future__ import annotations

import numpy as np

from polar_sim._validation import (
    as_float_array,
    as_int,
    as_pose2d,
    as_positive_float,
    as_rng,
    check_updated,
)
from polar_sim.registration import as_scan2d, as_sensor_offset, beam_points, valid_beams
from polar_sim.geometry import wrap_angle
from polar_sim.params import Parameterised, Tags

__all__ = ["ParticleFilterLocalizer", "sample_motion_model_odometry", "low_variance_resample"]


def sample_motion_model_odometry(particles, odom_prev, odom_now, alphas, rng):
    """Propagate particles (n, 3) by an odometry increment (Probabilistic Robotics, table 5.6).

    The increment between the odometry poses ``odom_prev`` and ``odom_now`` (x, y, theta) is split
    into a rotation, a translation and a rotation, each perturbed by zero-mean Gaussian noise of
    variance ``a1 rot^2 + a2 trans^2`` (rotations) and ``a3 trans^2 + a4 (rot1^2 + rot2^2)``
    (translation), with ``alphas = (a1, a2, a3, a4)``. For a translation below 1 mm the first
    rotation is taken as 0 (its direction is meaningless). Returns new particles (n, 3).
    """
    a1, a2, a3, a4 = alphas
    dx, dy = odom_now[0] - odom_prev[0], odom_now[1] - odom_prev[1]
    trans = float(np.hypot(dx, dy))
    if not trans < 1e100:   # its square would overflow the noise model
        raise ValueError(f"odom_pose2d: the odometry increment ({trans:.3g} m) is too large to model")
    rot1 = float(wrap_angle(np.arctan2(dy, dx) - odom_prev[2])) if trans > 1e-3 else 0.0
    rot2 = float(wrap_angle(odom_now[2] - odom_prev[2] - rot1))
    n = particles.shape[0]
    noise = rng.standard_normal((n, 3))
    r1 = rot1 - noise[:, 0] * np.sqrt(a1 * rot1**2 + a2 * trans**2)
    tr = trans - noise[:, 1] * np.sqrt(a3 * trans**2 + a4 * (rot1**2 + rot2**2))
    r2 = rot2 - noise[:, 2] * np.sqrt(a1 * rot2**2 + a2 * trans**2)
    th = particles[:, 2] + r1
    out = np.empty_like(particles)
    out[:, 0] = particles[:, 0] + tr * np.cos(th)
    out[:, 1] = particles[:, 1] + tr * np.sin(th)
    out[:, 2] = wrap_angle(th + r2)
    return out


def low_variance_resample(weights, rng):
    """Indices (n,) drawn by the low-variance (systematic) resampler (Probabilistic Robotics, table 4.4).

    ``weights`` (n,) must be normalised. One uniform draw places n equally spaced pointers.
    """
    n = weights.shape[0]
    c = np.cumsum(weights)
    c[-1] = 1.0  # guard against round-off leaving the last pointer past the end
    pointers = (rng.uniform(0.0, 1.0 / n) + np.arange(n) / n)
    return np.minimum(np.searchsorted(c, pointers, side="right"), n - 1)


#: At most this many particles (240 MB of poses): more is refused before anything is allocated.
MAX_PARTICLES = 10**7


class ParticleFilterLocalizer(Parameterised):
    """MCL with the odometry motion model and a likelihood-field sensor model.

    Parameters
    ----------
    n_particles : int, default=1000
    alphas : (a1, a2, a3, a4), default=(0.05, 0.05, 0.05, 0.05)
        Odometry noise (see :func:`sample_motion_model_odometry`).
    n_beams : int, default=60
        Beams scored per scan, evenly spread over the valid ones (beams are treated as
        independent, so using them all makes the filter overconfident).
    resample_threshold : float, default=0.5
        Resample when the effective sample size drops below this fraction of ``n_particles``.
    sensor_offset : (x, y) or (x, y, yaw), default=(0.0, 0.0)
        Sensor mounting in the robot base frame, m and rad.
    min_range, max_range : float, default=0.0, 30.0
        A beam is scored if ``min_range < r < max_range``; others carry no return.
    seed : int, Generator or None, default=None
        Randomness of the initial sampling, the motion noise and the resampler. With an int,
        ``initialize`` restarts the same stream, so a run is reproducible bit for bit.

    Attributes
    ----------
    particles_ : ndarray of shape (n_particles, 3)
        Particle poses (x, y, theta) of the robot base, m and rad.
    weights_ : ndarray of shape (n_particles,)
        Normalised weights.
    pose_ : ndarray of shape (3,)
        Weighted mean pose (circular mean for theta).
    cov_ : ndarray of shape (3, 3)
        Weighted covariance of the particles about ``pose_`` (theta deviations wrapped).
    n_eff_ : float
        Effective sample size ``1 / sum(w^2)`` after the last correction (before resampling).
    resampled_ : bool
        Whether the last correction resampled.
    """

    TAGS = Tags(update="update", random_state="seed", data="polar_sim.baselines.examples:particle_filter")

    def __init__(
        self,
        *,
        n_particles: int = 1000,
        alphas=(0.05, 0.05, 0.05, 0.05),
        n_beams: int = 60,
        resample_threshold: float = 0.5,
        sensor_offset=(0.0, 0.0),
        min_range: float = 0.0,
        max_range: float = 30.0,
        seed=None,
    ):
        self.n_particles = n_particles
        self.alphas = alphas
        self.n_beams = n_beams
        self.resample_threshold = resample_threshold
        self.sensor_offset = sensor_offset
        self.min_range = min_range
        self.max_range = max_range
        self.seed = seed

    def _check_params(self):
        as_int(self.n_particles, "n_particles", minimum=1, maximum=MAX_PARTICLES)
        as_int(self.n_beams, "n_beams", minimum=1)
        a = as_float_array(self.alphas, "alphas")
        if a.shape != (4,) or not np.isfinite(a).all() or (a < 0).any():
            raise ValueError(f"alphas: expected 4 finite non-negative numbers, got {self.alphas!r}")
        t = as_positive_float(self.resample_threshold, "resample_threshold", allow_zero=True)
        if t > 1:
            raise ValueError(f"resample_threshold: expected a fraction in [0, 1], got {t}")
        as_positive_float(self.min_range, "min_range", allow_zero=True)
        as_positive_float(self.max_range, "max_range")
        return a, as_sensor_offset(self.sensor_offset)

    def initialize(self, field, pose2d, std=(0.1, 0.1, 0.05)):
        """Start tracking: particles drawn from a Gaussian around ``pose2d``.

        Parameters
        ----------
        field : LikelihoodField
            The fitted likelihood field of the map.
        pose2d : (x, y, theta)
            Prior mean of the robot base pose, m and rad.
        std : (sx, sy, stheta), default=(0.1, 0.1, 0.05)
            Prior standard deviations, m and rad (zeros allowed).

        Returns
        -------
        self
        """
        self._check_params()
        check_updated(field, "log_field_")
        pose2d = as_pose2d(pose2d, "pose2d")
        std = as_float_array(std, "std")
        if std.shape != (3,) or not np.isfinite(std).all() or (std < 0).any():
            raise ValueError(f"std: expected 3 finite non-negative numbers, got {std!r}")
        self.reset()
        rng = as_rng(self.seed)
        n = int(self.n_particles)
        p = pose2d + rng.standard_normal((n, 3)) * std
        p[:, 2] = wrap_angle(p[:, 2])
        self.field_ = field
        self.rng_ = rng
        self.particles_ = p
        self.weights_ = np.full(n, 1.0 / n)
        self.n_eff_ = float(n)
        self.resampled_ = False
        self._estimate()
        return self

    def predict(self, odom_pose2d):
        """Apply the motion since the previous odometry pose (the first call only records it)."""
        check_updated(self, "particles_")
        alphas, _ = self._check_params()
        odom = as_pose2d(odom_pose2d, "odom_pose2d")
        if hasattr(self, "odom_"):
            self.particles_ = sample_motion_model_odometry(self.particles_, self.odom_, odom, alphas, self.rng_)
        self.odom_ = odom
        self._estimate()
        return self

    def correct(self, angles, ranges):
        """Weight the particles by a scan and resample if the effective sample size is low."""
        check_updated(self, "particles_")
        _, off = self._check_params()
        angles, ranges = as_scan2d(angles, ranges)
        ok = np.flatnonzero(valid_beams(ranges, self.min_range, self.max_range))
        if ok.size == 0:
            return self
        pick = ok[np.unique(np.round(np.linspace(0, ok.size - 1, min(int(self.n_beams), ok.size))).astype(int))]
        b = beam_points(angles[pick], ranges[pick], off)  # (k, 2) in the base frame
        p = self.particles_
        c, s = np.cos(p[:, 2])[:, None], np.sin(p[:, 2])[:, None]
        x = p[:, 0:1] + c * b[:, 0] - s * b[:, 1]
        y = p[:, 1:2] + s * b[:, 0] + c * b[:, 1]
        loglik = self.field_._lookup(x, y).sum(axis=1, dtype=np.float64)
        with np.errstate(divide="ignore"):  # a weight that underflowed to 0 stays at 0
            logw = np.log(self.weights_) + loglik
        logw -= logw.max()
        w = np.exp(logw)
        w /= w.sum()
        self.n_eff_ = float(1.0 / np.sum(w * w))
        self.weights_ = w
        self._estimate()  # estimate from the weighted set, before resampling throws information away
        self.resampled_ = self.n_eff_ < float(self.resample_threshold) * len(w)
        if self.resampled_:
            idx = low_variance_resample(w, self.rng_)
            self.particles_ = self.particles_[idx]
            self.weights_ = np.full(len(w), 1.0 / len(w))
        return self

    def update(self, angles, ranges, odom_pose2d):
        """One filter step: :meth:`predict` with the odometry pose, then :meth:`correct` with the scan.

        Parameters
        ----------
        angles, ranges : ndarray of shape (n,)
            Scan in the sensor frame (rad, m; inf/NaN = no return).
        odom_pose2d : (x, y, theta)
            The robot's odometry pose now (any fixed frame); only increments are used.

        Returns
        -------
        self
        """
        check_updated(self, "particles_")
        as_pose2d(odom_pose2d, "odom_pose2d")
        as_scan2d(angles, ranges)  # reject a bad scan before the motion step changes anything
        return self.predict(odom_pose2d).correct(angles, ranges)

    def _estimate(self):
        w, p = self.weights_, self.particles_
        th = np.arctan2(w @ np.sin(p[:, 2]), w @ np.cos(p[:, 2]))
        mean = np.array([w @ p[:, 0], w @ p[:, 1], th])
        dev = p - mean
        dev[:, 2] = wrap_angle(dev[:, 2])
        self.pose_ = mean
        self.cov_ = (dev * w[:, None]).T @ dev
