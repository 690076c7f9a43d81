"""Likelihood field of an occupancy grid (Thrun, Burgard & Fox, "Probabilistic Robotics", 6.4)."""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from polar_sim._validation import as_points, as_positive_float, check_updated
from polar_sim.params import Parameterised, Tags

__all__ = ["LikelihoodField"]


class LikelihoodField(Parameterised):
    """Precomputed per-cell log-likelihood of a beam end point.

    ``p(z | x, m) = z_hit * N(dist; 0, sigma_hit**2) + z_rand / max_range``, where ``dist`` is the
    distance from the end point to the nearest occupied cell centre (clipped at ``max_distance``).
    Beams without a return are not scored (Thrun's likelihood field skips max-range readings), so
    there is no ``z_max`` term. End points outside the grid score as if ``dist = max_distance``.

    Parameters
    ----------
    sigma_hit : float, default=0.2
        Standard deviation of the hit Gaussian, metres (AMCL's default).
    z_hit, z_rand : float, default=0.95, 0.05
        Mixture weights of the hit and random components.
    max_range : float, default=30.0
        Sensor maximum range (m): the random component is uniform on [0, max_range].
    max_distance : float, default=2.0
        Distances are clipped here (m); beyond a few sigma_hit the Gaussian is negligible anyway.

    Attributes
    ----------
    log_field_ : ndarray of shape (nx, ny), float32
        Log-likelihood of an end point in each cell.
    distance_ : ndarray of shape (nx, ny), float32
        Distance from each cell centre to the nearest occupied cell centre, metres.
    origin_ : ndarray of shape (2,)
        Lower-left corner of cell [0, 0], metres (the grid's).
    cell_size_ : float
        Cell side, metres.
    """

    TAGS = Tags(update="fit", query="log_likelihood", data="polar_sim.baselines.examples:likelihood_field")

    def __init__(
        self,
        *,
        sigma_hit: float = 0.2,
        z_hit: float = 0.95,
        z_rand: float = 0.05,
        max_range: float = 30.0,
        max_distance: float = 2.0,
    ):
        self.sigma_hit = sigma_hit
        self.z_hit = z_hit
        self.z_rand = z_rand
        self.max_range = max_range
        self.max_distance = max_distance

    def _log_p(self, dist):
        s = self.sigma_hit
        with np.errstate(over="ignore", divide="ignore"):   # far from walls g underflows to 0: no error
            g = np.exp(-0.5 * (np.asarray(dist, np.float64) / s) ** 2) / (math.sqrt(2 * math.pi) * s)
            return np.log(self.z_hit * g + self.z_rand / self.max_range)

    def fit(self, grid):
        """Precompute the field of an :class:`~polar_sim.baselines.OccupancyGrid2D`. Returns ``self``."""
        as_positive_float(self.sigma_hit, "sigma_hit")
        as_positive_float(self.z_hit, "z_hit", allow_zero=True)
        as_positive_float(self.z_rand, "z_rand", allow_zero=True)
        as_positive_float(self.max_range, "max_range")
        as_positive_float(self.max_distance, "max_distance")
        if self.z_hit + self.z_rand <= 0:
            raise ValueError("z_hit, z_rand: at least one must be positive")
        if not hasattr(grid, "occupied_mask"):
            raise TypeError(f"grid: expected an OccupancyGrid2D, got {type(grid).__name__}")
        check_updated(grid, "log_odds_")
        occ = grid.occupied_mask()
        if not occ.any():
            raise ValueError("grid: has no occupied cell, the likelihood field is undefined")
        cs = float(grid.cell_size)
        dist = np.minimum(ndimage.distance_transform_edt(~occ) * cs, self.max_distance)
        self.distance_ = dist.astype(np.float32)
        self.log_field_ = self._log_p(dist).astype(np.float32)
        self.origin_ = np.array(grid.origin_, dtype=np.float64)
        self.cell_size_ = cs
        self.log_outside_ = float(self._log_p(self.max_distance))
        # A one-cell border holding the outside value lets lookups clip instead of masking.
        self._log_pad_ = np.pad(self.log_field_, 1, constant_values=np.float32(self.log_outside_))
        return self

    def log_likelihood(self, points):
        """Log-likelihood (n,) of beam end points at world positions (n, 2)."""
        check_updated(self, "log_field_")
        p = as_points(points, 2, "points", allow_empty=True)
        return self._lookup(p[:, 0], p[:, 1]).astype(np.float64)

    def _lookup(self, x, y):
        """Unchecked nearest-cell lookup for arrays ``x``, ``y`` of any (equal) shape (float32 out)."""
        inv = 1.0 / self.cell_size_
        nx, ny = self.log_field_.shape
        fx = (x - self.origin_[0]) * inv + 1.0  # +1: index into the padded field
        fy = (y - self.origin_[1]) * inv + 1.0
        np.clip(fx, 0.0, nx + 1, out=fx)  # past the edges: the border cell (outside value)
        np.clip(fy, 0.0, ny + 1, out=fy)
        lin = fx.astype(np.intp) * (ny + 2) + fy.astype(np.intp)  # truncation = floor, all >= 0
        return np.take(self._log_pad_, lin)
