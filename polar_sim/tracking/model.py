"""The shape prior M: model points, normals, a static KD-tree and a nearest-neighbour lookup grid.

All geometry is held in the *centred* model frame (object frame shifted to the points' centroid):
the tracker's pose perturbations rotate about the object's centre, which decouples rotation from
translation in the motion filter and in the gates (see ``docs/guide/tracking.md``, "Where this departs from the spec").
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from polar_sim.geometry import diameter
from polar_sim.tracking._kernels import nearest_visible

__all__ = ["ShapeModel", "estimate_normals"]


def estimate_normals(points, k=12):
    """Unit normals (n, 3) by PCA over the k nearest neighbours, oriented away from the centroid.

    The centroid rule is exact for convex (star-shaped) objects only: pass true normals for
    objects with concavities (a mug's inside).
    """
    tree = cKDTree(points)
    k = min(k, len(points))
    _, nb = tree.query(points, k=k)
    nb = nb.reshape(len(points), -1)
    Q = points[nb] - points[nb].mean(axis=1, keepdims=True)
    C = np.einsum("nki,nkj->nij", Q, Q)
    _, vecs = np.linalg.eigh(C)
    n = vecs[:, :, 0]
    out = points - points.mean(axis=0)
    n[np.einsum("ij,ij->i", n, out) < 0] *= -1.0
    return n


class ShapeModel:
    """Model points and normals in the centred frame, with the structures used for correspondences.

    Parameters
    ----------
    points : ndarray (M, 3)
        Object-frame points, metres.
    normals : ndarray (M, 3)
        Unit outward normals.
    grid_cells : int, default=64
        Cells along the longest side of the lookup grid.
    k : int, default=4
        Candidates per grid cell (the spec's k = 4 nearest neighbours).

    Attributes
    ----------
    centroid : (3,) object-frame centroid; ``P`` = points - centroid; ``N`` normals;
    diameter, spacing (1/sqrt(points per area) = 2 x mean nearest-neighbour distance) and
    margin (of the lookup grid around the points), all in metres; ``local_spacing`` (M,) the
    radius each point covers: ``spacing`` where the model is about as dense as on average, and
    2x the local 1/sqrt(density) (from its 16 nearest neighbours, averaged over them) where that
    is more than 1.3x ``spacing``, m. (The local estimates of a uniformly sampled model stay below
    1.3x the mean, 99.9th percentile, so such a model keeps ``spacing`` everywhere. Random
    samples leave empty discs up to about 1.3 / sqrt(density) in radius; on average they are covered by
    ``spacing``'s splats together with their neighbours', which a sparse patch does not have.) A model need not be
    sampled uniformly (a user may sample each part of an object with the same number of points,
    so that a large face is sparse): splats and distance bands use the spacing where they are.
    """

    def __init__(self, points, normals, *, grid_cells=64, k=4):
        self.centroid = points.mean(axis=0)
        self.P = np.ascontiguousarray(points - self.centroid)
        self.N = np.ascontiguousarray(normals / np.linalg.norm(normals, axis=1, keepdims=True))
        self.diameter = diameter(self.P)
        self.tree = cKDTree(self.P)
        if len(self.P) > 1:
            d, _ = self.tree.query(self.P, k=2)
            # 1/sqrt(density): for random (Poisson) surface samples the mean nearest-neighbour
            # distance is half of it, and splats need the larger value to close their gaps
            self.spacing = 2.0 * float(np.mean(d[:, 1]))
            kk = min(17, len(self.P))
            dk, nb = self.tree.query(self.P, k=kk)
            # E[r_k^2] = k / (pi rho) for surface samples of density rho: 1/sqrt(rho) = r_k sqrt(pi / k)
            est = (dk[:, -1] * np.sqrt(np.pi / (kk - 1)))[nb].mean(axis=1)
            self.local_spacing = np.ascontiguousarray(np.where(est > 1.3 * self.spacing, 2.0 * est, self.spacing))
        else:
            self.spacing = 0.001
            self.local_spacing = np.full(len(self.P), 0.001)
        self.slack = np.ascontiguousarray(self.local_spacing - self.spacing)
        self.k = min(k, len(self.P))
        self.margin = float(np.clip(0.25 * self.diameter, 0.03, 0.06))
        lo = self.P.min(axis=0) - self.margin
        hi = self.P.max(axis=0) + self.margin
        h = float((hi - lo).max()) / grid_cells
        dims = np.maximum(np.ceil((hi - lo) / h).astype(int), 1)
        self.origin = lo
        self.cell = h
        self.inv_h = 1.0 / h
        axes = [lo[i] + (np.arange(dims[i]) + 0.5) * h for i in range(3)]
        C = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        if (self.slack > 0).any():
            # a non-uniform model: rank candidates by distance in units of their own spacing, so a
            # cell over a sparse face keeps that face's points rather than a dense face's nearby
            kk = min(4 * self.k, len(self.P))
            dd, nb = self.tree.query(C, k=kk)
            nb = nb.reshape(len(C), kk)
            order = np.argsort(dd.reshape(len(C), kk) / self.local_spacing[nb], axis=1, kind="stable")[:, : self.k]
            nb = np.take_along_axis(nb, order, axis=1)
        else:
            _, nb = self.tree.query(C, k=self.k)
        self.knn = np.ascontiguousarray(nb.reshape(*dims, self.k).astype(np.int32))

    def nearest_visible(self, Y, vis, *, exact=False):
        """Nearest visible model point of each Y (n, 3) (centred frame): index (n,) (-1: none), distance (n,).

        ``exact=False`` looks up the k candidates stored in the grid cell of each point (O(1)); with
        ``exact=True`` the static cKDTree is queried for the k nearest neighbours instead.
        """
        if not exact:
            return nearest_visible(np.ascontiguousarray(Y), self.origin, self.inv_h, self.knn, self.P, vis)
        d, nb = self.tree.query(Y, k=self.k)
        d, nb = d.reshape(len(Y), -1), nb.reshape(len(Y), -1)
        ok = vis[nb]
        d = np.where(ok, d, np.inf)
        c = np.argmin(d, axis=1)
        dist = d[np.arange(len(Y)), c]
        idx = np.where(np.isfinite(dist), nb[np.arange(len(Y)), c], -1)
        far = dist > self.margin
        idx[far] = -1
        dist[far] = np.inf
        return idx.astype(np.int64), dist
