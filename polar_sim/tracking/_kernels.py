"""numba kernels for the per-pixel hot loops (nearest visible model point, ROI distances).

Measured first (see ``benchmarks/results/tracking.md``): the numpy versions of these loops cost
3-10 ms per call on a 250 x 250 ROI, the kernels 0.2-0.6 ms. Compiled once and cached on disk.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["nearest_visible", "roi_distances", "icp_residuals", "icp_normal_equations"]


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
def roi_distances(depth, x0, y0, fx, fy, cx, cy, R, t, origin, inv_h, knn, P, N, vis, kappa, slack, out):
    """Distance (h, w) from each back-projected ROI pixel to the nearest visible model point.

    ``depth`` is the ROI crop (h, w) in metres, its top-left pixel at (x0, y0) of the image; R, t
    map camera to model coordinates. With ``kappa > 1`` the offset from the matched point m is
    split along its normal n: ``sqrt((n.d)^2 + |d - (n.d) n|^2 / kappa^2)``, so a point that slid
    along the surface counts less than one off it. Where ``slack[j] > 0`` (m, per model point:
    where the model is sparser than on average) the first ``slack[j]`` of the tangential offset
    does not count: ``sqrt((n.d)^2 + max(0, |d_t| - slack)^2 / kappa^2)``. Missing depth (0, NaN,
    inf) gives NaN; no visible candidate or a point outside the grid gives inf. Written into
    ``out`` (h, w) float32.
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
            j, d = _lookup(px, py, pz, origin, inv_h, knn, P, vis)
            if j >= 0 and (kappa > 1.0 or slack[j] > 0.0):
                dx = px - P[j, 0]
                dy = py - P[j, 1]
                dz = pz - P[j, 2]
                dn = dx * N[j, 0] + dy * N[j, 1] + dz * N[j, 2]
                dt2 = max(d * d - dn * dn, 0.0)
                if slack[j] > 0.0:
                    et = max(np.sqrt(dt2) - slack[j], 0.0)
                    dt2 = et * et
                d = np.sqrt(dn * dn + dt2 / (kappa * kappa))
            out[v, u] = d


@njit(cache=True, nogil=True)
def icp_residuals(X, R, t, origin, inv_h, knn, P, N, vis, gate, idx, res):
    """Correspondences of camera points X (n, 3) under T = (R, t) (T_cam_cen): for each point the
    nearest visible model point within ``gate`` (idx, -1 if none) and the point-to-plane residual
    ``n . (m - y)`` with y = R^T (x - t). Returns the number of matched points."""
    n = X.shape[0]
    cnt = 0
    for i in range(n):
        dx = X[i, 0] - t[0]
        dy = X[i, 1] - t[1]
        dz = X[i, 2] - t[2]
        yx = R[0, 0] * dx + R[1, 0] * dy + R[2, 0] * dz
        yy = R[0, 1] * dx + R[1, 1] * dy + R[2, 1] * dz
        yz = R[0, 2] * dx + R[1, 2] * dy + R[2, 2] * dz
        j, d = _lookup(yx, yy, yz, origin, inv_h, knn, P, vis)
        if j < 0 or d >= gate:
            idx[i] = -1
            res[i] = 0.0
            continue
        idx[i] = j
        res[i] = N[j, 0] * (P[j, 0] - yx) + N[j, 1] * (P[j, 1] - yy) + N[j, 2] * (P[j, 2] - yz)
        cnt += 1
    return cnt


@njit(cache=True, nogil=True)
def icp_normal_equations(X, R, t, P, N, idx, res, w, mu2, dz, H, g):
    """Accumulate H (6, 6) and g (6,) of the weighted point-to-plane term plus ``mu2`` times the
    tangential point-to-point term (body twist about the centred frame, see icp.py).

    ``dz`` (M,): the tangential term's dead zone per model point, m. A point whose tangential
    offset from its model point is within it gives no tangential term (only point-to-plane); one
    beyond it gives the offset shortened by it. 0 everywhere: the plain tangential term."""
    for a in range(6):
        g[a] = 0.0
        for b in range(6):
            H[a, b] = 0.0
    Hin = np.zeros((6, 6))
    s0 = 0.0
    s1 = np.zeros(3)
    s2 = np.zeros((3, 3))
    gt = np.zeros(6)
    J = np.zeros(6)
    for i in range(X.shape[0]):
        j = idx[i]
        wi = w[i]
        if j < 0 or wi <= 0.0:
            continue
        mx, my, mz = P[j, 0], P[j, 1], P[j, 2]
        nx, ny, nz = N[j, 0], N[j, 1], N[j, 2]
        J[0] = my * nz - mz * ny
        J[1] = mz * nx - mx * nz
        J[2] = mx * ny - my * nx
        J[3] = nx
        J[4] = ny
        J[5] = nz
        r = res[i]
        for a in range(6):
            wa = wi * J[a]
            g[a] += wa * r
            for b in range(a, 6):
                H[a, b] += wa * J[b]
        if mu2 > 0.0:
            dx = X[i, 0] - t[0]
            dy = X[i, 1] - t[1]
            dw = X[i, 2] - t[2]
            yx = R[0, 0] * dx + R[1, 0] * dy + R[2, 0] * dw
            yy = R[0, 1] * dx + R[1, 1] * dy + R[2, 1] * dw
            yz = R[0, 2] * dx + R[1, 2] * dy + R[2, 2] * dw
            ex, ey, ez = mx - yx, my - yy, mz - yz
            en = ex * nx + ey * ny + ez * nz
            ex, ey, ez = ex - en * nx, ey - en * ny, ez - en * nz
            dzj = dz[j]
            if dzj > 0.0:
                # within the dead zone the offset is the gap random samples leave: no tangential term
                # (the point keeps its full point-to-plane term, added back below)
                a_t = np.sqrt(ex * ex + ey * ey + ez * ez)
                if a_t <= dzj:
                    for a in range(6):
                        wa = wi * J[a]
                        for b in range(a, 6):
                            Hin[a, b] += wa * J[b]
                    continue
                f = 1.0 - dzj / a_t
                ex, ey, ez = f * ex, f * ey, f * ez
            ex, ey, ez = wi * ex, wi * ey, wi * ez
            gt[0] += my * ez - mz * ey
            gt[1] += mz * ex - mx * ez
            gt[2] += mx * ey - my * ex
            gt[3] += ex
            gt[4] += ey
            gt[5] += ez
            s0 += wi
            s1[0] += wi * mx
            s1[1] += wi * my
            s1[2] += wi * mz
            s2[0, 0] += wi * mx * mx
            s2[0, 1] += wi * mx * my
            s2[0, 2] += wi * mx * mz
            s2[1, 1] += wi * my * my
            s2[1, 2] += wi * my * mz
            s2[2, 2] += wi * mz * mz
    for a in range(6):
        for b in range(a):
            H[a, b] = H[b, a]
    if mu2 > 0.0:
        s2[1, 0] = s2[0, 1]
        s2[2, 0] = s2[0, 2]
        s2[2, 1] = s2[1, 2]
        tr = s2[0, 0] + s2[1, 1] + s2[2, 2]
        for a in range(6):
            g[a] += mu2 * gt[a]
            for b in range(6):
                H[a, b] *= 1.0 - mu2
        for a in range(6):
            for b in range(a, 6):
                H[a, b] += mu2 * Hin[a, b]
                if b > a:
                    H[b, a] += mu2 * Hin[a, b]
        for a in range(3):
            for b in range(3):
                H[a, b] += mu2 * ((tr if a == b else 0.0) - s2[a, b])
            H[3 + a, 3 + a] += mu2 * s0
        # hat(s1) in the top right, -hat(s1) in the bottom left
        H[0, 4] += -mu2 * s1[2]
        H[0, 5] += mu2 * s1[1]
        H[1, 3] += mu2 * s1[2]
        H[1, 5] += -mu2 * s1[0]
        H[2, 3] += -mu2 * s1[1]
        H[2, 4] += mu2 * s1[0]
        H[4, 0] += -mu2 * s1[2]
        H[5, 0] += mu2 * s1[1]
        H[3, 1] += mu2 * s1[2]
        H[5, 1] += -mu2 * s1[0]
        H[3, 2] += -mu2 * s1[1]
        H[4, 2] += mu2 * s1[0]

