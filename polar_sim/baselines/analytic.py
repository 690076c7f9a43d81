"""Exact maps of simple scenes: a box room with round pillars (2D) or balls (3D).

They answer ``query(points) -> (sdf, grad, var)`` like a learned map, with the exact signed
distance (positive in the free space of the room), its gradient and zero variance, and they cast
exact rays. They are the oracle "map" of the localisation tests and benchmarks (ICP on the exact
SDF is the upper bound that ICP-G and ICP-D approach) and need no simulator.
"""

from __future__ import annotations

import numpy as np

from polar_sim._validation import as_float_array, as_angles, as_intrinsics, as_points, as_pose, as_pose2d
from polar_sim.registration import as_sensor_offset, transform2d
from polar_sim.geometry import pose2d_to_T
from polar_sim.params import Parameterised, Tags

__all__ = ["RoomSDF2D", "RoomSDF3D"]


class _Room(Parameterised):
    """Box [0, size] (room frame) minus balls; ``T`` maps room frame -> world (dim+1 square)."""

    def __init__(self, size, balls, T):
        self.size = np.asarray(size, dtype=np.float64)
        self.balls = np.asarray(balls, dtype=np.float64).reshape(-1, self.size.shape[0] + 1)
        self._R = T[:-1, :-1]
        self._t = T[:-1, -1]
        dim = self.size.shape[0]
        if (self.size <= 0).any():
            raise ValueError(f"size: expected positive side lengths, got {self.size.tolist()}")
        for b in self.balls:
            c, r = b[:dim], b[dim]
            if r <= 0 or (c - r <= 0).any() or (c + r >= self.size).any():
                raise ValueError(f"pillars: each must lie strictly inside the room with radius > 0, got {b.tolist()}")

    def _to_room(self, p):
        return (p - self._t) @ self._R

    def query(self, points):
        """Exact SDF (n,), unit gradient (n, dim) and zero variance (n,) at world points (n, dim)."""
        dim = self.size.shape[0]
        p = self._to_room(as_points(points, dim, "points"))
        lo = p
        hi = self.size - p
        inside = (lo > 0).all(axis=1) & (hi > 0).all(axis=1)
        # Inside: distance to the nearest wall, gradient pointing away from it.
        both = np.concatenate([lo, hi], axis=1)
        k = np.argmin(both, axis=1)
        d_in = both[np.arange(len(p)), k]
        g_in = np.zeros_like(p)
        g_in[np.arange(len(p)), k % dim] = np.where(k < dim, 1.0, -1.0)
        # Outside: minus the Euclidean distance to the box, gradient pointing back in.
        out = np.maximum(np.maximum(-lo, -hi), 0.0)
        sgn = np.where(p < 0, 1.0, -1.0)
        d_out = np.linalg.norm(out, axis=1)
        g_out = sgn * out / np.where(d_out > 0, d_out, 1.0)[:, None]
        sdf = np.where(inside, d_in, -d_out)
        grad = np.where(inside[:, None], g_in, g_out)
        for b in self.balls:
            v = p - b[:dim]
            n = np.linalg.norm(v, axis=1)
            d = n - b[dim]
            closer = d < sdf
            sdf = np.where(closer, d, sdf)
            gb = v / np.where(n > 0, n, 1.0)[:, None]
            grad = np.where(closer[:, None], gb, grad)
        return sdf, grad @ self._R.T, np.zeros(len(p))

    def _cast(self, origin, dirs):
        """Distance along each world direction (n, dim) from a world origin to the first surface."""
        dim = self.size.shape[0]
        o = self._to_room(origin[None])[0]
        u = dirs @ self._R
        if not ((o > 0).all() and (o < self.size).all()):
            raise ValueError(f"origin: the sensor must be inside the room, got {origin.tolist()}")
        with np.errstate(divide="ignore", invalid="ignore"):
            t_wall = np.where(u > 0, (self.size - o) / u, np.where(u < 0, -o / u, np.inf))
        t = t_wall.min(axis=1)
        for b in self.balls:
            oc = o - b[:dim]
            if np.linalg.norm(oc) <= b[dim]:
                raise ValueError(f"origin: the sensor is inside an obstacle, got {origin.tolist()}")
            uu = np.einsum("ij,ij->i", u, u)
            bb = u @ oc
            cc = oc @ oc - b[dim] ** 2
            disc = bb * bb - uu * cc
            hit = disc >= 0
            th = np.where(hit, (-bb - np.sqrt(np.where(hit, disc, 0.0))) / uu, np.inf)
            t = np.where((th > 0) & (th < t), th, t)
        return t


class RoomSDF2D(_Room):
    """Rectangular room ``[0, w] x [0, h]`` with circular pillars, placed in the world by ``pose``.

    Parameters
    ----------
    size : (w, h), default=(10.0, 6.0)
        Inner size of the room, metres.
    pillars : sequence of (cx, cy, radius), default=((6.0, 3.0, 0.5),)
        Round pillars in the room frame, metres; each strictly inside the room.
    pose : (x, y, theta), default=(0, 0, 0)
        Pose of the room frame (its corner) in the world, m and rad.

    Notes
    -----
    The SDF is exact everywhere: positive in the free space, negative inside pillars and behind
    the walls (outside the box).
    """

    TAGS = Tags(query="query", requires_update=False, data="polar_sim.baselines.examples:room_2d")

    def __init__(self, size=(10.0, 6.0), pillars=((6.0, 3.0, 0.5),), pose=(0.0, 0.0, 0.0)):
        pose = as_pose2d(pose, "pose")
        self.pose = pose
        self.pillars = pillars
        T = pose2d_to_T(pose)
        super().__init__(as_float_array(size, "size").reshape(2), pillars, np.delete(np.delete(T, 2, 0), 2, 1))

    def scan(self, pose2d, angles, *, sensor_offset=(0.0, 0.0)):
        """Exact ranges (n,) of beams at ``angles`` (rad, sensor frame) from a robot at ``pose2d``.

        The sensor sits at ``sensor_offset`` (x, y[, yaw]) in the robot base frame.
        """
        pose2d = as_pose2d(pose2d, "pose2d")
        angles = as_angles(angles, "angles")
        off = as_sensor_offset(sensor_offset)
        origin = transform2d(pose2d, off[None, :2])[0]
        a = angles + pose2d[2] + off[2]
        return self._cast(origin, np.column_stack([np.cos(a), np.sin(a)]))

    def polylines(self):
        """The walls as one closed polyline (5, 2) and each pillar as a closed 128-gon, world frame."""
        w, h = self.size
        box = np.array([[0, 0], [w, 0], [w, h], [0, h], [0, 0]], dtype=np.float64)
        out = [box]
        ang = np.linspace(0.0, 2 * np.pi, 129)
        for cx, cy, r in self.balls:
            out.append(np.column_stack([cx + r * np.cos(ang), cy + r * np.sin(ang)]))
        return [transform2d(self.pose, p) for p in out]


class RoomSDF3D(_Room):
    """Box room ``[0, w] x [0, d] x [0, h]`` with balls inside, placed in the world by ``T``.

    Parameters
    ----------
    size : (w, d, h), default=(4.0, 3.0, 2.5)
        Inner size, metres.
    balls : sequence of (cx, cy, cz, radius), default=((2.5, 1.5, 1.0, 0.4),)
        Balls in the room frame, metres.
    T : (4, 4), default=identity
        Room frame -> world.
    """

    TAGS = Tags(query="query", requires_update=False, data="polar_sim.baselines.examples:room_3d")

    def __init__(self, size=(4.0, 3.0, 2.5), balls=((2.5, 1.5, 1.0, 0.4),), T=None):
        T = np.eye(4) if T is None else as_pose(T, "T")
        self.T = T
        super().__init__(as_float_array(size, "size").reshape(3), balls, T)

    def depth_image(self, T_world_cam, K, shape):
        """Exact planar depth (H, W) in metres seen by a pinhole camera (OpenCV axes) inside the room."""
        T = as_pose(T_world_cam, "T_world_cam")
        K = as_intrinsics(K, "K")
        h, w = shape
        v, u = np.mgrid[0:h, 0:w].astype(np.float64)
        y = (v - K[1, 2]) / K[1, 1]
        x = (u - K[0, 2] - K[0, 1] * y) / K[0, 0]
        rays = np.stack([x.ravel(), y.ravel(), np.ones(x.size)], axis=1)
        # Rays with z = 1 in the camera frame: the distance along them is the planar depth.
        t = self._cast(T[:3, 3], rays @ T[:3, :3].T)
        return t.reshape(h, w)

    def ranges(self, T_world_sensor, directions):
        """Exact ranges (n,) along unit-normalised sensor-frame ``directions`` (n, 3) from a sensor pose."""
        T = as_pose(T_world_sensor, "T_world_sensor")
        d = as_points(directions, 3, "directions")
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        return self._cast(T[:3, 3], d @ T[:3, :3].T)
