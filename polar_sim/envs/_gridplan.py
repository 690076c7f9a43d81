"""A small remembered obstacle grid and shortest-path cost-to-go, for the scripted navigator.

The grid lives in a frame anchored at the goal (origin) with a fixed orientation; it is filled
from surface points and cleared by free-space disks, then planned on optimistically (unknown
cells are free), as in planning for navigation in unknown terrain.
"""

from __future__ import annotations

import heapq

import numba
import numpy as np
from scipy import ndimage

__all__ = ["ObstacleMemory", "cost_to_go"]


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
