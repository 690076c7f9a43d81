"""Exact signed distances of MuJoCo geom shapes, in 3D and in a horizontal 2D section.

Each function takes points already expressed in the geom's own frame and returns the signed
distance in metres, negative inside. A scene's distance is the minimum over its geoms, which is
exact everywhere outside the shapes and inside any shape that overlaps no other.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "sdf_box", "sdf_sphere", "sdf_cylinder", "sdf_capsule", "sdf_plane",
    "sdf_rect2d", "sdf_circle2d", "sdf_polygons2d",
]


def sdf_box(p, half):
    """Box centred at the origin with half sizes ``half`` (3,); p (n, 3)."""
    q = np.abs(p) - np.asarray(half)
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
    inside = np.minimum(q.max(axis=-1), 0.0)
    return outside + inside


def sdf_sphere(p, radius):
    """Sphere of ``radius`` centred at the origin; p (n, 3)."""
    return np.linalg.norm(p, axis=-1) - radius


def sdf_cylinder(p, radius, half_height):
    """Cylinder along z, centred at the origin; p (n, 3)."""
    d = np.stack([np.linalg.norm(p[:, :2], axis=1) - radius, np.abs(p[:, 2]) - half_height], 1)
    return np.minimum(d.max(axis=1), 0.0) + np.linalg.norm(np.maximum(d, 0.0), axis=1)


def sdf_capsule(p, radius, half_length):
    """Capsule along z (segment of half length ``half_length``, swept ``radius``); p (n, 3)."""
    q = p.copy()
    q[:, 2] = np.clip(q[:, 2], -half_length, half_length)
    return np.linalg.norm(p - q, axis=1) - radius


def sdf_plane(p):
    """Half-space z <= 0 (a MuJoCo plane is solid below its surface); p (n, 3)."""
    return p[:, 2].copy()


def sdf_rect2d(p, half):
    """Rectangle centred at the origin with half sizes ``half`` (2,); p (n, 2)."""
    q = np.abs(p) - np.asarray(half)
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


def sdf_circle2d(p, radius):
    """Disc of ``radius`` centred at the origin; p (n, 2)."""
    return np.linalg.norm(p, axis=-1) - radius


def sdf_polygons2d(p, segments, inside):
    """Signed distance to closed polygons given as segments.

    Parameters
    ----------
    p : (n, 2) points.
    segments : (m, 2, 2) segment end points of all polygon edges.
    inside : (n,) bool, which points lie inside the polygons (computed by the caller, e.g. with
        a point-in-polygon test).
    """
    a = segments[:, 0]
    b = segments[:, 1]
    ab = b - a
    denom = np.maximum((ab * ab).sum(1), 1e-300)
    best = np.full(len(p), np.inf)
    for start in range(0, len(p), 4096):
        pp = p[start : start + 4096, None, :]
        t = np.clip(((pp - a) * ab).sum(-1) / denom, 0.0, 1.0)
        d = np.linalg.norm(pp - (a + t[..., None] * ab), axis=-1).min(axis=1)
        best[start : start + 4096] = d
    return np.where(inside, -best, best)
