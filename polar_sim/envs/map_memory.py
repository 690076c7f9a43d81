"""The remembered map of a learned GPISNav policy: a goal-anchored grid of obstacle, known-free and
visited cells built from the observation alone, read as egocentric crops (numpy only).

This is the memory :class:`~polar_sim.envs.policies.SDFNavigator` plans on (the same grid,
:class:`~polar_sim.envs._gridplan.ObstacleMemory`, filled from the same stencil evidence in the
same goal-anchored frame), plus what a learner needs to read it without planning: which cells are
known free, which cells the robot has been in, and where the goal lies. It is part of the
policy's state (``reset()`` clears it), not of the environment.
"""

from __future__ import annotations

import numpy as np

from polar_sim._validation import as_float, as_int
from polar_sim.envs._gridplan import ObstacleMemory

__all__ = ["MapMemory", "MAP_CHANNELS", "DEFAULT_SCALES"]

#: The channels of each crop, in order.
MAP_CHANNELS = ("obstacle", "free", "visited", "goal")
#: The default crops: (cells per side, cell size m): a fine 4.8 m view and a coarse 19.2 m one.
DEFAULT_SCALES = ((16, 0.3), (16, 1.2))


class MapMemory(ObstacleMemory):
    """Obstacle, known-free and visited cells in the goal-anchored frame of ``SDFNavigator``.

    Every :meth:`update` reads one GPISNav observation (``goal``, ``pose``, ``sdf``, ``sdf_grad``,
    ``sdf_var``; stencil ``points`` in the robot frame): the goal vector fixes the robot's position
    relative to the goal (the origin), the estimated pose's heading the grid's orientation. As in
    ``SDFNavigator``, each known stencil point p (variance below ``max_var``) with distance d and
    gradient g marks the surface estimate s = p - d g as obstacle (if d < 1.5 m and |g| > 0.3),
    and, if d > 0.25 m, clears the disk of radius min(d, 3) - 0.15 m around p, which the SDF says
    is free (those cells become known free). The robot's own cell becomes visited.

    :meth:`crops` reads the grid as egocentric images, the robot at the centre looking up.

    Parameters
    ----------
    points : ndarray of shape (n, 2)
        The stencil points in the robot frame, m (``SDFStencil.points_robot``).
    half : float, default=18.0
        Half the side of the grid, m (``SDFNavigator``'s: it covers every GPISNav world).
    cell : float, default=0.2
        Grid cell, m.
    max_var : float, default=0.5
        Stencil points with a map variance at or above this are unknown space.
    scales : sequence of (int, float), default=DEFAULT_SCALES
        The crops: cells per side (even) and cell size (m, at least ``cell``).
    """

    def __init__(self, points, half=18.0, cell=0.2, max_var=0.5, scales=DEFAULT_SCALES):
        points = np.asarray(points, np.float64)
        if points.ndim != 2 or points.shape[1] != 2 or not len(points) or not np.isfinite(points).all():
            raise ValueError(f"points: expected finite stencil points of shape (n, 2), got {points.shape}")
        half = as_float(half, "half", minimum=1.0, maximum=1000.0)
        cell = as_float(cell, "cell", minimum=0.01, maximum=half, exclusive_minimum=True)
        self.max_var = as_float(max_var, "max_var", minimum=0.0, exclusive_minimum=True)
        if not isinstance(scales, (tuple, list)) or not scales:
            raise ValueError(f"scales: expected a non-empty sequence of (cells, cell size m), got {scales!r}")
        checked = []
        for sc in scales:
            if not isinstance(sc, (tuple, list)) or len(sc) != 2:
                raise ValueError(f"scales: expected (cells, cell size m) pairs, got {sc!r}")
            n = as_int(sc[0], "scales", minimum=2, maximum=256)
            if n % 2:
                raise ValueError(f"scales: cells per side must be even (the robot at a corner of the centre cells), "
                                 f"got {n}")
            checked.append((n, as_float(sc[1], "scales", minimum=cell, maximum=2 * half)))
        super().__init__(half, cell)
        self.points = points
        self.scales = tuple(checked)
        self._offsets = [self._sample_offsets(n, r) for n, r in self.scales]
        self.reset()

    def _sample_offsets(self, n, res):
        """Robot-frame sample points (n, n, k*k, 2) of an n x n crop of ``res`` m cells, k x k per cell
        (k the cells of the grid a crop cell spans, rounded up); row 0 ahead, column 0 to the left."""
        k = int(np.ceil(res / self.cell - 1e-9))
        sub = (np.arange(k) + 0.5) / k
        centres = (np.arange(n)[:, None] + sub[None, :]).reshape(-1) * res - n * res / 2  # (n k,)
        ahead = -centres  # row 0 is the farthest ahead
        left = -centres   # column 0 is the farthest to the left
        x = np.broadcast_to(ahead[:, None], (n * k, n * k))
        y = np.broadcast_to(left[None, :], (n * k, n * k))
        xy = np.stack([x, y], -1).reshape(n, k, n, k, 2).transpose(0, 2, 1, 3, 4).reshape(n, n, k * k, 2)
        return xy

    def reset(self):
        """Forget everything: no obstacle, no known free cell, nothing visited."""
        self.hits = np.zeros((self.n, self.n), np.int8)
        self.free = np.zeros((self.n, self.n), bool)
        self.visited = np.zeros((self.n, self.n), bool)
        self.position = np.zeros(2)
        self.heading = 0.0

    def update(self, obs):
        """Add one observation's evidence (see the class docstring); returns the robot's position
        (2,) in the goal-anchored frame, m."""
        try:
            goal = np.asarray(obs["goal"], np.float64).reshape(2)
            theta = float(np.asarray(obs["pose"], np.float64).reshape(-1)[2])
            d = np.asarray(obs["sdf"], np.float64).reshape(-1)
            g = np.asarray(obs["sdf_grad"], np.float64).reshape(-1, 2)
            var = np.asarray(obs["sdf_var"], np.float64).reshape(-1)
        except KeyError as exc:
            raise ValueError(f"obs: the map memory reads goal, pose, sdf, sdf_grad and sdf_var; {exc} is missing") \
                from None
        if not (len(d) == len(g) == len(var) == len(self.points)):
            raise ValueError(f"obs: the map memory was made for a stencil of {len(self.points)} points, the "
                             f"observation has {len(d)}")
        c, sn = np.cos(theta), np.sin(theta)
        R = np.array([[c, -sn], [sn, c]])
        p = -R @ goal
        known = var < self.max_var
        norm = np.linalg.norm(g, axis=1)
        surf = known & (d < 1.5) & (norm > 0.3)
        s = self.points[surf] - d[surf, None] * (g[surf] / norm[surf, None])
        free = known & (d > 0.25)
        self._mark(p + s @ R.T, p + self.points[free] @ R.T, np.minimum(d[free], 3.0) - 0.15)
        here = self.index(p[None])[0]
        self.visited[here[0], here[1]] = True
        self.position, self.heading = p, theta
        return p

    def _mark(self, surface_xy, free_xy, free_radius):
        """``ObstacleMemory.add`` that also records the cleared cells as known free."""
        if len(free_xy):
            r = int(np.ceil(max(free_radius.max(), 0.0) / self.cell))
            o = np.arange(-r, r + 1)
            oi, oj = np.meshgrid(o, o, indexing="ij")
            off = np.c_[oi.ravel(), oj.ravel()]
            dist = np.hypot(off[:, 0], off[:, 1]) * self.cell
            centres = self.index(free_xy)
            cells = [off[dist <= rad] + ctr for ctr, rad in zip(centres, free_radius)]
            k = np.concatenate(cells)
            k = k[(k >= 0).all(1) & (k < self.n).all(1)]
            self.hits[k[:, 0], k[:, 1]] = 0
            self.free[k[:, 0], k[:, 1]] = True
        if len(surface_xy):
            ij = self.index(surface_xy)
            self.hits[ij[:, 0], ij[:, 1]] = np.minimum(self.hits[ij[:, 0], ij[:, 1]] + 1, 3)
            self.free[ij[:, 0], ij[:, 1]] = False

    def crops(self):
        """The egocentric images of the map, float32 (len(scales) * 4, n, n): per scale, the
        fraction of each crop cell's grid cells that are obstacle, known free and visited, and a
        goal channel (1 in the crop cell holding the goal or, if it lies outside the crop, in the
        border cell toward it). The robot is at the centre, heading up (row 0 ahead, column 0 to
        its left); grid cells outside the grid read 0."""
        c, sn = np.cos(self.heading), np.sin(self.heading)
        R = np.array([[c, -sn], [sn, c]])
        occupied = self.hits > 0
        goal_robot = R.T @ (-self.position)
        out = []
        for (n, res), off in zip(self.scales, self._offsets):
            xy = off.reshape(-1, 2) @ R.T + self.position
            ij = np.floor((xy[:, ::-1] + self.half) / self.cell).astype(np.int64)
            inside = ((ij >= 0) & (ij < self.n)).all(1)
            ij = np.clip(ij, 0, self.n - 1)
            chans = [np.where(inside, layer[ij[:, 0], ij[:, 1]], False).reshape(n, n, -1).mean(-1)
                     for layer in (occupied, self.free, self.visited)]
            goal = np.zeros((n, n))
            # Row from the distance ahead, column from the distance to the left, clipped to the border.
            row = int(np.clip(np.floor(n / 2 - goal_robot[0] / res), 0, n - 1))
            col = int(np.clip(np.floor(n / 2 - goal_robot[1] / res), 0, n - 1))
            goal[row, col] = 1.0
            out += chans + [goal]
        return np.asarray(out, np.float32)
