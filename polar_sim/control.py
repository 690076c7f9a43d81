"""Path following on planar poses (numpy only): pure pursuit and a speed profile.

:class:`PurePursuit` is the project's one path follower: the simulator's route driver (rover
routes), the recorded 2D lidar drives and the scripted baseline policies of the environments all
steer with it.
"""

from __future__ import annotations

import numpy as np

from polar_sim._validation import as_bool, as_float, as_positive_float, check_choice
from polar_sim.geometry import wrap_angle

__all__ = ["PurePursuit"]

TARGETS = ("arc", "waypoint")


class PurePursuit:
    """Pure-pursuit steering along a polyline.

    The unicycle at ``(x, y, yaw)`` steers onto the arc through a target point at distance ``ld``
    and heading error ``alpha``: yaw rate ``2 v sin(alpha) / ld`` (curvature ``2 sin(alpha) / ld``,
    or ``2 y / d^2`` for a target at ``(x, y)`` in the robot frame, :meth:`curvature`). Two ways to
    pick the target:

    - ``target="arc"`` (the rover routes): the point ``lookahead + lookahead_time * |v|`` metres of
      arc length ahead of the pose's projection on the path (a closed path wraps round; progress is
      monotone over laps).
    - ``target="waypoint"`` (the lidar drives): the first waypoint at least ``lookahead`` metres
      away, counting from the last one reached; progress never goes back, so a route that passes
      near itself is safe. ``lookahead_time`` is not used. :attr:`done` once the target is the
      last waypoint.

    :meth:`steer` gives the yaw rate at a given speed; :meth:`command` adds a speed profile: a
    speed ``v = max(vmax cos^2(alpha), min_speed)`` (0 when the target is behind, before the
    floor), and on the spot at ``max_yaw_rate`` when ``|alpha| >= turn_in_place``.

    Parameters
    ----------
    path : (n, 2) waypoints, metres, n >= 2.
    lookahead : float
        Lookahead distance, metres (> 0).
    closed : bool
        The path is a loop (the last waypoint connects to the first); ``target="arc"`` only.
    lookahead_time : float
        Seconds of travel added to the lookahead distance (``target="arc"``), >= 0.
    target : {"arc", "waypoint"}
        How the target point is picked (above).
    max_yaw_rate : float
        :meth:`command`'s yaw-rate limit, rad/s (> 0; ``inf``: none).
    turn_in_place : float
        :meth:`command` turns on the spot at ``max_yaw_rate`` when ``|alpha|`` reaches this, rad
        (in (0, pi]; ``pi``: never, the default).
    min_speed : float
        :meth:`command`'s speed floor, m/s (>= 0).
    """

    def __init__(self, path, lookahead=6.0, *, closed=False, lookahead_time=0.6, target="arc",
                 max_yaw_rate=np.inf, turn_in_place=np.pi, min_speed=0.0):
        self.path = np.asarray(path, dtype=np.float64)
        if self.path.ndim != 2 or self.path.shape[1] != 2 or len(self.path) < 2:
            raise ValueError(f"path: expected shape (n >= 2, 2), got {self.path.shape}")
        if not np.isfinite(self.path).all():
            raise ValueError("path: expected finite waypoints")
        self.lookahead = as_positive_float(lookahead, "lookahead")
        self.closed = as_bool(closed, "closed")
        self.lookahead_time = as_positive_float(lookahead_time, "lookahead_time", allow_zero=True)
        self.target = check_choice(target, TARGETS, "target")
        if self.closed and target == "waypoint":
            raise ValueError("closed: a closed path takes target='arc' (waypoints are followed once)")
        self.max_yaw_rate = as_float(max_yaw_rate, "max_yaw_rate", minimum=0.0, exclusive_minimum=True,
                                     allow_inf=True)
        self.turn_in_place = as_float(turn_in_place, "turn_in_place", minimum=0.0, maximum=np.pi,
                                      exclusive_minimum=True)
        self.min_speed = as_positive_float(min_speed, "min_speed", allow_zero=True)
        seg = np.diff(np.vstack([self.path, self.path[:1]]) if closed else self.path, axis=0)
        self._s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(seg, axis=1))])
        self.length = float(self._s[-1])
        self.reset()

    def reset(self):
        """Back to the start of the path (progress 0, the first waypoint)."""
        self._progress = 0.0
        self._i = 0

    @property
    def done(self):
        """The end of an open path is reached (``target="waypoint"``: the target is the last waypoint)."""
        if self.target == "waypoint":
            return self._i >= len(self.path) - 1
        return not self.closed and self._progress >= self.length

    @staticmethod
    def curvature(x, y):
        """Curvature (1/m, positive to the left) of the arc from the robot, at the origin heading
        along +x, through the point ``(x, y)`` (m, robot frame): ``2 y / (x^2 + y^2)``."""
        return 2.0 * y / max(x * x + y * y, 1e-6)

    def _point_at(self, s):
        if self.closed:
            s = s % self.length
            pts = np.vstack([self.path, self.path[:1]])
        else:
            s = min(max(s, 0.0), self.length)
            pts = self.path
        i = int(np.clip(np.searchsorted(self._s, s, side="right") - 1, 0, len(pts) - 2))
        t = (s - self._s[i]) / max(self._s[i + 1] - self._s[i], 1e-12)
        return pts[i] + t * (pts[i + 1] - pts[i])

    def _nearest_s(self, xy):
        """Arc length of the nearest path point, searched near the previous progress."""
        pts = np.vstack([self.path, self.path[:1]]) if self.closed else self.path
        a, b = pts[:-1], pts[1:]
        ab = b - a
        t = np.clip(((xy - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
        d = np.linalg.norm(a + t[:, None] * ab - xy, axis=1)
        s = self._s[:-1] + t * np.diff(self._s)
        if self.closed:
            # Prefer candidates just ahead of the previous progress (loops pass near themselves).
            gap = (s - self._progress % self.length) % self.length
            d = d + 0.05 * np.minimum(gap, self.length - gap)
        i = int(np.argmin(d))
        s_i = s[i]
        if self.closed:
            # The lap of the nearest point is the one that puts it closest to the previous progress. (Taking
            # the lap of the previous progress jumped a whole lap ahead when the pose was just past the start
            # and the nearest point still just behind it, which ended multi-lap routes a lap early.)
            s_i += self.length * np.round((self._progress - s_i) / self.length)
        return s_i, float(d[i] if not self.closed else np.linalg.norm(a[i] + t[i] * ab[i] - xy))

    def progress(self, pose2d):
        """Arc length travelled along the path (m), monotone over laps of a closed path."""
        s, _ = self._nearest_s(np.asarray(pose2d[:2], dtype=np.float64))
        self._progress = max(self._progress, s)
        return self._progress

    def cross_track_error(self, pose2d):
        """Distance (m) from the pose to the path."""
        return self._nearest_s(np.asarray(pose2d[:2], dtype=np.float64))[1]

    def _target_point(self, pose2d, v):
        """The point (2,) to steer at; advances the progress."""
        if self.target == "arc":
            return self._point_at(self.progress(pose2d) + self.lookahead + self.lookahead_time * abs(v))
        x, y = pose2d[0], pose2d[1]
        while self._i < len(self.path) - 1 and np.hypot(*(self.path[self._i] - (x, y))) < self.lookahead:
            self._i += 1
        return self.path[self._i]

    def _heading_error(self, pose2d, v):
        """``(alpha, ld)``: the target's bearing from the heading (rad, wrapped) and distance (m)."""
        x, y, th = pose2d
        dx, dy = self._target_point(pose2d, v) - [x, y]
        return wrap_angle(np.arctan2(dy, dx) - th), max(np.hypot(dx, dy), 1e-6)

    def steer(self, pose2d, v):
        """Yaw rate (rad/s) that points a unicycle at ``pose2d`` moving at ``v`` (m/s) onto the path."""
        alpha, ld = self._heading_error(pose2d, v)
        return float(2.0 * v * np.sin(alpha) / ld)

    def command(self, pose2d, vmax):
        """``(v, omega)``: speed (m/s, at most ``vmax``) and yaw rate (rad/s) from the speed profile
        (class docstring); ``vmax`` also sets the lookahead's speed term (``target="arc"``)."""
        alpha, ld = self._heading_error(pose2d, vmax)
        v = max(vmax * max(0.0, np.cos(alpha)) ** 2, self.min_speed)
        if abs(alpha) < self.turn_in_place:
            om = 2.0 * v * np.sin(alpha) / ld
        else:
            om = np.sign(alpha) * self.max_yaw_rate
        return float(v), float(np.clip(om, -self.max_yaw_rate, self.max_yaw_rate))
