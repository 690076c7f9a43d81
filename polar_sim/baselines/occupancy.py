"""Log-odds occupancy grid in the plane, updated scan by scan with exact grid ray traversal."""

from __future__ import annotations

import logging
import math

import numba
import numpy as np
from scipy import ndimage

from polar_sim._validation import (
    as_float_array,
    as_points,
    as_pose2d,
    as_positive_float,
    check_updated,
)
from polar_sim.registration import as_scan2d, as_sensor_offset, beam_points, transform2d, valid_beams
from polar_sim.geometry import compose2d
from polar_sim.params import Parameterised, Tags

__all__ = ["OccupancyGrid2D"]

logger = logging.getLogger(__name__)

_CHUNK = 64  # a growing grid extends by whole chunks of cells, so it reallocates rarely
#: A scan that would grow the grid past this many cells (1.6 GB of float32) is refused first.
MAX_CELLS = 4 * 10**8


@numba.njit(cache=True, nogil=True)
def _update_kernel(L, touched, i0, j0, sx, sy, ex, ey, hit, l_occ, l_free, l_min, l_max):  # pragma: no cover
    """Apply one scan to the log-odds grid ``L`` (all coordinates in cell units).

    Each cell changes at most once per scan, and a cell holding an end point is marked occupied
    even if another ray of the same scan crosses it (OctoMap's rule). ``touched`` covers the cells
    [i0:, j0:] that the scan can reach. Rays are traversed with Amanatides & Woo's DDA, which
    visits exactly the cells the segment crosses.
    """
    nx, ny = L.shape
    n = ex.shape[0]
    for k in range(n):
        if hit[k]:
            ix = int(math.floor(ex[k]))
            iy = int(math.floor(ey[k]))
            if 0 <= ix < nx and 0 <= iy < ny and touched[ix - i0, iy - j0] == 0:
                touched[ix - i0, iy - j0] = 2
                L[ix, iy] = min(max(L[ix, iy] + l_occ, l_min), l_max)
    cx0 = int(math.floor(sx))
    cy0 = int(math.floor(sy))
    for k in range(n):
        dx = ex[k] - sx
        dy = ey[k] - sy
        jx = int(math.floor(ex[k]))
        jy = int(math.floor(ey[k]))
        ix = cx0
        iy = cy0
        stx = 1 if dx > 0 else -1
        sty = 1 if dy > 0 else -1
        if dx != 0.0:
            tmx = ((ix + (1 if dx > 0 else 0)) - sx) / dx
            tdx = abs(1.0 / dx)
        else:
            tmx = np.inf
            tdx = np.inf
        if dy != 0.0:
            tmy = ((iy + (1 if dy > 0 else 0)) - sy) / dy
            tdy = abs(1.0 / dy)
        else:
            tmy = np.inf
            tdy = np.inf
        n_steps = abs(jx - ix) + abs(jy - iy)
        last = n_steps if hit[k] else n_steps + 1  # a no-return ray also clears its last cell
        for s in range(last):
            if 0 <= ix < nx and 0 <= iy < ny and touched[ix - i0, iy - j0] == 0:
                touched[ix - i0, iy - j0] = 1
                L[ix, iy] = min(max(L[ix, iy] + l_free, l_min), l_max)
            if s == n_steps:
                break
            # Step to the next cell; the guards keep round-off from overshooting the end cell.
            if (tmx < tmy and ix != jx) or iy == jy:
                ix += stx
                tmx += tdx
            else:
                iy += sty
                tmy += tdy


def _logit(p):
    return math.log(p / (1.0 - p))


class OccupancyGrid2D(Parameterised):
    """Log-odds occupancy grid (Thrun, Burgard & Fox, ch. 9) with exact ray traversal.

    Each valid beam marks the cell of its end point occupied and every cell it crosses before
    that free; a cell is updated at most once per scan, and occupied wins over free within a scan.
    Log-odds are clamped to ``[logit(p_min), logit(p_max)]`` so the map can still change.

    Parameters
    ----------
    cell_size : float, default=0.05
        Side of a square cell, metres.
    bounds : (xmin, ymin, xmax, ymax) or None, default=None
        Fixed extent in metres. Rays are clipped to it. ``None``: the grid grows to hold every
        scan, on the lattice of multiples of ``cell_size``.
    sensor_offset : (x, y) or (x, y, yaw), default=(0.0, 0.0)
        Sensor mounting in the robot base frame (m, rad), used when ``update`` gets no offset.
    min_range, max_range : float, default=0.0, 30.0
        A beam is a return if ``min_range < r < max_range`` (metres).
    no_return_range : float or None, default=None
        What to do with a beam without return (inf, NaN or a range outside the window): ``None``
        ignores it; a number clears free space along it up to that distance (use the sensor's
        maximum range when "no return" reliably means "nothing within range").
    p_hit, p_miss : float, default=0.7, 0.4
        Inverse sensor model: probability of occupancy after one hit / one pass-through.
    p_min, p_max : float, default=0.12, 0.97
        Clamping probabilities (OctoMap's defaults).
    occupied_threshold, free_threshold : float, default=0.5, 0.5
        A cell is occupied if p > occupied_threshold, free if p < free_threshold, else unknown.

    Attributes
    ----------
    log_odds_ : ndarray of shape (nx, ny), float32
        Log-odds of occupancy, indexed ``[ix, iy]``; 0 is unknown.
    origin_ : ndarray of shape (2,)
        World position (m) of the lower-left corner of cell ``[0, 0]``; cell ``[i, j]`` spans
        ``origin_ + ([i, i+1], [j, j+1]) * cell_size``.
    n_scans_ : int
        Number of scans fused.
    """

    TAGS = Tags(update="update", query="probability", data="polar_sim.baselines.examples:occupancy_grid")

    def __init__(
        self,
        *,
        cell_size: float = 0.05,
        bounds=None,
        sensor_offset=(0.0, 0.0),
        min_range: float = 0.0,
        max_range: float = 30.0,
        no_return_range: float | None = None,
        p_hit: float = 0.7,
        p_miss: float = 0.4,
        p_min: float = 0.12,
        p_max: float = 0.97,
        occupied_threshold: float = 0.5,
        free_threshold: float = 0.5,
    ):
        self.cell_size = cell_size
        self.bounds = bounds
        self.sensor_offset = sensor_offset
        self.min_range = min_range
        self.max_range = max_range
        self.no_return_range = no_return_range
        self.p_hit = p_hit
        self.p_miss = p_miss
        self.p_min = p_min
        self.p_max = p_max
        self.occupied_threshold = occupied_threshold
        self.free_threshold = free_threshold

    # ------------------------------------------------------------------ parameters
    def _params(self):
        cs = as_positive_float(self.cell_size, "cell_size")
        as_positive_float(self.min_range, "min_range", allow_zero=True)
        as_positive_float(self.max_range, "max_range")
        if self.no_return_range is not None:
            as_positive_float(self.no_return_range, "no_return_range")
        for name in ("p_hit", "p_miss", "p_min", "p_max", "occupied_threshold", "free_threshold"):
            p = as_positive_float(getattr(self, name), name)
            if not p < 1.0:
                raise ValueError(f"{name}: expected a probability in (0, 1), got {p!r}")
        if not (self.p_hit > 0.5 > self.p_miss):
            raise ValueError(f"p_hit, p_miss: expected p_hit > 0.5 > p_miss, got {self.p_hit}, {self.p_miss}")
        if not (self.p_min < 0.5 < self.p_max):
            raise ValueError(f"p_min, p_max: expected p_min < 0.5 < p_max, got {self.p_min}, {self.p_max}")
        if self.free_threshold > self.occupied_threshold:
            raise ValueError("free_threshold: must not exceed occupied_threshold")
        if self.bounds is not None:
            b = as_float_array(self.bounds, "bounds")
            if b.shape != (4,) or not np.isfinite(b).all() or not (b[2] - b[0] >= cs and b[3] - b[1] >= cs):
                raise ValueError("bounds: expected finite (xmin, ymin, xmax, ymax) at least one cell wide, "
                                 f"got {self.bounds!r}")
        return cs

    # ------------------------------------------------------------------ update
    def update(self, angles, ranges, pose2d, *, sensor_offset=None):
        """Fuse one planar scan.

        Parameters
        ----------
        angles : ndarray of shape (n,)
            Beam angles in the sensor frame, radians.
        ranges : ndarray of shape (n,)
            Ranges in metres; inf or NaN = no return (see ``no_return_range``); negatives raise.
        pose2d : (x, y, theta)
            Pose of the robot base in the world, m and rad.
        sensor_offset : (x, y) or (x, y, yaw), optional
            Sensor mounting in the base frame; defaults to the ``sensor_offset`` parameter.

        Returns
        -------
        self
        """
        cs = self._params()
        angles, ranges = as_scan2d(angles, ranges)
        pose2d = as_pose2d(pose2d, "pose2d")
        off = as_sensor_offset(self.sensor_offset if sensor_offset is None else sensor_offset)
        hit = valid_beams(ranges, self.min_range, self.max_range)
        use = hit
        if self.no_return_range is not None:
            # No return (NaN, inf or beyond max_range) clears; a too-short range (<= min_range) does not.
            with np.errstate(invalid="ignore"):
                use = hit | ~(ranges <= self.min_range)
        r = np.where(hit, ranges, 0.0 if self.no_return_range is None else float(self.no_return_range))
        if not use.any():
            return self
        sensor = compose2d(pose2d, off)
        ends = transform2d(sensor, beam_points(angles[use], r[use], np.zeros(3)))
        hit = hit[use]

        lo = np.minimum(ends.min(axis=0), sensor[:2])
        hi = np.maximum(ends.max(axis=0), sensor[:2])
        self._check_growth(lo, hi, cs)
        self._ensure_extent(lo, hi, cs)
        g_end = (ends - self.origin_) / cs
        g_src = (sensor[:2] - self.origin_) / cs
        nx, ny = self.log_odds_.shape
        # The window of cells this scan can touch (its bounding box clipped to the grid).
        i0, j0 = (np.floor(np.minimum(g_end.min(axis=0), g_src)).astype(np.int64)).clip(0, [nx - 1, ny - 1])
        i1, j1 = (np.floor(np.maximum(g_end.max(axis=0), g_src)).astype(np.int64) + 1).clip(1, [nx, ny])
        touched = np.zeros((max(i1 - i0, 1), max(j1 - j0, 1)), dtype=np.uint8)
        _update_kernel(
            self.log_odds_, touched, int(i0), int(j0), float(g_src[0]), float(g_src[1]),
            np.ascontiguousarray(g_end[:, 0]), np.ascontiguousarray(g_end[:, 1]), hit,
            np.float32(_logit(self.p_hit)), np.float32(_logit(self.p_miss)),
            np.float32(_logit(self.p_min)), np.float32(_logit(self.p_max)),
        )
        self.n_scans_ += 1
        return self

    def _check_growth(self, lo, hi, cs):
        """Refuse a scan whose box [lo, hi] (m) the growing grid cannot index or hold."""
        if self.bounds is not None:
            return
        if not np.abs(np.concatenate([lo, hi])).max() / cs < 2.0**52:
            raise ValueError(f"pose2d, ranges: the scan lies up to {np.abs(np.concatenate([lo, hi])).max():.3g} m "
                             f"from the origin, beyond what cells of cell_size={cs} m can index")
        cells = np.prod((hi - lo) / cs + 2 * _CHUNK)
        if not cells <= MAX_CELLS:
            raise ValueError(f"pose2d, ranges, cell_size: the scan spans {hi - lo} m; the grid would need "
                             f"{cells:.3g} cells of {cs} m (at most MAX_CELLS = {MAX_CELLS:.0e})")

    def _ensure_extent(self, lo, hi, cs):
        """Create or grow the grid so that it covers the box [lo, hi] (metres)."""
        if self.bounds is not None:
            if not hasattr(self, "log_odds_"):
                b = np.asarray(self.bounds, dtype=np.float64)
                shape = np.ceil((b[2:] - b[:2]) / cs - 1e-9).astype(int)
                self.log_odds_ = np.zeros(tuple(shape), dtype=np.float32)
                self.origin_ = b[:2].copy()
                self.n_scans_ = 0
            return
        want_lo = np.floor(lo / cs).astype(np.int64)
        want_hi = np.floor(hi / cs).astype(np.int64) + 1
        if not hasattr(self, "log_odds_"):
            c_lo = (want_lo // _CHUNK) * _CHUNK
            c_hi = -((-want_hi) // _CHUNK) * _CHUNK
            self.log_odds_ = np.zeros(tuple(c_hi - c_lo), dtype=np.float32)
            self.origin_ = c_lo * cs
            self.n_scans_ = 0
            return
        cur_lo = np.round(self.origin_ / cs).astype(np.int64)
        cur_hi = cur_lo + np.array(self.log_odds_.shape)
        if (want_lo >= cur_lo).all() and (want_hi <= cur_hi).all():
            return
        new_lo = np.minimum(cur_lo, (want_lo // _CHUNK) * _CHUNK)
        new_hi = np.maximum(cur_hi, -((-want_hi) // _CHUNK) * _CHUNK)
        grown = np.zeros(tuple(new_hi - new_lo), dtype=np.float32)
        a = cur_lo - new_lo
        grown[a[0] : a[0] + self.log_odds_.shape[0], a[1] : a[1] + self.log_odds_.shape[1]] = self.log_odds_
        logger.debug("occupancy grid grows from %s to %s cells", self.log_odds_.shape, grown.shape)
        self.log_odds_ = grown
        self.origin_ = new_lo * cs

    # ------------------------------------------------------------------ queries
    @property
    def extent(self):
        """``(xmin, ymin, xmax, ymax)`` of the grid in metres."""
        check_updated(self, "log_odds_")
        hi = self.origin_ + np.array(self.log_odds_.shape) * self.cell_size
        return (float(self.origin_[0]), float(self.origin_[1]), float(hi[0]), float(hi[1]))

    def probability_map(self):
        """Occupancy probability (nx, ny) of every cell, indexed ``[ix, iy]``; 0.5 = unknown."""
        check_updated(self, "log_odds_")
        return 1.0 / (1.0 + np.exp(-self.log_odds_.astype(np.float64)))

    def cell_centers(self):
        """Cell-centre coordinates ``(xs (nx,), ys (ny,))`` in metres."""
        check_updated(self, "log_odds_")
        nx, ny = self.log_odds_.shape
        cs = self.cell_size
        return self.origin_[0] + (np.arange(nx) + 0.5) * cs, self.origin_[1] + (np.arange(ny) + 0.5) * cs

    def probability(self, points):
        """Occupancy probability (n,) of the cells holding world points (n, 2); 0.5 outside the grid."""
        check_updated(self, "log_odds_")
        points = as_points(points, 2, "points", allow_empty=True)
        idx = np.floor((points - self.origin_) / self.cell_size).astype(np.int64)
        nx, ny = self.log_odds_.shape
        inside = (idx[:, 0] >= 0) & (idx[:, 0] < nx) & (idx[:, 1] >= 0) & (idx[:, 1] < ny)
        lo = np.zeros(len(points))
        lo[inside] = self.log_odds_[idx[inside, 0], idx[inside, 1]]
        return 1.0 / (1.0 + np.exp(-lo))

    def occupied_mask(self):
        """Boolean (nx, ny): p > occupied_threshold."""
        check_updated(self, "log_odds_")
        return self.log_odds_ > _logit(self.occupied_threshold)

    def free_mask(self):
        """Boolean (nx, ny): p < free_threshold."""
        check_updated(self, "log_odds_")
        return self.log_odds_ < _logit(self.free_threshold)

    def unknown_mask(self):
        """Boolean (nx, ny): neither occupied nor free."""
        return ~(self.occupied_mask() | self.free_mask())

    def _centres(self, mask):
        ix, iy = np.nonzero(mask)
        return self.origin_ + (np.column_stack([ix, iy]) + 0.5) * self.cell_size

    def occupied_points(self):
        """Centres (m, 2) of the occupied cells, metres."""
        return self._centres(self.occupied_mask())

    def surface_points(self):
        """Centres (m, 2) of the occupied cells that touch a free cell (4-neighbourhood): the seen surface."""
        occ = self.occupied_mask()
        near_free = ndimage.binary_dilation(self.free_mask(), structure=ndimage.generate_binary_structure(2, 1))
        return self._centres(occ & near_free)
