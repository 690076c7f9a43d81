"""Surface metrics: distances between point sets, SDF errors and normal errors.

Definitions (all distances in the points' unit, metres in polar_sim):

- ``d(a, B)``: Euclidean distance from a point a to its nearest neighbour in the set B.
- directed Hausdorff ``h(A, B) = max_a d(a, B)``; **Hausdorff** ``max(h(A, B), h(B, A))``.
- **Chamfer** ``(mean_a d(a, B) + mean_b d(b, A)) / 2``: the mean of the two directed mean
  nearest-neighbour distances (not squared), so it is in metres and equals the offset for two
  copies of a dense surface shifted along its normal.
- **surface RMSE** ``sqrt(mean_a d(a, B)^2)``: how far the estimated surface points A lie from the
  true surface, densely sampled as B (directed: A -> B). With an exact SDF at hand, the same figure
  is ``sdf_error(np.zeros(n), true_sdf(A)).rmse``.

Sample true 2D surfaces densely (spacing well below the tolerance of interest) with
:func:`sample_polyline`: the distance to a sampled curve over-estimates the distance to the curve
by at most half the spacing.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from polar_sim._validation import as_float_array, as_points, as_positive_float

__all__ = [
    "MAX_SURFACE_POINTS",
    "SurfaceErrorStats",
    "nearest_distances",
    "hausdorff",
    "chamfer",
    "surface_rmse",
    "sdf_error",
    "normal_angles",
    "normal_angle_error",
    "sample_polyline",
]


@dataclasses.dataclass(frozen=True)
class SurfaceErrorStats:
    """Summary of a per-point error array (absolute values where a sign exists)."""

    n: int
    mean: float
    rmse: float
    median: float
    p90: float
    max: float
    bias: float  # signed mean (equals ``mean`` for unsigned errors)

    @classmethod
    def from_errors(cls, e):
        """Statistics of errors (n,): mean, RMSE, median, 90th percentile and max of |e|, signed mean."""
        a = np.abs(e)
        return cls(
            n=int(e.size),
            mean=float(a.mean()),
            rmse=float(np.sqrt(np.mean(e * e))),
            median=float(np.median(a)),
            p90=float(np.percentile(a, 90)),
            max=float(a.max()),
            bias=float(e.mean()),
        )


#: The most points a point set may hold in the nearest-neighbour metrics (:func:`hausdorff`,
#: :func:`chamfer`, :func:`nearest_distances`, :func:`surface_rmse`): a KD-tree of 1e7 points in 3D
#: takes about 0.5 GB and tens of seconds to build and query; beyond, subsample the surface.
MAX_SURFACE_POINTS = 10_000_000


def _cloud(x, name, dim=None):
    """Point set (n, 2|3) validated through ``as_points``; ``dim`` fixes the dimension. At most
    :data:`MAX_SURFACE_POINTS` points, checked before anything is allocated."""
    a = as_float_array(x, name)
    if a.ndim == 2 and a.shape[0] > MAX_SURFACE_POINTS:
        raise ValueError(f"{name}: at most {MAX_SURFACE_POINTS:,} points (subsample the surface), got {a.shape[0]:,}")
    if dim is None:
        dim = a.shape[1] if a.ndim == 2 and a.shape[1] in (2, 3) else 3
    return as_points(a, dim, name)


def _pair(points_a, points_b):
    a = _cloud(points_a, "points_a")
    return a, _cloud(points_b, "points_b", dim=a.shape[1])


def nearest_distances(points, reference):
    """Distance (n,) from each of ``points`` (n, d) to its nearest neighbour in ``reference`` (m, d)."""
    p = _cloud(points, "points")
    r = _cloud(reference, "reference", dim=p.shape[1])
    return cKDTree(r).query(p)[0]


def hausdorff(points_a, points_b) -> float:
    """Symmetric Hausdorff distance between point sets (n, d) and (m, d), d in {2, 3}."""
    a, b = _pair(points_a, points_b)
    return float(max(cKDTree(b).query(a)[0].max(), cKDTree(a).query(b)[0].max()))


def chamfer(points_a, points_b) -> float:
    """Chamfer distance: mean of the two directed mean nearest-neighbour distances (module docstring)."""
    a, b = _pair(points_a, points_b)
    return float(0.5 * (cKDTree(b).query(a)[0].mean() + cKDTree(a).query(b)[0].mean()))


def surface_rmse(points_est, points_true) -> float:
    """RMS distance from estimated surface points (n, d) to a dense sampling of the true surface (m, d)."""
    e = _cloud(points_est, "points_est")
    t = _cloud(points_true, "points_true", dim=e.shape[1])
    d = cKDTree(t).query(e)[0]
    return float(np.sqrt(np.mean(d * d)))


def sdf_error(est, truth, *, mask=None) -> SurfaceErrorStats:
    """Statistics of ``est - truth`` for signed distances (n,) (any shape, flattened), metres.

    ``mask`` (same shape, bool) selects the points to score, e.g. those within 0.3 m of a wall or
    where the map variance is low. NaN or inf in the selected values raise ``ValueError``.
    """
    e = as_float_array(est, "est").ravel()
    t = as_float_array(truth, "truth").ravel()
    if e.shape != t.shape:
        raise ValueError(f"truth: expected {e.shape[0]} values like est, got {t.shape[0]}")
    if mask is not None:
        if not isinstance(mask, np.ndarray) or mask.dtype != bool:
            got = f"dtype {mask.dtype}" if isinstance(mask, np.ndarray) else type(mask).__name__
            raise TypeError(f"mask: expected a boolean array, got {got}")
        if mask.size != e.size:
            raise ValueError(f"mask: expected {e.size} values like est, got {mask.size}")
        e, t = e[mask.ravel()], t[mask.ravel()]
    if e.size == 0:
        raise ValueError("est: no value to score")
    if not (np.isfinite(e).all() and np.isfinite(t).all()):
        raise ValueError("est: contains NaN or inf" if not np.isfinite(e).all() else "truth: contains NaN or inf")
    return SurfaceErrorStats.from_errors(e - t)


def normal_angles(est_normals, true_normals, *, oriented: bool = True):
    """Angle (n,) in degrees between paired normals (n, d); need not be unit length.

    ``oriented=False`` ignores the sign (the angle to the nearer of n and -n, at most 90 deg).
    """
    e = _cloud(est_normals, "est_normals")
    t = _cloud(true_normals, "true_normals", dim=e.shape[1])
    if e.shape[0] != t.shape[0]:
        raise ValueError(f"true_normals: expected {e.shape[0]} normals like est_normals, got {t.shape[0]}")
    ne, nt = np.linalg.norm(e, axis=1), np.linalg.norm(t, axis=1)
    if (ne == 0).any():
        raise ValueError("est_normals: contains a zero vector")
    if (nt == 0).any():
        raise ValueError("true_normals: contains a zero vector")
    c = np.einsum("ij,ij->i", e, t) / (ne * nt)
    if not oriented:
        c = np.abs(c)
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def normal_angle_error(est_normals, true_normals, *, oriented: bool = True) -> SurfaceErrorStats:
    """Statistics (degrees) of :func:`normal_angles`."""
    return SurfaceErrorStats.from_errors(normal_angles(est_normals, true_normals, oriented=oriented))


def sample_polyline(vertices, spacing, *, closed: bool = False):
    """Points (m, 2|3) every ``spacing`` metres of arc length along a polyline (k, 2|3).

    Each segment is split into ``ceil(length / spacing)`` equal parts, so no gap exceeds
    ``spacing``; every vertex is included once. ``closed=True`` adds the segment back to the start.
    """
    v = _cloud(vertices, "vertices")
    spacing = as_positive_float(spacing, "spacing")
    if closed:
        v = np.vstack([v, v[:1]])
    if len(v) < 2:
        raise ValueError(f"vertices: expected at least 2 vertices, got {len(v)}")
    out = []
    for a, b in zip(v[:-1], v[1:]):
        k = max(int(np.ceil(np.linalg.norm(b - a) / spacing)), 1)
        s = np.arange(k)[:, None] / k
        out.append(a + s * (b - a))
    if not closed:
        out.append(v[-1:])
    return np.vstack(out)
