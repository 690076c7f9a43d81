"""Exact signed distances of MuJoCo geom shapes, in 3D and in a horizontal 2D section.

Each function takes points already expressed in the geom's own frame and returns the signed
distance in metres, negative inside. A scene's distance is the minimum over its geoms, which is
exact everywhere outside the shapes and inside any shape that overlaps no other.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "sdf_box", "sdf_sphere", "sdf_cylinder", "sdf_capsule", "sdf_plane",
    "sdf_rect2d", "sdf_circle2d", "sdf_polygons2d", "section_boxes_discs", "section_boxes_discs_gradient",
    "section_stencil",
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


# -- compiled 2D sections of many rectangles and discs ---------------------------------------------
# A world's section is the minimum over its shapes; evaluating it for every (point, shape) pair in
# one compiled loop avoids the (points x shapes) temporaries and the per-call overhead of numpy
# broadcasting, which dominated an environment step. Each distance is computed with exactly the
# operations, in the same order, of the numpy forms above (sdf_rect2d of the rotated point,
# sdf_circle2d), so the results are bit for bit the same.

@numba.njit(cache=True, nogil=True, inline="always")
def _point_section(x, y, boxes, discs):
    best = np.inf
    for b in range(boxes.shape[0]):
        rx = x - boxes[b, 0]
        ry = y - boxes[b, 1]
        # The point in the box frame: rel @ R (R = [[r00, r01], [r10, r11]]).
        u = rx * boxes[b, 2] + ry * boxes[b, 4]
        v = rx * boxes[b, 3] + ry * boxes[b, 5]
        qx = abs(u) - boxes[b, 6]
        qy = abs(v) - boxes[b, 7]
        mx = max(qx, 0.0)
        my = max(qy, 0.0)
        d = math.sqrt(mx * mx + my * my) + min(max(qx, qy), 0.0)
        if d < best:
            best = d
    for k in range(discs.shape[0]):
        dx = x - discs[k, 0]
        dy = y - discs[k, 1]
        d = math.sqrt(dx * dx + dy * dy) - discs[k, 2]
        if d < best:
            best = d
    return best


@numba.njit(cache=True, nogil=True)
def section_boxes_discs(points, boxes, discs):
    """Signed distance (n,) of points (n, 2) to the union of rectangles and discs, m.

    ``boxes`` (k, 8): centre x, y, the rotation's entries r00, r01, r10, r11 (box frame to world)
    and the half sizes; ``discs`` (m, 3): centre x, y and radius. ``inf`` with no shapes.
    """
    out = np.empty(points.shape[0])
    for i in range(points.shape[0]):
        out[i] = _point_section(points[i, 0], points[i, 1], boxes, discs)
    return out


@numba.njit(cache=True, nogil=True)
def section_boxes_discs_gradient(points, boxes, discs, h):
    """Distance (n,) and its central-difference gradient (n, 2) with step ``h`` (m): the
    gradient is ``(f(p + h e) - f(p - h e)) / (2 h)`` per axis, as numpy would compute it."""
    n = points.shape[0]
    d = np.empty(n)
    g = np.empty((n, 2))
    for i in range(n):
        x = points[i, 0]
        y = points[i, 1]
        d[i] = _point_section(x, y, boxes, discs)
        g[i, 0] = (_point_section(x + h, y + 0.0, boxes, discs)
                   - _point_section(x - h, y - 0.0, boxes, discs)) / (2 * h)
        g[i, 1] = (_point_section(x + 0.0, y + h, boxes, discs)
                   - _point_section(x - 0.0, y - h, boxes, discs)) / (2 * h)
    return d, g


@numba.njit(cache=True, nogil=True)
def section_stencil(offsets, pose, frame, boxes, discs, h):
    """:func:`section_boxes_discs` (and, with ``h`` > 0, its central-difference gradient) at the
    points ``offsets`` (n, 2) given in the frame of a planar pose, that pose given in ``frame``:
    world point = frame ∘ pose ∘ offset. ``pose`` and ``frame`` are (x, y, cos theta, sin theta)
    (4,); ``frame`` None-like is passed as an empty array (the pose is in the world). The
    gradient (n, 2) is expressed in ``frame``'s axes. Each point and rotation is computed with
    the operations of ``robot_to_world`` and the numpy forms, so the results are the same bit for
    bit as composing the points in numpy and calling the kernels above."""
    n = offsets.shape[0]
    d = np.empty(n)
    g = np.empty((n, 2) if h > 0 else (0, 2))
    x, y, c, s = pose[0], pose[1], pose[2], pose[3]
    for i in range(n):
        px, py = offsets[i, 0], offsets[i, 1]
        wx = x + c * px - s * py
        wy = y + s * px + c * py
        if frame.shape[0]:
            mx, my = wx, wy
            wx = frame[0] + frame[2] * mx - frame[3] * my
            wy = frame[1] + frame[3] * mx + frame[2] * my
        d[i] = _point_section(wx, wy, boxes, discs)
        if h > 0:
            gx = (_point_section(wx + h, wy + 0.0, boxes, discs)
                  - _point_section(wx - h, wy - 0.0, boxes, discs)) / (2 * h)
            gy = (_point_section(wx + 0.0, wy + h, boxes, discs)
                  - _point_section(wx - 0.0, wy - h, boxes, discs)) / (2 * h)
            if frame.shape[0]:
                cf, sf = frame[2], frame[3]
                gx, gy = cf * gx + sf * gy, -sf * gx + cf * gy
            g[i, 0] = gx
            g[i, 1] = gy
    return d, g
