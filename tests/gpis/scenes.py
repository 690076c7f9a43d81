"""Analytic scenes with exact ranges and exact signed distance, for the GPIS tests and benchmarks.

2D: a rectangular room with a box and a circular pillar, scanned by ray-segment / ray-circle
intersection. 3D: a sphere (and optionally a box) seen by a pinhole camera, by ray casting.
"""

from __future__ import annotations

import numpy as np

# -- 2D room -----------------------------------------------------------------------------------
ROOM = (0.0, 0.0, 8.0, 6.0)                 # x0, y0, x1, y1 (inner faces of the walls)
BOX = (5.0, 1.0, 6.0, 2.0)                  # an obstacle box
PILLAR = ((2.0, 4.8), 0.4)                  # centre, radius


def _segments():
    x0, y0, x1, y1 = ROOM
    bx0, by0, bx1, by1 = BOX
    walls = [((x0, y0), (x1, y0)), ((x1, y0), (x1, y1)), ((x1, y1), (x0, y1)), ((x0, y1), (x0, y0))]
    box = [((bx0, by0), (bx1, by0)), ((bx1, by0), (bx1, by1)), ((bx1, by1), (bx0, by1)),
           ((bx0, by1), (bx0, by0))]
    return np.array(walls + box, float)


def ray_cast_2d(origin, dirs):
    """Exact range from origin (2,) along unit directions (n, 2) to the first wall, box or pillar."""
    segs = _segments()
    a, b = segs[:, 0], segs[:, 1]
    e = b - a                                                    # (s, 2)
    w = a[None] - origin[None, None]                             # (1, s, 2)
    den = dirs[:, None, 0] * e[None, :, 1] - dirs[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[None, :, 1] - w[..., 1] * e[None, :, 0]) / den
        u = (w[..., 0] * dirs[:, None, 1] - w[..., 1] * dirs[:, None, 0]) / den
    t = np.where((t > 1e-9) & (u >= 0) & (u <= 1) & np.isfinite(t), t, np.inf)
    r = t.min(1)
    c, rad = np.array(PILLAR[0]), PILLAR[1]
    oc = origin - c
    bq = dirs @ oc
    disc = bq**2 - (oc @ oc - rad**2)
    with np.errstate(invalid="ignore"):
        tc = -bq - np.sqrt(disc)
    tc = np.where((disc >= 0) & (tc > 1e-9), tc, np.inf)
    return np.minimum(r, tc)


def scan_2d(pose, angles, offset=(0.0, 0.0), noise=0.0, rng=None):
    """Ranges (n,) of a laser at ``offset`` in the base frame of ``pose`` = (x, y, theta)."""
    x, y, th = pose
    c, s = np.cos(th), np.sin(th)
    o = np.array([x + c * offset[0] - s * offset[1], y + s * offset[0] + c * offset[1]])
    d = np.stack([np.cos(th + angles), np.sin(th + angles)], 1)
    r = ray_cast_2d(o, d)
    if noise:
        r = r + rng.normal(0, noise, r.shape)
    return r


def _seg_dist(p, a, b):
    e = b - a
    t = np.clip(((p - a) @ e) / (e @ e), 0, 1)
    return np.linalg.norm(p - (a + t[:, None] * e), axis=1)


def sdf_2d(p):
    """Exact signed distance (n,) to the room walls, box and pillar: positive in the free space."""
    segs = _segments()
    d = np.min([_seg_dist(p, a, b) for a, b in segs], axis=0)
    c, rad = np.array(PILLAR[0]), PILLAR[1]
    dc = np.linalg.norm(p - c, axis=1) - rad
    x0, y0, x1, y1 = ROOM
    bx0, by0, bx1, by1 = BOX
    inside_room = (p[:, 0] > x0) & (p[:, 0] < x1) & (p[:, 1] > y0) & (p[:, 1] < y1)
    in_box = (p[:, 0] > bx0) & (p[:, 0] < bx1) & (p[:, 1] > by0) & (p[:, 1] < by1)
    free = inside_room & ~in_box & (dc > 0)
    dist = np.minimum(d, np.abs(dc))
    return np.where(free, dist, -dist)


def wall_points_2d(step=0.01):
    """Dense points on all true surfaces (for Hausdorff distances)."""
    pts = []
    for a, b in _segments():
        n = int(np.ceil(np.linalg.norm(b - a) / step)) + 1
        pts.append(a + np.linspace(0, 1, n)[:, None] * (b - a))
    c, rad = PILLAR
    t = np.linspace(0, 2 * np.pi, int(2 * np.pi * rad / step), endpoint=False)
    pts.append(np.stack([c[0] + rad * np.cos(t), c[1] + rad * np.sin(t)], 1))
    return np.vstack(pts)


def room_path(n=60):
    """A closed drive (n, 3) through the room, heading along the path."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    x = 3.8 + 2.0 * np.cos(t)
    y = 3.2 + 1.0 * np.sin(t)
    th = np.arctan2(1.0 * np.cos(t), -2.0 * np.sin(t))
    return np.stack([x, y, th], 1)


# -- 3D sphere ---------------------------------------------------------------------------------
SPHERE_C = np.array([0.0, 0.0, 0.0])
SPHERE_R = 0.1


def look_at(eye, target, up=(0.0, 0.0, 1.0)):
    """Camera-to-world pose (4, 4), OpenCV axes, camera at eye looking at target."""
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], 1)
    T[:3, 3] = eye
    return T


def intrinsics(W=640, H=480, f=525.0):
    return np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1.0]])


def render_sphere(T, K, W=640, H=480, noise=0.0, rng=None, centre=SPHERE_C, radius=SPHERE_R):
    """Depth image (H, W) of the sphere; inf where the ray misses."""
    jj, ii = np.meshgrid(np.arange(W), np.arange(H))
    d = np.stack([(jj - K[0, 2]) / K[0, 0], (ii - K[1, 2]) / K[1, 1], np.ones_like(jj, float)], -1)
    dw = d @ T[:3, :3].T                                       # not normalised: z_cam = 1
    o = T[:3, 3] - centre
    a = (dw * dw).sum(-1)
    b = 2 * dw @ o
    c = o @ o - radius**2
    disc = b * b - 4 * a * c
    with np.errstate(invalid="ignore"):
        t = (-b - np.sqrt(disc)) / (2 * a)
    z = np.where((disc >= 0) & (t > 0), t, np.inf)
    if noise:
        z = z + rng.normal(0, noise, z.shape) * np.isfinite(z)
    return z


def sphere_sdf(p, centre=SPHERE_C, radius=SPHERE_R):
    return np.linalg.norm(p - centre, axis=1) - radius


def orbit_poses(n, dist=0.6, height=0.15):
    """Camera poses on a circle around the sphere, looking at its centre."""
    out = []
    for k in range(n):
        a = 2 * np.pi * k / n
        eye = SPHERE_C + np.array([dist * np.cos(a), dist * np.sin(a), height])
        out.append(look_at(eye, SPHERE_C))
    return out


# -- 3D box (a small cube by default) -----------------------------------------------------------
BOX_C = np.array([0.0, 0.0, 0.0])
BOX_HALF = np.array([0.0225, 0.0225, 0.0225])     # the 4.5 cm cube of object_orbit


def render_box(T, K, W=640, H=480, centre=BOX_C, half=BOX_HALF):
    """Depth image (H, W) of an axis-aligned box (slab ray casting); inf where the ray misses."""
    jj, ii = np.meshgrid(np.arange(W), np.arange(H))
    d = np.stack([(jj - K[0, 2]) / K[0, 0], (ii - K[1, 2]) / K[1, 1], np.ones_like(jj, float)], -1)
    dw = d @ T[:3, :3].T                                       # not normalised: z_cam = 1
    o = T[:3, 3] - centre
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - o) / dw
        t2 = (half - o) / dw
    tn = np.nanmax(np.minimum(t1, t2), -1)
    tf = np.nanmin(np.maximum(t1, t2), -1)
    return np.where((tn <= tf) & (tn > 0), tn, np.inf)


def box_sdf(p, centre=BOX_C, half=BOX_HALF):
    """Exact signed distance (n,) to the box, positive outside."""
    q = np.abs(p - centre) - half
    out = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    return out + np.minimum(q.max(1), 0.0)


def observed_2d(points, poses, behind=0.3, fov=np.deg2rad(135.0), offset=(0.0, 0.0), max_range=30.0):
    """True where some scan saw the point: inside the field of view, at most ``behind`` metres
    behind the first surface along the ray from the laser (so free space and thin bands on
    both sides of observed surfaces count; occluded space does not)."""
    seen = np.zeros(len(points), bool)
    for x, y, th in poses:
        c, s = np.cos(th), np.sin(th)
        o = np.array([x + c * offset[0] - s * offset[1], y + s * offset[0] + c * offset[1]])
        v = points - o
        r = np.linalg.norm(v, axis=1)
        bearing = np.arctan2(v[:, 1], v[:, 0]) - th
        bearing = (bearing + np.pi) % (2 * np.pi) - np.pi
        ok = (np.abs(bearing) <= fov) & (r > 1e-9) & (r < max_range)
        d = v[ok] / r[ok, None]
        hit = ray_cast_2d(o, d)
        seen[np.nonzero(ok)[0][hit >= r[ok] - behind]] = True
    return seen


def observed_hits_2d(poses, step_deg=0.1, offset=(0.0, 0.0), fov_deg=135.0):
    """Dense points of the true surfaces that the laser hit from ``poses`` (fine angular step)."""
    a = np.deg2rad(np.arange(-fov_deg, fov_deg, step_deg))
    out = []
    for x, y, th in poses:
        c, s = np.cos(th), np.sin(th)
        o = np.array([x + c * offset[0] - s * offset[1], y + s * offset[0] + c * offset[1]])
        d = np.stack([np.cos(th + a), np.sin(th + a)], 1)
        r = ray_cast_2d(o, d)
        out.append(o + r[:, None] * d)
    return np.vstack(out)


def eval_sets_2d(points, poses, tol=0.02):
    """Masks (near, far) of the issue's 2D metrics: observed points within 0.3 m of an observed
    surface, and observed free points 0.3-2 m from the nearest surface, which was observed."""
    from scipy.spatial import cKDTree

    gt = sdf_2d(points)
    seen = observed_2d(points, poses)
    d_obs = cKDTree(observed_hits_2d(poses)).query(points)[0]
    nearest_seen = d_obs <= np.abs(gt) + tol
    near = seen & nearest_seen & (np.abs(gt) < 0.3)
    far = seen & nearest_seen & (gt > 0.3) & (gt < 2.0)
    return near, far
