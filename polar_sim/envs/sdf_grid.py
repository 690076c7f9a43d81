"""The egocentric SDF image of ``GPISNav`` (``obs_mode="grid"``) and its visited mask."""

from __future__ import annotations

import numpy as np

__all__ = ["SDFGrid", "VisitedMask", "GRID_SDF_BOUND", "GRID_VAR_MAX"]

GRID_SDF_BOUND = 4.0  # m: the image's distance channel is clipped to +-4 m
GRID_VAR_MAX = 2.0  # the variance channel is clipped to [0, 2] (the GPIS map's prior is about 1)
MAX_GRID_SIZE = 256  # cells per side of the grid image
MAX_GRID_RESOLUTION = 10.0  # m per cell


class SDFGrid:
    """A ``size`` x ``size`` image of cells of ``resolution`` m centred on the robot, aligned with
    it: row 0 is farthest ahead (robot +x), column 0 farthest to the left (robot +y), so the robot
    looks up the image. ``points_robot`` (size * size, 2) are the cell centres in the robot frame,
    row-major."""

    def __init__(self, size=32, resolution=0.25):
        self.size, self.resolution = self.check(size, resolution)
        off = (self.size / 2 - 0.5 - np.arange(self.size)) * self.resolution
        X, Y = np.meshgrid(off, off, indexing="ij")
        self.points_robot = np.stack([X.ravel(), Y.ravel()], 1)

    @staticmethod
    def check(size, resolution):
        """(size, resolution) checked: an integer in 4..:data:`MAX_GRID_SIZE` cells and a number of
        metres in (0, :data:`MAX_GRID_RESOLUTION`]."""
        from polar_sim._validation import as_float, as_int

        return (as_int(size, "grid_size", minimum=4, maximum=MAX_GRID_SIZE),
                as_float(resolution, "grid_resolution", minimum=0.0, exclusive_minimum=True,
                         maximum=MAX_GRID_RESOLUTION))

    def world_points(self, pose2d):
        """Cell centres (size * size, 2) in the map frame for a robot pose (x, y, theta)."""
        from polar_sim.envs.observers import robot_to_world

        return robot_to_world(pose2d, self.points_robot)

    def image(self, d, v, visited=None):
        """(C, size, size) float32: distance (m, clipped to +-4), variance (clipped to [0, 2];
        inf/NaN where the map has nothing = 2) and, if given, the visited mask (0/1)."""
        n = self.size
        chans = [np.clip(np.nan_to_num(d, nan=GRID_SDF_BOUND), -GRID_SDF_BOUND, GRID_SDF_BOUND),
                 np.clip(np.nan_to_num(v, nan=GRID_VAR_MAX, posinf=GRID_VAR_MAX), 0.0, GRID_VAR_MAX)]
        if visited is not None:
            chans.append(visited.astype(np.float64))
        return np.stack([c.reshape(n, n) for c in chans]).astype(np.float32)


class VisitedMask:
    """Where the robot has been, by its own estimate: the cells of ``resolution`` m in the map frame
    that a disk of ``radius`` m around an estimated robot position touches, over a square of half side ``extent`` m
    around the map origin (positions beyond it are not marked)."""

    def __init__(self, extent, resolution=0.25, radius=0.3):
        self.res = float(resolution)
        self.half = float(extent)
        self.n = int(np.ceil(2 * self.half / self.res))
        self.radius = float(radius)
        r = int(np.ceil(radius / self.res)) + 1
        di, dj = np.mgrid[-r : r + 1, -r : r + 1]
        self._window = np.stack([di.ravel(), dj.ravel()], 1)
        self.reset()

    def reset(self):
        self.mask = np.zeros((self.n, self.n), bool)

    def _index(self, xy):
        return np.floor((np.asarray(xy, float) + self.half) / self.res).astype(np.int64)

    def add(self, xy):
        """Mark every cell that the disk around a position (2,) in the map frame (m) touches."""
        xy = np.asarray(xy, float)
        ij = self._index(xy[None])[0] + self._window
        lo = ij * self.res - self.half  # the cells' lower corners
        gap = np.maximum(np.maximum(lo - xy, xy - (lo + self.res)), 0.0)  # point-to-box distance
        ij = ij[np.hypot(gap[:, 0], gap[:, 1]) <= self.radius]
        ok = ((ij >= 0) & (ij < self.n)).all(1)
        self.mask[ij[ok, 0], ij[ok, 1]] = True

    def sample(self, points):
        """Visited (n,) bool at points (n, 2) in the map frame (False outside the mask)."""
        ij = self._index(points)
        ok = ((ij >= 0) & (ij < self.n)).all(1)
        out = np.zeros(len(points), bool)
        out[ok] = self.mask[ij[ok, 0], ij[ok, 1]]
        return out
