"""Visibility of model points (back-face test + z-buffer) and the projected silhouette (spec 3.2, 3.3).

Everything works on point splats: no mesh is needed, only the model points, their normals and
their mean spacing.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["Projection", "project_model", "splat_silhouette", "splat_depth", "disc"]

_DISCS: dict = {}
#: z-buffer resolution relative to the image (spec 3.2: half resolution)
ZS = 0.5


def disc(r):
    """Elliptic structuring element of radius ``r`` pixels (uint8, (2r+1, 2r+1))."""
    r = int(r)
    if r not in _DISCS:
        _DISCS[r] = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    return _DISCS[r]


@dataclass
class Projection:
    """Model points under one pose: camera-frame points ``Pc`` (M, 3), pixel coordinates ``uv``
    (M, 2), the visibility flags ``vis`` (M,) bool, and the mean depth ``z_mean`` of the visible points."""

    Pc: np.ndarray
    uv: np.ndarray
    vis: np.ndarray
    z_mean: float


def project_model(P, N, R, t, K, shape, spacing, *, cos_backface=np.cos(np.deg2rad(85.0)),
                  zbuffer=True):
    """Project model points P (M, 3) with normals N under x_cam = R P + t and test their visibility.

    1. back-face: keep j if ``n'_j . p_j / |p_j| < cos_backface`` (default cos 85 deg: points up to
       5 deg past the limb are kept, the spec's "slightly permissive");
    2. z-buffer at half resolution: each kept point is splatted as a disc of its footprint (half
       the point spacing, at least one half-res cell) by a grey erosion of the min-depth buffer;
       keep j if ``z_j <= zbuf + 5 mm + 0.01 z_j + footprint * tan(incidence)`` (the last term,
       capped at 4 x footprint, lets oblique surfaces pass their own neighbours' splats);
    3. points behind the camera or outside the image are not visible.
    """
    H, W = shape
    Pc = P @ R.T + t
    Nc = N @ R.T
    z = Pc[:, 2]
    front = z > 1e-3
    zs = np.where(front, z, 1.0)
    u = K[0, 0] * Pc[:, 0] / zs + K[0, 2]
    v = K[1, 1] * Pc[:, 1] / zs + K[1, 2]
    uv = np.stack([u, v], axis=1)
    inside = front & (u > -0.5) & (u < W - 0.5) & (v > -0.5) & (v < H - 0.5)
    rn = np.linalg.norm(Pc, axis=1)
    facing = np.einsum("ij,ij->i", Nc, Pc) < cos_backface * rn
    vis = inside & facing
    if zbuffer and vis.any():
        cu = np.floor((u[vis] + 0.5) * ZS).astype(np.int64)
        cv = np.floor((v[vis] + 0.5) * ZS).astype(np.int64)
        zv = z[vis]
        u0, v0 = cu.min(), cv.min()
        # footprint: half the point spacing, in half-resolution cells
        zmed = float(np.median(zv))
        r = int(max(1, np.ceil(K[0, 0] * spacing * ZS / (2.0 * zmed))))
        bh, bw = int(cv.max() - v0 + 1 + 2 * r), int(cu.max() - u0 + 1 + 2 * r)
        buf = np.full((bh, bw), 1e6, np.float32)
        iy, ix = cv - v0 + r, cu - u0 + r
        np.minimum.at(buf, (iy, ix), zv.astype(np.float32))
        buf = cv2.erode(buf, disc(r), borderType=cv2.BORDER_CONSTANT, borderValue=1e6)
        # a neighbour on the same oblique surface is nearer by up to footprint * tan(incidence)
        c = np.abs(np.einsum("ij,ij->i", Nc[vis], Pc[vis])) / rn[vis]
        tan = np.minimum(np.sqrt(np.maximum(1.0 - c * c, 0.0)) / np.maximum(c, 1e-3), 4.0)
        foot = (r / ZS) * zv / K[0, 0]
        ok = zv <= buf[iy, ix] + 0.005 + 0.01 * zv + foot * tan
        idx = np.flatnonzero(vis)
        vis[idx[~ok]] = False
    z_mean = float(z[vis].mean()) if vis.any() else float(np.mean(zs))
    return Projection(Pc, uv, vis, z_mean)


def splat_silhouette(uv, z_mean, f, spacing, roi):
    """Silhouette (h, w) uint8 {0, 1} of visible points ``uv`` (n, 2) inside ``roi`` = (x0, y0, x1, y1).

    ``spacing``: the radius each point covers, m, one value or one per point (n,). Each point is a
    disc of radius ``r_s = max(1, ceil(f s / z))`` px; the discs are joined by a closing (which
    shrinks them back, so the silhouette does not grow past the outermost points). With one
    radius this is OpenCV's dilation and erosion by that disc; with several, the union of every
    point's disc eroded by the smallest radius of the discs that cover each pixel (a closing with
    a varying radius: a sparsely sampled face closes with its own, larger discs).
    """
    x0, y0, x1, y1 = roi
    h, w = y1 - y0, x1 - x0
    S = np.zeros((h, w), np.uint8)
    if len(uv) == 0 or h <= 0 or w <= 0:
        return S
    iu = np.rint(uv[:, 0]).astype(np.int64) - x0
    iv = np.rint(uv[:, 1]).astype(np.int64) - y0
    ok = (iu >= 0) & (iu < w) & (iv >= 0) & (iv < h)
    sp = np.broadcast_to(np.asarray(spacing, dtype=np.float64), (len(uv),))
    rad = np.maximum(1, np.ceil(f * sp / max(z_mean, 1e-3))).astype(np.int64)
    radii = np.unique(rad[ok])
    if len(radii) <= 1:
        r = int(radii[0]) if len(radii) else int(rad.max())
        S[iv[ok], iu[ok]] = 1
        S = cv2.dilate(S, disc(r))
        S = cv2.erode(S, disc(r), borderType=cv2.BORDER_CONSTANT, borderValue=1)
        return cv2.dilate(S, disc(1))
    big = np.int32(1 << 20)
    e = np.full((h, w), big, np.int32)  # smallest radius of a disc covering each pixel
    for rv in radii:
        G = np.zeros((h, w), np.uint8)
        sel = ok & (rad == rv)
        G[iv[sel], iu[sel]] = 1
        cover = cv2.dilate(G, disc(rv)) > 0
        e[cover] = np.minimum(e[cover], np.int32(rv))
    D = (e < big).astype(np.uint8)
    # distance to the nearest pixel outside the union; the ROI's border counts as inside (as the
    # erosion's border value 1 above)
    dt = cv2.distanceTransform(cv2.copyMakeBorder(D, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=1), cv2.DIST_L2,
                               cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    S = ((D > 0) & (dt > e)).astype(np.uint8)
    # the outermost samples of a sparse patch lie about half their spacing inside its edge: grow the
    # closed silhouette back by half the local radius (one pixel where the samples are dense)
    ds = cv2.distanceTransform(1 - S, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return ((ds <= np.maximum(1.0, 0.5 * np.where(e < big, e, 0))) & (D > 0) | (S > 0)).astype(np.uint8)


def splat_depth(uv, z, r, roi):
    """Predicted depth (h, w) float32 of visible points ``uv`` (n, 2) at depths ``z`` (n,), m, in
    ``roi`` = (x0, y0, x1, y1): each point is a disc of radius ``r`` px, the nearest one winning
    (a min filter, as the z-buffer above); ``inf`` where no disc reaches."""
    x0, y0, x1, y1 = roi
    h, w = y1 - y0, x1 - x0
    Z = np.full((max(h, 0), max(w, 0)), np.inf, np.float32)
    if len(uv) == 0 or h <= 0 or w <= 0:
        return Z
    iu = np.rint(uv[:, 0]).astype(np.int64) - x0
    iv = np.rint(uv[:, 1]).astype(np.int64) - y0
    ok = (iu >= 0) & (iu < w) & (iv >= 0) & (iv < h)
    Z[:] = 1e6
    np.minimum.at(Z, (iv[ok], iu[ok]), np.asarray(z, np.float32)[ok])
    Z = cv2.erode(Z, disc(max(1, int(r))), borderType=cv2.BORDER_CONSTANT, borderValue=1e6)
    Z[Z >= 1e6] = np.inf
    return Z
