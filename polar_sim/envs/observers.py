"""Module adapters shared by the environments and their module wrappers.

An adapter turns raw sensor data into a module's observation, so the same code serves a
registered environment (``GPISNav-v0`` holds one internally) and a wrapper around a raw
environment (``GPISObservation(LidarNav-v0)``). Users swap in their own module by passing any
object with the same small interface.
"""

from __future__ import annotations

import numpy as np

from polar_sim.geometry import compose2d

__all__ = ["SDFStencil", "GPISSource", "TruthSource", "OccupancyEDTSource", "make_sdf_source", "SDF_SOURCES"]


class SDFStencil:
    """A robot-centred polar stencil: ``n_rays`` directions x ``radii`` distances.

    ``points_robot`` (n, 2) are in the robot frame (x forward, y left), metres, ordered
    ray-major (all radii of ray 0, then ray 1, ...).
    """

    def __init__(self, n_rays=16, radii=(0.5, 1.0, 2.0, 3.0)):
        self.n_rays = int(n_rays)
        self.radii = np.asarray(radii, dtype=np.float64)
        if self.n_rays < 1 or self.radii.ndim != 1 or len(self.radii) < 1 or np.any(self.radii <= 0):
            raise ValueError(f"stencil: expected n_rays >= 1 and positive radii, got {n_rays}, {radii}")
        ang = np.linspace(-np.pi, np.pi, self.n_rays, endpoint=False)
        A, R = np.meshgrid(ang, self.radii, indexing="ij")
        self.points_robot = np.stack([R * np.cos(A), R * np.sin(A)], -1).reshape(-1, 2)

    @property
    def size(self):
        return len(self.points_robot)

    def world_points(self, pose2d):
        """Stencil points (n, 2) in the world for a robot pose (x, y, theta)."""
        pts = np.c_[self.points_robot, np.zeros(self.size)]
        return compose2d(np.asarray(pose2d, float), pts)[:, :2]


class GPISSource:
    """The online GPIS map (default mode: faithful distance) as an SDF source."""

    name = "gpis"

    def __init__(self, **params):
        from polar_sim.gpis import GPISMap2D

        params.setdefault("sensor_offset", (0.0, 0.0))  # the env passes the sensor's own pose
        self.map = GPISMap2D(**params)

    def reset(self):
        self.map.reset()

    def update(self, angles, ranges, sensor_pose2d):
        self.map.update(angles, ranges, sensor_pose2d)

    def query(self, points):
        """(sdf (n,), grad (n, 2), var (n,)); before any data: distance 0, no gradient, var inf."""
        if getattr(self.map, "n_updates_", 0) == 0:
            return np.zeros(len(points)), np.zeros((len(points), 2)), np.full(len(points), np.inf)
        return self.map.query(points)


class OccupancyEDTSource:
    """A log-odds occupancy grid and the signed EDT of it (the grid baseline) as an SDF source."""

    name = "occupancy_edt"

    def __init__(self, cell_size=0.05, max_range=30.0):
        from polar_sim.baselines import OccupancyGrid2D

        self.grid = OccupancyGrid2D(cell_size=cell_size, max_range=max_range)
        self._sdf = None

    def reset(self):
        self.grid.reset()
        self._sdf = None

    def update(self, angles, ranges, sensor_pose2d):
        self.grid.update(angles, ranges, sensor_pose2d, sensor_offset=(0.0, 0.0))
        self._sdf = None

    def query(self, points):
        from polar_sim.baselines import DiscreteSDF2D

        if getattr(self.grid, "n_scans_", 0) == 0:
            return np.zeros(len(points)), np.zeros((len(points), 2)), np.full(len(points), np.inf)
        if self._sdf is None:
            self._sdf = DiscreteSDF2D.from_grid(self.grid)
        out = self._sdf.query(points)
        d, g = out[0], out[1]
        v = out[2] if len(out) > 2 else np.zeros(len(points))
        return d, g, v


class TruthSource:
    """The exact SDF of the scene in the lidar plane (``World.sdf``): the perfect map.

    The gradient is a central difference of the exact field (step 1 mm); the variance is 0.
    """

    name = "truth"

    def __init__(self, world=None):
        self.world = world

    def reset(self):
        pass

    def update(self, angles, ranges, sensor_pose2d):
        pass

    def query(self, points):
        h = 1e-3
        f = self.world.sdf
        d = f(points)
        gx = (f(points + [h, 0]) - f(points - [h, 0])) / (2 * h)
        gy = (f(points + [0, h]) - f(points - [0, h])) / (2 * h)
        return d, np.stack([gx, gy], 1), np.zeros(len(points))


SDF_SOURCES = ("gpis", "truth", "occupancy_edt")


def make_sdf_source(source, **params):
    """An SDF source by name (see :data:`SDF_SOURCES`), or ``source`` itself if it is an object
    with ``reset()``, ``update(angles, ranges, sensor_pose2d)`` and ``query(points)``."""
    if not isinstance(source, str):
        for m in ("reset", "update", "query"):
            if not callable(getattr(source, m, None)):
                raise TypeError(f"sdf_source: a custom source needs a {m}() method; got {type(source).__name__}")
        return source
    if source == "gpis":
        return GPISSource(**params)
    if source == "truth":
        return TruthSource()
    if source == "occupancy_edt":
        return OccupancyEDTSource(**params)
    raise ValueError(f"sdf_source: unknown source {source!r}; expected one of {', '.join(SDF_SOURCES)} or an object")
