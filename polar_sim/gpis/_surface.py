"""Zero level set of a GPIS map: polylines in 2D (marching squares), a mesh in 3D (marching cubes)."""

from __future__ import annotations

import numpy as np

__all__ = ["surface_2d", "surface_3d", "grid_query"]


def grid_query(m, axes, band, var_max, chunk=100_000):
    """SDF on the grid spanned by ``axes`` (indexing 'ij') at nodes within ``band`` of a sample.

    Returns (sdf, mask): nodes outside the band, or (legacy) with GP variance >= var_max, are
    masked out and hold +band.
    """
    mesh = np.meshgrid(*axes, indexing="ij")
    P = np.stack([g.ravel() for g in mesh], 1)
    kd, _ = m._kd()
    dist, _ = kd.query(P, k=1, distance_upper_bound=band)
    idx = np.nonzero(np.isfinite(dist))[0]
    sdf = np.full(len(P), band)
    keep = np.zeros(len(P), bool)
    for a in range(0, len(idx), chunk):
        j = idx[a:a + chunk]
        d, _, v = m.query(P[j])
        sdf[j] = d
        keep[j] = v < var_max
    shape = tuple(len(x) for x in axes)
    # cells touching an unevaluated node would see the +band filler: erode the mask by one node
    from scipy.ndimage import binary_erosion

    keep = binary_erosion(keep.reshape(shape), structure=np.ones((3,) * len(shape), bool),
                          border_value=0)
    return sdf.reshape(shape), keep


def _jumps(sdf, res, k=2.0):
    """Nodes of grid cells whose sign change is a jump, not a zero crossing.

    A distance field changes by at most ``res * sqrt(2)`` across a cell, so at a true zero
    crossing every corner lies within that of zero; a cell with a sign change and a corner beyond
    ``k`` times it straddles a discontinuity of the field (the surfel distance changes sign
    where a point passes the plane of a surfel beyond its rim), which marching squares would
    turn into a spurious surface."""
    a, b, c, d = sdf[:-1, :-1], sdf[1:, :-1], sdf[:-1, 1:], sdf[1:, 1:]
    lo = np.minimum(np.minimum(a, b), np.minimum(c, d))
    hi = np.maximum(np.maximum(a, b), np.maximum(c, d))
    big = np.maximum(np.maximum(np.abs(a), np.abs(b)), np.maximum(np.abs(c), np.abs(d)))
    bad = (lo < 0) & (hi > 0) & (big > k * np.sqrt(2.0) * res)
    out = np.zeros(sdf.shape, bool)
    out[:-1, :-1] |= bad
    out[1:, :-1] |= bad
    out[:-1, 1:] |= bad
    out[1:, 1:] |= bad
    return out


#: Grid nodes :meth:`surface` evaluates at most (about 60 bytes each while it runs).
MAX_SURFACE_NODES = 1 << 24


def _axes(m, res, margin):
    """Grid axes over the samples' bounding box; ``ValueError`` naming ``res`` and the limit
    when the grid would exceed :data:`MAX_SURFACE_NODES` (checked before anything is allocated)."""
    if not (np.isfinite(res) and res > 0):
        raise ValueError(f"res: expected a finite grid step > 0 m, got {res!r}")
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError(f"band: expected a finite band >= 0 m, got {margin!r}")
    pts = m.samples()["points"]
    lo = np.floor((pts.min(0) - margin) / res) * res
    hi = np.ceil((pts.max(0) + margin) / res) * res
    n = np.prod([float(x) for x in np.floor((hi - lo) / res + 1.5)])
    if not n <= MAX_SURFACE_NODES:
        raise ValueError(f"res: a surface grid of {n:.3g} nodes at res={res:g} m over the map's "
                         f"{np.round(hi - lo, 3).tolist()} m extent is over the limit of "
                         f"{MAX_SURFACE_NODES} nodes (MAX_SURFACE_NODES); raise res")
    return [np.arange(a, b + 0.5 * res, res) for a, b in zip(lo, hi)]


def surface_2d(m, res, band, var_max):
    """List of polylines (k, 2) along the zero level of the map's query, near observed samples;
    (default mode) with the zero level of objects smaller than ``res`` (:func:`_refined`), where
    a (1, 2) array is a point at which the level only touches zero."""
    from skimage.measure import find_contours

    if len(m.tree_.alive()) == 0:
        return []
    axes = _axes(m, res, 2 * res + band)
    sdf, mask = grid_query(m, axes, band, var_max)
    if not m._pub("query_mode"):
        mask = mask & ~_jumps(sdf, res)
    lines = find_contours(sdf, 0.0, mask=mask)
    x0 = np.array([a[0] for a in axes])
    out = [x0 + c * res for c in lines if len(c) >= 2]
    if not m._pub("query_mode"):
        # closed loops shorter than 4 grid steps enclose at most a cell or two: bubbles of the
        # field's sign (a spurious zero between samples), not a surface the grid can resolve
        out = [ln for ln in out if not _bubble(ln, res)]
        out += _refined(m, out, res)
    return out


def _bubble(line, res):
    """A closed polyline shorter than 4 grid steps ``res``."""
    return bool(np.allclose(line[0], line[-1]) and np.linalg.norm(np.diff(line, axis=0), axis=1).sum() < 4 * res)


#: Refinement of :func:`surface_2d` around samples its grid misses: the finer step (a share of
#: ``res``) and the window's half-width (in ``res``).
REFINE_STEP, REFINE_HALF = 0.2, 3


def _refined(m, lines, res):
    """The zero level of objects smaller than the grid resolves (a post a few cm across, seen
    end-on, whose zero level at ``res`` is a bubble or no crossing at all).

    Around every sample with no polyline within ``2 res``: the zero level of a window of
    ``REFINE_HALF`` res at ``REFINE_STEP`` res, its own bubbles dropped; a sample that still has
    no polyline near it but where the map is zero (within the finer step) is a point of the zero
    level that only touches zero, returned as a (1, 2) array."""
    from scipy.spatial import cKDTree
    from skimage.measure import find_contours

    P = m.samples()["points"]
    fine, half = REFINE_STEP * res, REFINE_HALF * res
    if len(lines):
        orphan = P[cKDTree(np.vstack(lines)).query(P, distance_upper_bound=2 * res)[0] > 2 * res]
    else:
        orphan = P
    if not len(orphan):
        return []
    ax = np.arange(-half, half + 0.5 * fine, fine)
    win = np.stack(np.meshgrid(ax, ax, indexing="ij"), -1).reshape(-1, 2)
    kd = cKDTree(orphan)
    out, covered = [], np.zeros(len(orphan), bool)
    for i, c in enumerate(orphan):
        if covered[i]:
            continue
        inside = np.array(kd.query_ball_point(c, 0.8 * half), int)   # one window per cluster
        covered[inside] = True
        sdf = m.query(win + c)[0].reshape(len(ax), len(ax))
        found = [ln for ln in (c - half + k * fine for k in find_contours(sdf, 0.0))
                 if len(ln) >= 2 and not _bubble(ln, fine)]
        out += found
        q = orphan[inside]
        if found:
            q = q[cKDTree(np.vstack(found)).query(q, distance_upper_bound=2 * fine)[0] > 2 * fine]
        if len(q):
            out += [p[None] for p, d in zip(q, m.query(q)[0]) if abs(d) < fine]
    return out


def surface_3d(m, res, band, var_max):
    """trimesh.Trimesh of the zero level near observed samples (marching cubes)."""
    import trimesh
    from skimage.measure import marching_cubes

    if len(m.tree_.alive()) == 0:
        return trimesh.Trimesh()
    axes = _axes(m, res, 2 * res + band)
    sdf, mask = grid_query(m, axes, band, var_max)
    if not ((sdf[mask] > 0).any() and (sdf[mask] < 0).any()):
        return trimesh.Trimesh()
    verts, faces, normals, _ = marching_cubes(sdf, 0.0, spacing=(res,) * 3, mask=mask,
                                              gradient_direction="ascent")
    x0 = np.array([a[0] for a in axes])
    return trimesh.Trimesh(verts + x0, faces[:, ::-1], vertex_normals=normals, process=False)
