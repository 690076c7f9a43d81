"""Shortest paths on grids: the geodesic distance that scores navigation progress, and the
remembered obstacle grid of the scripted navigator.

The navigator's grid lives in a frame anchored at the goal (origin) with a fixed orientation; it
is filled from surface points and cleared by free-space disks, then planned on optimistically
(unknown cells are free), as in planning for navigation in unknown terrain.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy import ndimage
from skimage.graph import MCP_Geometric

__all__ = ["GeodesicDistance", "ObstacleMemory", "cost_to_go"]


def cost_to_go(cost, gi, gj, until=None):
    """Least cost (H, W) from cell (gi, gj) over an 8-connected grid (``skimage.graph``'s
    ``MCP_Geometric``, Dijkstra's algorithm).

    ``cost`` (H, W) is the traversal cost per cell length (inf = blocked); an edge costs the mean
    of its two cells times its length (1 or sqrt 2, in cells). Unreachable cells are inf. With
    ``until`` = (i, j) the search stops once that cell's cost is final: every cell cheaper than it
    is then final too, and the cells not yet reached are inf.
    """
    mcp = MCP_Geometric(np.asarray(cost, dtype=np.float64), fully_connected=True)
    dist, _ = mcp.find_costs([(int(gi), int(gj))], ends=None if until is None else [tuple(int(v) for v in until)])
    return dist


class ObstacleMemory:
    """Obstacle evidence on a square grid centred on the origin.

    Parameters
    ----------
    half : float
        Half the side of the grid, m.
    cell : float
        Cell size, m.
    inflate : float
        Obstacles are grown by this radius (m) for planning: the robot's half-width plus a margin.
    clearance : float
        Cells nearer than this to an obstacle (m), beyond the inflation, cost up to
        ``1 + clearance_weight`` instead of 1, so paths keep to the middle of doorways.
    """

    def __init__(self, half=18.0, cell=0.2, inflate=0.45, clearance=0.8, clearance_weight=3.0):
        self.cell = float(cell)
        self.n = int(np.ceil(2 * half / cell))
        self.half = self.n * self.cell / 2
        self.inflate = float(inflate)
        self.clearance = float(clearance)
        self.clearance_weight = float(clearance_weight)
        self.hits = np.zeros((self.n, self.n), np.int8)

    def index(self, xy):
        """Cell indices (row = y, col = x) of points (n, 2); clipped to the grid."""
        ij = np.floor((np.asarray(xy, float)[:, ::-1] + self.half) / self.cell).astype(np.int64)
        return np.clip(ij, 0, self.n - 1)

    def centre(self, ij):
        """Cell centres (n, 2) as (x, y), m."""
        return (np.asarray(ij, float)[:, ::-1] + 0.5) * self.cell - self.half

    def add(self, surface_xy, free_xy, free_radius):
        """Clear the disks around ``free_xy`` (n, 2) of radius ``free_radius`` (n,) m (known free
        space), then mark the cells of ``surface_xy`` (m, 2) as obstacle."""
        if len(free_xy):
            r = int(np.ceil(free_radius.max() / self.cell))
            o = np.arange(-r, r + 1)
            oi, oj = np.meshgrid(o, o, indexing="ij")
            off = np.c_[oi.ravel(), oj.ravel()]
            dist = np.hypot(off[:, 0], off[:, 1]) * self.cell
            centres = self.index(free_xy)
            for c, rad in zip(centres, free_radius):
                k = off[dist <= rad] + c
                k = k[(k >= 0).all(1) & (k < self.n).all(1)]
                self.hits[k[:, 0], k[:, 1]] = 0
        if len(surface_xy):
            ij = self.index(surface_xy)
            self.hits[ij[:, 0], ij[:, 1]] = np.minimum(self.hits[ij[:, 0], ij[:, 1]] + 1, 3)

    def cost(self, inflate=None):
        """Per-cell traversal cost (n, n): inf within ``inflate`` m (default: the memory's) of an
        obstacle cell."""
        inflate = self.inflate if inflate is None else float(inflate)
        occupied = self.hits > 0
        if not occupied.any():
            return np.ones((self.n, self.n))
        edt = ndimage.distance_transform_edt(~occupied) * self.cell
        c = 1.0 + self.clearance_weight * np.clip((inflate + self.clearance - edt) / self.clearance, 0, 1)
        c[edt <= inflate] = np.inf
        return c


class GeodesicDistance:
    """The shortest-path distance (m) to a goal around the obstacles of an occupancy grid.

    Parameters
    ----------
    occupancy : (ny, nx) bool
        Cells the robot cannot enter (obstacles inflated by its radius); row i is y, column j is x.
    origin : (2,) float
        World (x, y) of the grid's lower-left corner, m.
    res : float
        Cell size, m.
    goal : (2,) float
        World (x, y) of the goal, m.
    """

    def __init__(self, occupancy, origin, res, goal):
        occupancy = np.asarray(occupancy, bool)
        self.origin = np.asarray(origin, float)
        self.res = float(res)
        self.shape = occupancy.shape
        cost = np.where(occupancy, np.inf, 1.0)
        gi, gj = self._cell(goal)
        cost[gi, gj] = 1.0
        self.dist = cost_to_go(cost, gi, gj) * self.res
        self._nearest = None  # (rows, cols) of the nearest reachable cell, made when first needed

    def _cell(self, xy):
        j, i = np.floor((np.asarray(xy, float)[:2] - self.origin) / self.res).astype(int)
        return int(np.clip(i, 0, self.shape[0] - 1)), int(np.clip(j, 0, self.shape[1] - 1))

    def __call__(self, xy):
        """Distance (m) from the world point ``xy`` (2,): the least, over the reachable cells of
        its 3x3 neighbourhood, of the cell's path length plus the straight line to its centre
        (continuous in ``xy``, so its decrease is a smooth progress signal). A point with no
        reachable cell around it (a robot brushing a wall stands in the inflation) goes by the
        nearest reachable cell."""
        x, y = float(xy[0]), float(xy[1])
        best = _geodesic_at(x, y, self.origin[0], self.origin[1], self.res, self.dist)
        if np.isfinite(best):
            return best
        if self._nearest is None:
            _, self._nearest = ndimage.distance_transform_edt(~np.isfinite(self.dist), return_indices=True)
        i, j = self._cell(xy)
        a, b = int(self._nearest[0][i, j]), int(self._nearest[1][i, j])
        ox, oy, res = self.origin[0], self.origin[1], self.res
        return self.dist[a, b] + np.hypot(x - (ox + res * (b + 0.5)), y - (oy + res * (a + 0.5)))


@numba.njit(cache=True, nogil=True)
def _geodesic_at(x, y, ox, oy, res, dist):
    """The 3x3-neighbourhood part of :meth:`GeodesicDistance.__call__` at (x, y), m; inf if no
    cell there is reachable (numba's ``hypot`` is numpy's)."""
    H, W = dist.shape
    i = min(max(int(np.floor((y - oy) / res)), 0), H - 1)
    j = min(max(int(np.floor((x - ox) / res)), 0), W - 1)
    best = np.inf
    for a in range(max(i - 1, 0), min(i + 2, H)):
        for b in range(max(j - 1, 0), min(j + 2, W)):
            d = dist[a, b]
            if np.isfinite(d):
                best = min(best, d + np.hypot(x - (ox + res * (b + 0.5)), y - (oy + res * (a + 0.5))))
    return best
