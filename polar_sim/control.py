"""Path following on planar poses (numpy only): pure pursuit and a speed profile.

Used by the simulator's route driver and by the scripted baseline policies of the environments.
"""

from __future__ import annotations

import numpy as np

from polar_sim.geometry import wrap_angle

__all__ = ["PurePursuit"]


class PurePursuit:
    """Pure-pursuit steering along a polyline.

    Parameters
    ----------
    path : (n, 2) waypoints, metres.
    lookahead : float
        Lookahead distance, metres (a speed-proportional term is added: ``lookahead_time * v``).
    closed : bool
        The path is a loop (the last waypoint connects to the first).
    lookahead_time : float
        Seconds of travel added to the lookahead distance.
    """

    def __init__(self, path, lookahead=6.0, *, closed=False, lookahead_time=0.6):
        self.path = np.asarray(path, dtype=np.float64)
        if self.path.ndim != 2 or self.path.shape[1] != 2 or len(self.path) < 2:
            raise ValueError(f"path: expected shape (n >= 2, 2), got {self.path.shape}")
        self.lookahead = float(lookahead)
        self.closed = bool(closed)
        self.lookahead_time = float(lookahead_time)
        seg = np.diff(np.vstack([self.path, self.path[:1]]) if closed else self.path, axis=0)
        self._s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(seg, axis=1))])
        self.length = float(self._s[-1])
        self._progress = 0.0

    def reset(self):
        self._progress = 0.0

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

    def steer(self, pose2d, v):
        """Yaw rate (rad/s) that points a unicycle at ``pose2d`` moving at ``v`` (m/s) onto the path."""
        x, y, th = pose2d
        s = self.progress(pose2d)
        target = self._point_at(s + self.lookahead + self.lookahead_time * abs(v))
        dx, dy = target - [x, y]
        alpha = wrap_angle(np.arctan2(dy, dx) - th)
        ld = max(np.hypot(dx, dy), 1e-6)
        return float(2.0 * v * np.sin(alpha) / ld)
