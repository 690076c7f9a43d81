"""numba kernels for the per-pixel hot loops (nearest visible model point, ROI distances).

Measured first (see ``benchmarks/results/tracking.md``): the numpy versions of these loops cost
3-10 ms per call on a 250 x 250 ROI, the kernels 0.2-0.6 ms. Compiled once and cached on disk.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["nearest_visible", "roi_distances"]


@njit(cache=True, nogil=True)
def _lookup(px, py, pz, origin, inv_h, knn, P, vis):
    nx, ny, nz, k = knn.shape
    ix = int(np.floor((px - origin[0]) * inv_h))
    iy = int(np.floor((py - origin[1]) * inv_h))
    iz = int(np.floor((pz - origin[2]) * inv_h))
    if ix < 0 or iy < 0 or iz < 0 or ix >= nx or iy >= ny or iz >= nz:
        return -1, np.inf
    best, bd = -1, np.inf
    for c in range(k):
        j = knn[ix, iy, iz, c]
        if not vis[j]:
            continue
        dx = P[j, 0] - px
        dy = P[j, 1] - py
        dz = P[j, 2] - pz
        d = dx * dx + dy * dy + dz * dz
        if d < bd:
            bd = d
            best = j
    if best < 0:
        return -1, np.inf
    return best, np.sqrt(bd)


@njit(cache=True, nogil=True)
def nearest_visible(Y, origin, inv_h, knn, P, vis):
    """For points Y (n, 3) in the model frame: index (n,) of the nearest visible model point among
    the grid cell's k candidates (-1 if none or outside the grid) and its distance (n,) (inf)."""
    n = Y.shape[0]
    idx = np.empty(n, np.int64)
    dist = np.empty(n, np.float64)
    for i in range(n):
        j, d = _lookup(Y[i, 0], Y[i, 1], Y[i, 2], origin, inv_h, knn, P, vis)
        idx[i] = j
        dist[i] = d
    return idx, dist


@njit(cache=True, nogil=True)
def roi_distances(depth, x0, y0, fx, fy, cx, cy, R, t, origin, inv_h, knn, P, vis, out):
    """Distance (h, w) from each back-projected ROI pixel to the nearest visible model point.

    ``depth`` is the ROI crop (h, w) in metres, its top-left pixel at (x0, y0) of the image; R, t
    map camera to model coordinates. Missing depth (0, NaN, inf) gives NaN; no visible candidate or
    a point outside the grid gives inf. Written into ``out`` (h, w) float32.
    """
    h, w = depth.shape
    for v in range(h):
        yn = (v + y0 - cy) / fy
        for u in range(w):
            z = depth[v, u]
            if not (z > 0.0) or not np.isfinite(z):
                out[v, u] = np.nan
                continue
            xc = (u + x0 - cx) / fx * z
            yc = yn * z
            px = R[0, 0] * xc + R[0, 1] * yc + R[0, 2] * z + t[0]
            py = R[1, 0] * xc + R[1, 1] * yc + R[1, 2] * z + t[1]
            pz = R[2, 0] * xc + R[2, 1] * yc + R[2, 2] * z + t[2]
            _, d = _lookup(px, py, pz, origin, inv_h, knn, P, vis)
            out[v, u] = d
