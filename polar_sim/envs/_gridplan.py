"""Shortest paths on grids: the geodesic distance that scores navigation progress, and the
remembered obstacle grid of the scripted navigator.

The navigator's grid lives in a frame anchored at the goal (origin) with a fixed orientation; it
is filled from surface points and cleared by free-space disks, then planned on optimistically
(unknown cells are free), as in planning for navigation in unknown terrain.
"""

from __future__ import annotations

import heapq

import numba
import numpy as np
from scipy import ndimage

__all__ = ["GeodesicDistance", "ObstacleMemory", "cost_to_go"]


@numba.njit(cache=True, nogil=True)
def cost_to_go(cost, gi, gj):
    """Dijkstra on an 8-connected grid from cell (gi, gj).

    ``cost`` (H, W) is the traversal cost per cell length (inf = blocked); an edge costs the mean
    of its two cells times its length (1 or sqrt 2, in cells). Returns (H, W) costs, inf where
    unreachable.
    """
    H, W = cost.shape
    dist = np.full((H, W), np.inf)
    dist[gi, gj] = 0.0
    heap = [(0.0, gi, gj)]
    while len(heap):
        d, i, j = heapq.heappop(heap)
        if d > dist[i, j]:
            continue
        for di in range(-1, 2):
            for dj in range(-1, 2):
                if di == 0 and dj == 0:
                    continue
                ni, nj = i + di, j + dj
                if ni < 0 or nj < 0 or ni >= H or nj >= W or not np.isfinite(cost[ni, nj]):
                    continue
                step = 1.4142135623730951 if di != 0 and dj != 0 else 1.0
                nd = d + 0.5 * (cost[i, j] + cost[ni, nj]) * step
                if nd < dist[ni, nj]:
                    dist[ni, nj] = nd
                    heapq.heappush(heap, (nd, ni, nj))
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
        # For points off the reachable cells (a robot brushing a wall stands in the inflation):
        # the nearest reachable cell.
        reach = np.isfinite(self.dist)
        _, (self._ni, self._nj) = ndimage.distance_transform_edt(~reach, return_indices=True)

    def _cell(self, xy):
        j, i = np.floor((np.asarray(xy, float) - self.origin) / self.res).astype(int)
        return int(np.clip(i, 0, self.shape[0] - 1)), int(np.clip(j, 0, self.shape[1] - 1))

    def __call__(self, xy):
        """Distance (m) from the world point ``xy`` (2,): the least, over the reachable cells of
        its 3x3 neighbourhood, of the cell's path length plus the straight line to its centre
        (continuous in ``xy``, so its decrease is a smooth progress signal)."""
        xy = np.asarray(xy, float)
        i, j = self._cell(xy)
        best = np.inf
        for a in range(max(i - 1, 0), min(i + 2, self.shape[0])):
            for b in range(max(j - 1, 0), min(j + 2, self.shape[1])):
                d = self.dist[a, b]
                if np.isfinite(d):
                    c = self.origin + self.res * (np.array([b, a]) + 0.5)
                    best = min(best, d + float(np.hypot(*(xy - c))))
        if not np.isfinite(best):
            a, b = self._ni[i, j], self._nj[i, j]
            c = self.origin + self.res * (np.array([b, a]) + 0.5)
            best = self.dist[a, b] + float(np.hypot(*(xy - c)))
        return best
