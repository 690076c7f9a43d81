"""Signed Euclidean distance transform of an occupancy grid (2D) or voxel grid (3D).

Sign convention
---------------
Cells are split into *inside* (occupied, plus the unknown cells chosen by ``unknown``) and
*outside* (everything else, which includes all known free cells). The zero level set runs through
the centres of the inside cells that touch the outside, because an occupied cell of a range-sensor
grid is one that holds a measured surface point, and the surface passes on average through its
centre. So, with ``D(c, S)`` the distance between cell centres and the nearest cell of set S,

- an outside cell has ``sdf = +D(c, inside)``  (at least one cell size: positive in free space);
- an inside cell has ``sdf = -(D(c, outside) - cell_size)`` (0 on the surface, negative behind it).

Between cell centres the field is interpolated bilinearly (2D) or trilinearly (3D). The gradient
is the central-difference gradient of the cell values (``numpy.gradient``), interpolated the same
way: its direction is about twice as accurate as the derivative of the interpolant, which jumps
at every cell line. Both slopes across the surface are 1, so the interpolated field is a distance
at the scale of a cell. For a *solid* voxelisation (every
voxel whose centre is inside an object is occupied) the zero level lies on average half a voxel
inside the true surface.

``unknown`` says where the unknown cells go:

- ``"enclosed"`` (default): unknown cells that cannot be reached from a known free cell without
  passing next to an occupied cell are inside (behind the walls, inside objects); unknown cells
  connected to free space through an opening at least two cells wide (beyond a frontier) are
  outside. This matches the GPIS sign (negative behind the surface) without putting a surface at
  every frontier, and it tolerates the one-cell gaps that grazing rays leave in grid walls. Known
  free cells are always outside, even the few that grazing rays mark free just behind a wall.
- ``"free"``: all unknown cells are outside (only occupied cells are inside).
- ``"occupied"``: all unknown cells are inside (frontiers become surfaces).
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy import ndimage

from polar_sim._validation import as_float_array, as_points, as_positive_float, check_choice, check_updated
from polar_sim.params import Parameterised, Tags

__all__ = ["DiscreteSDF2D", "DiscreteSDF3D"]

_UNKNOWN = ("enclosed", "free", "occupied")


class _DiscreteSDF(Parameterised):
    _dim = 0

    def __init__(self, *, unknown: str = "enclosed", outside_variance: float = 1.0):
        self.unknown = unknown
        self.outside_variance = outside_variance

    def fit(self, occupied, origin, cell_size, *, free=None):
        """Build the signed distance field of a boolean occupancy array.

        Parameters
        ----------
        occupied : ndarray of bool, shape (nx, ny[, nz])
            Occupied cells, indexed ``[ix, iy(, iz)]``.
        origin : array of shape (dim,)
            World position (m) of the lower corner of cell 0; cell centres sit at
            ``origin + (index + 0.5) * cell_size``.
        cell_size : float
            Cell side, metres.
        free : ndarray of bool, same shape, optional
            Known free cells. Default: every cell that is not occupied is known free.

        Returns
        -------
        self
        """
        check_choice(self.unknown, _UNKNOWN, "unknown")
        as_positive_float(self.outside_variance, "outside_variance")
        d = self._dim
        occ = self._as_mask(occupied, "occupied")
        if any(s < 2 for s in occ.shape):
            raise ValueError(f"occupied: expected at least 2 cells along each axis, got shape {occ.shape}")
        origin = as_float_array(origin, "origin")
        if origin.shape != (d,) or not np.isfinite(origin).all():
            raise ValueError(f"origin: expected {d} finite numbers, got {origin!r}")
        cs = as_positive_float(cell_size, "cell_size")
        if free is None:
            free = ~occ
        else:
            free = self._as_mask(free, "free")
            if free.shape != occ.shape:
                raise ValueError(f"free: expected shape {occ.shape} like occupied, got {free.shape}")
            if (free & occ).any():
                raise ValueError("free: a cell cannot be both free and occupied")
        inside = occ.copy()
        unknown = ~(occ | free)
        if self.unknown == "occupied":
            inside |= unknown
        elif self.unknown == "enclosed" and unknown.any():
            # Flood the outside from the known free cells through cells at least one cell away
            # from an occupied one: that seals the one-cell leaks of a range-sensor wall (grazing
            # rays mark a few wall cells free) while real openings stay open. The unknown cells
            # the flood does not reach are enclosed; so are unknown cells along the walls.
            cross = ndimage.generate_binary_structure(d, 1)
            open_ = ~ndimage.binary_dilation(occ, cross)
            labels, _ = ndimage.label(open_, structure=cross)
            reached = np.unique(labels[free & open_])
            inside |= unknown & ~(open_ & np.isin(labels, reached[reached > 0]))
        if not inside.any():
            raise ValueError("occupied: no occupied cell, the distance field is undefined")
        if inside.all():
            raise ValueError("occupied: every cell is inside, the distance field is undefined")
        d_in = ndimage.distance_transform_edt(~inside) * cs  # outside cells: to the nearest inside cell
        d_out = ndimage.distance_transform_edt(inside) * cs  # inside cells: to the nearest outside cell
        self.sdf_ = np.where(inside, cs - d_out, d_in)
        self.grad_ = np.stack(np.gradient(self.sdf_, cs), axis=-1)
        self.inside_ = inside
        self.origin_ = origin.copy()
        self.cell_size_ = cs
        return self

    @staticmethod
    def _as_mask(a, name):
        if not isinstance(a, np.ndarray):
            raise TypeError(f"{name}: expected a numpy array, got {type(a).__name__}")
        if a.dtype.kind in "cOSUVMm":   # complex, objects, text, timestamps: no truth value per cell
            raise TypeError(f"{name}: expected a boolean (or numeric) array, got dtype {a.dtype}")
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            raise ValueError(f"{name}: contains NaN or inf")
        return np.asarray(a, dtype=bool)

    def _check_mask_dim(self, a, name):
        if a.ndim != self._dim:
            raise ValueError(f"{name}: expected a {self._dim}D array, got shape {a.shape}")

    def query(self, points):
        """Signed distance (n,), gradient (n, dim) and a variance (n,) at world points (n, dim).

        The variance is ``cell_size**2 / 12`` (where the surface may lie within its cell) inside
        the grid, and ``outside_variance`` outside it, where the values are those of the nearest
        grid point. It lets ICP-G's variance weighting and gating treat this map like a GPIS.
        """
        check_updated(self, "sdf_")
        p = as_points(points, self._dim, "points", allow_empty=True)
        return self._interp(p)

    def _interp(self, p):
        d = self._dim
        cs = self.cell_size_
        shape = np.array(self.sdf_.shape)
        u = (p - self.origin_) / cs - 0.5  # continuous index: cell centres at integers
        uc = np.clip(u, 0.0, shape - 1)
        outside = (np.abs(u - uc) > 1e-9).any(axis=1)
        i0 = np.minimum(np.floor(uc).astype(np.int64), shape - 2)
        f = uc - i0
        val = np.zeros(len(p))
        grad = np.zeros((len(p), d))
        for corner in itertools.product((0, 1), repeat=d):
            c = np.array(corner)
            idx = tuple((i0 + c).T)
            w = np.prod(np.where(c == 1, f, 1.0 - f), axis=1)
            val += w * self.sdf_[idx]
            grad += w[:, None] * self.grad_[idx]
        var = np.where(outside, float(self.outside_variance), cs * cs / 12.0)
        return val, grad, var

    def surface_points(self):
        """Centres (m, dim) of the inside cells that touch an outside cell: the zero level set."""
        check_updated(self, "sdf_")
        edge = self.inside_ & ndimage.binary_dilation(~self.inside_, ndimage.generate_binary_structure(self._dim, 1))
        return self.origin_ + (np.column_stack(np.nonzero(edge)) + 0.5) * self.cell_size_


class DiscreteSDF2D(_DiscreteSDF):
    """Signed EDT of a 2D occupancy grid with bilinear distance and gradient queries.

    See the module docstring for the sign convention.

    Parameters
    ----------
    unknown : {"enclosed", "free", "occupied"}, default="enclosed"
        Side of the unknown cells (module docstring).
    outside_variance : float, default=1.0
        Variance reported for points outside the grid (like GPIS's "no data" variance).

    Attributes
    ----------
    sdf_ : ndarray of shape (nx, ny)
        Signed distance at the cell centres, metres.
    grad_ : ndarray of shape (nx, ny, 2)
        Its central-difference gradient.
    inside_ : ndarray of bool, shape (nx, ny)
        Cells on the negative side.
    origin_ : ndarray of shape (2,)
        Lower-left corner of cell [0, 0], metres.
    cell_size_ : float
        Cell side, metres.

    Examples
    --------
    >>> sdf = DiscreteSDF2D.from_grid(grid)          # doctest: +SKIP
    >>> d, g, v = sdf.query([[1.0, 2.0]])            # doctest: +SKIP
    """

    TAGS = Tags(update="fit", query="query", data="polar_sim.baselines.examples:discrete_sdf_2d")

    _dim = 2

    def fit(self, occupied, origin, cell_size, *, free=None):
        self._check_mask_dim(self._as_mask(occupied, "occupied"), "occupied")
        return super().fit(occupied, origin, cell_size, free=free)

    fit.__doc__ = _DiscreteSDF.fit.__doc__

    @classmethod
    def from_grid(cls, grid, **params):
        """Signed EDT of an :class:`~polar_sim.baselines.OccupancyGrid2D` (its occupied and free cells)."""
        check_updated(grid, "log_odds_")
        return cls(**params).fit(grid.occupied_mask(), grid.origin_, grid.cell_size, free=grid.free_mask())

    @classmethod
    def from_values(cls, values, origin, cell_size, **params):
        """A field given by its values at the cell centres, (nx, ny) metres at
        ``origin + (index + 0.5) * cell_size`` (for example an exact SDF sampled on a grid: the
        dissertation's ground-truth discrete SDF), queried like the EDT; inside = negative."""
        sdf = cls(**params)
        as_positive_float(sdf.outside_variance, "outside_variance")
        vals = as_float_array(values, "values")
        if vals.ndim != 2 or min(vals.shape) < 2 or not np.isfinite(vals).all():
            raise ValueError(f"values: expected a finite (nx >= 2, ny >= 2) array, got shape {vals.shape}")
        origin = as_float_array(origin, "origin")
        if origin.shape != (2,) or not np.isfinite(origin).all():
            raise ValueError(f"origin: expected 2 finite numbers, got {origin!r}")
        cs = as_positive_float(cell_size, "cell_size")
        sdf.sdf_ = vals.copy()
        sdf.grad_ = np.stack(np.gradient(sdf.sdf_, cs), axis=-1)
        sdf.inside_ = sdf.sdf_ < 0
        sdf.origin_ = origin.copy()
        sdf.cell_size_ = cs
        return sdf


class DiscreteSDF3D(_DiscreteSDF):
    """Signed EDT of a 3D voxel occupancy with trilinear distance and gradient queries.

    Same parameters, attributes and sign convention as :class:`DiscreteSDF2D`, with arrays of
    shape (nx, ny, nz) and points of shape (n, 3).
    """

    TAGS = Tags(update="fit", query="query", data="polar_sim.baselines.examples:discrete_sdf_3d")

    _dim = 3

    def fit(self, occupied, origin, cell_size, *, free=None):
        self._check_mask_dim(self._as_mask(occupied, "occupied"), "occupied")
        return super().fit(occupied, origin, cell_size, free=free)

    fit.__doc__ = _DiscreteSDF.fit.__doc__
