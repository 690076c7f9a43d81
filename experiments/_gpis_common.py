"""Shared pieces of the GPIS-chapter experiments (not an experiment itself: the leading underscore
keeps it out of ``polar-sim list``).

- :func:`route` plans a seeded drive through ``office2d`` rooms via the doors, on the exact
  clearance map (``World.sdf``), and :func:`drive` follows it with the kinematic rover, recording
  true sensor poses, noisy scans and the noise-free scans of the same instants.
- :func:`observed_sets` defines what "observed" means for the accuracy figures (see its docstring).
- :func:`exact_grad` is the gradient of the exact SDF by central differences.

Everything is seeded; the same arguments give the same arrays bit for bit.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from polar_sim.geometry import T_to_pose2d

__all__ = ["Drive", "route", "drive", "office_world", "observed_sets", "exact_grad", "load_now",
           "Follower", "clearance_map"]

LIDAR_SIGMA = 0.01          # issue 3: 2D lidar noise sigma 1 cm
ROBOT_CLEARANCE = 0.45      # m, hard clearance of planned routes (doors leave 0.6 m)


def load_now():
    """1-minute load average (context for every timing)."""
    try:
        return float(os.getloadavg()[0])
    except OSError:  # pragma: no cover
        return float("nan")


def office_world(seed, *, noise=True, **options):
    """``World("office2d", seed, kinematic=True)`` with 1 cm lidar noise (or none)."""
    from polar_sim.sim import World
    from polar_sim.sim.sensors import RangeNoise

    nz = {"lidar": RangeNoise(sigma=LIDAR_SIGMA)} if noise else None
    return World("office2d", seed=seed, kinematic=True, noise=nz, **options)


def clearance_map(world, res=0.1, bounds=None):
    """Exact clearance (signed distance) on a grid over the scene: (xs, ys, C[ix, iy])."""
    x0, x1, y0, y1 = bounds if bounds is not None else world.meta["bounds"]
    xs = np.arange(x0 + res / 2, x1, res)
    ys = np.arange(y0 + res / 2, y1, res)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    C = world.sdf(np.column_stack([X.ravel(), Y.ravel()])).reshape(X.shape)
    return xs, ys, C


def route(world, seed, *, n_rooms=5, start=None, clearance=None, res=0.1):
    """A seeded route (n, 2) through the rooms of ``office2d``, 0.1 m between points.

    The rooms are visited in a seeded random order, each at a random point with at least 0.9 m
    clearance; between them the cheapest path on the exact clearance map (``skimage.graph``
    minimum-cost path, cost growing near obstacles, forbidden within ``ROBOT_CLEARANCE``) goes
    through the doors. The path is smoothed (Gaussian, 0.3 m). ``n_rooms`` rooms are visited
    (repeating the order if more than 5).
    """
    from scipy.ndimage import gaussian_filter1d
    from skimage.graph import route_through_array

    from polar_sim.sim.office import ROOMS

    if clearance is None:
        clearance = clearance_map(world, res)
    xs, ys, C = clearance
    cost = np.where(C > ROBOT_CLEARANCE, 1.0 + 5.0 * np.clip(1.2 - C, 0.0, None), 1e6)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 4242]))

    def ij(p):
        return (int(np.clip(np.round((p[0] - xs[0]) / res), 0, len(xs) - 1)),
                int(np.clip(np.round((p[1] - ys[0]) / res), 0, len(ys) - 1)))

    start = np.asarray(world.meta["start_pose2d"][:2] if start is None else start, float)
    pts = [start]
    names = list(ROOMS)
    order = []
    while len(order) < n_rooms:
        order += [names[i] for i in rng.permutation(len(names))]
    for name in order[:n_rooms]:
        x0, x1, y0, y1 = ROOMS[name]
        for _ in range(200):
            goal = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)])
            if C[ij(goal)] > 0.9:
                break
        idx, _ = route_through_array(cost, ij(pts[-1]), ij(goal), fully_connected=True, geometric=True)
        idx = np.asarray(idx)
        pts += list(np.column_stack([xs[idx[:, 0]], ys[idx[:, 1]]])[1:])
    p = np.asarray(pts)
    return np.column_stack([gaussian_filter1d(p[:, 0], 3, mode="nearest"),
                            gaussian_filter1d(p[:, 1], 3, mode="nearest")])


class Follower:
    """Forward-only path follower for a unicycle: pure pursuit on a point ``lookahead`` metres
    ahead along the path (progress never goes back, so routes that pass near themselves are safe);
    slows down and turns on the spot when the target is behind."""

    def __init__(self, path, lookahead=0.5, max_yaw_rate=2.0):
        self.path = np.asarray(path, float)
        self.i = 0
        self.lookahead = float(lookahead)
        self.max_yaw_rate = float(max_yaw_rate)

    @property
    def done(self):
        return self.i >= len(self.path) - 1

    def __call__(self, pose, vmax):
        x, y, th = pose
        while self.i < len(self.path) - 1 and np.hypot(*(self.path[self.i] - (x, y))) < self.lookahead:
            self.i += 1
        dx, dy = self.path[self.i] - (x, y)
        a = (np.arctan2(dy, dx) - th + np.pi) % (2 * np.pi) - np.pi
        v = max(vmax * max(0.0, np.cos(a)) ** 2, 0.05)
        if abs(a) < np.pi / 3:
            om = 2.0 * v * np.sin(a) / max(np.hypot(dx, dy), 1e-6)
        else:
            om = np.sign(a) * self.max_yaw_rate
        return float(v), float(np.clip(om, -self.max_yaw_rate, self.max_yaw_rate))


@dataclasses.dataclass
class Drive:
    """A recorded drive: per scan the true sensor pose (x, y, theta), the noisy and the noise-free
    ranges (same instant), the beam angles, and the true travelled distance at each scan."""

    angles: np.ndarray          # (n_beams,)
    poses: np.ndarray           # (n, 3) true lidar pose in the world
    ranges: np.ndarray          # (n, n_beams) with noise (inf = no return)
    clean: np.ndarray           # (n, n_beams) without noise
    travelled: np.ndarray       # (n,) m
    base_poses: np.ndarray      # (n, 3) true robot base pose


def drive(world, path, *, duration=60.0, speed=1.0, every_m=None, every_steps=1, lookahead=0.5):
    """Follow ``path`` with the kinematic rover for ``duration`` seconds at up to ``speed`` m/s.

    A scan is taken every ``every_steps`` control steps, or (when ``every_m`` is given) each
    time the rover has travelled ``every_m`` metres since the last scan, plus one at the start.
    Stops early at the end of the path. Returns a :class:`Drive`.
    """
    follow = Follower(path, lookahead)
    n_steps = int(round(duration / world.dt))
    angles = None
    poses, noisy, clean, trav, base = [], [], [], [], []
    dist, last = 0.0, -np.inf
    prev = world.truth()["robot_pose2d"]
    for k in range(n_steps + 1):
        if k:
            world.step(follow(prev, speed))
            cur = world.truth()["robot_pose2d"]
            dist += float(np.hypot(*(cur[:2] - prev[:2])))
            prev = cur
        take = (dist - last >= every_m - 1e-9) if every_m is not None else (k % every_steps == 0)
        if k == 0 or take:
            last = dist
            s = world.lidar("lidar")
            noise = world._noise.get("lidar")
            world.set_noise("lidar", None)
            c = world.lidar("lidar")
            if noise is not None:
                world.set_noise("lidar", noise)
            angles = s.angles
            poses.append(T_to_pose2d(s.T_world_sensor))
            noisy.append(s.ranges)
            clean.append(c.ranges)
            trav.append(dist)
            base.append(prev.copy())
        if follow.done:
            break
    return Drive(np.asarray(angles), np.asarray(poses), np.asarray(noisy), np.asarray(clean),
                 np.asarray(trav), np.asarray(base))


def hit_points(angles, poses, ranges, max_range=30.0):
    """World end points (m, 2) of the valid returns of scans taken at sensor poses (n, 3)."""
    out = []
    for p, r in zip(poses, ranges):
        ok = np.isfinite(r) & (r < max_range)
        a = angles[ok] + p[2]
        out.append(np.column_stack([p[0] + r[ok] * np.cos(a), p[1] + r[ok] * np.sin(a)]))
    return np.vstack(out) if out else np.zeros((0, 2))


def beam_grid(angles, poses, ranges, *, extend=0.0, cell=0.02, bounds=None):
    """Occupancy grid (2 cm) of the beams, each lengthened by ``extend`` metres: its known cells
    (free or occupied) are the cells some beam crossed or ended in."""
    from polar_sim.baselines import OccupancyGrid2D

    g = OccupancyGrid2D(cell_size=cell, bounds=bounds)
    for p, r in zip(poses, ranges):
        g.update(angles, r + extend, p)
    return g


def _known(grid, P):
    idx = np.floor((P - grid.origin_) / grid.cell_size).astype(np.int64)
    nx, ny = grid.log_odds_.shape
    inside = (idx[:, 0] >= 0) & (idx[:, 0] < nx) & (idx[:, 1] >= 0) & (idx[:, 1] < ny)
    out = np.zeros(len(P), bool)
    out[inside] = grid.log_odds_[idx[inside, 0], idx[inside, 1]] != 0
    return out


def observed_sets(d: Drive, P, gt, *, tol=0.03, behind=0.3):
    """Masks of evaluation points P (n, 2) with exact SDF ``gt`` (n,), from the noise-free beams.

    "Observed" is defined from what the beams did, never from the map:

    - ``crossed``: P lies in a 2 cm cell that a beam crossed or ended in;
    - ``reached``: the same with every beam lengthened by ``behind`` (0.3 m): P is in observed free
      space or at most 0.3 m behind an observed surface, along a beam;
    - ``nearest_hit``: the true surface point nearest to P was hit by a beam: some beam end point
      lies within ``|gt| + tol`` of P (``tol`` 3 cm covers the spacing of the 0.25 deg beams up
      to about 12 m). This drops, e.g., points inside or beyond a wall whose far face nobody saw.

    Returns a dict of masks: ``near`` = reached & nearest_hit & |gt| < 0.3 (the SDF and gradient
    set "within 0.3 m of observed walls", both sides); ``far`` = crossed & nearest_hit &
    0.3 < gt < 2 ("observed free space 0.3-2 m from the nearest wall"); and the raw masks.
    """
    from scipy.spatial import cKDTree

    b = d.poses
    # The grids only need to span what the beams reached.
    hits = hit_points(d.angles, d.poses, d.clean)
    lo = np.minimum(hits.min(0), b[:, :2].min(0)) - behind - 0.1
    hi = np.maximum(hits.max(0), b[:, :2].max(0)) + behind + 0.1
    bounds = (lo[0], lo[1], hi[0], hi[1])
    crossed = _known(beam_grid(d.angles, d.poses, d.clean, bounds=bounds), P)
    reached = _known(beam_grid(d.angles, d.poses, d.clean, extend=behind, bounds=bounds), P)
    d_hit = cKDTree(hits).query(P)[0]
    nearest_hit = d_hit <= np.abs(gt) + tol
    near = reached & nearest_hit & (np.abs(gt) < 0.3)
    far = crossed & nearest_hit & (gt > 0.3) & (gt < 2.0)
    return {"near": near, "far": far, "crossed": crossed, "reached": reached, "nearest_hit": nearest_hit,
            "hits": hits}


def exact_grad(world, P, h=1e-4):
    """Gradient (n, 2) of the exact 2D SDF by central differences."""
    dx = np.array([h, 0.0])
    dy = np.array([0.0, h])
    gx = (world.sdf(P + dx) - world.sdf(P - dx)) / (2 * h)
    gy = (world.sdf(P + dy) - world.sdf(P - dy)) / (2 * h)
    return np.column_stack([gx, gy])


def angle_deg(a, b):
    """Angle (n,) in degrees between the rows of a and b (n, 2|3)."""
    na = np.linalg.norm(a, axis=1)
    nb = np.linalg.norm(b, axis=1)
    c = np.einsum("ij,ij->i", a, b) / np.maximum(na * nb, 1e-300)
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def corners(world):
    """Corner points (m, 2) of the scene's section in the lidar plane: the vertices of every
    vertical box that the plane cuts (walls, desks, cabinets, shelves). Where boxes join (a wall
    junction), the concave corner lies within a wall thickness of such a vertex."""
    import mujoco

    from polar_sim.sim.truth import static_geoms

    m, dat = world.model, world.data
    z = world.lidar_plane_height()
    out = []
    for g in static_geoms(m):
        if m.geom_type[g] != mujoco.mjtGeom.mjGEOM_BOX:
            continue
        R = dat.geom_xmat[g].reshape(3, 3)
        x = dat.geom_xpos[g]
        s = m.geom_size[g]
        if abs(abs(R[2, 2]) - 1.0) > 1e-9 or abs(z - x[2]) >= s[2]:
            continue
        loc = np.array([[s[0], s[1]], [s[0], -s[1]], [-s[0], s[1]], [-s[0], -s[1]]])
        out.append(loc @ R[:2, :2].T + x[:2])
    return np.vstack(out) if out else np.zeros((0, 2))


def scan_counts(d: Drive, cell=0.05):
    """Per 5 cm cell of the plane, how many scans of the drive hit it: a function
    ``count(points (n, 2)) -> (n,)`` giving the largest count over the 3 x 3 cells around each
    point (so "hit by k scans" means within about 7 cm)."""
    keys = []
    for p, r in zip(d.poses, d.clean):
        ok = np.isfinite(r)
        a = d.angles[ok] + p[2]
        h = np.column_stack([p[0] + r[ok] * np.cos(a), p[1] + r[ok] * np.sin(a)])
        c = np.floor(h / cell).astype(np.int64)
        keys.append(np.unique(c[:, 0] * 1_000_003 + c[:, 1]))
    uk, cnt = np.unique(np.concatenate(keys) if keys else np.zeros(0, np.int64), return_counts=True)

    def count(points):
        c = np.floor(np.asarray(points) / cell).astype(np.int64)
        best = np.zeros(len(c), np.int64)
        if len(uk) == 0:
            return best
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                key = (c[:, 0] + dx) * 1_000_003 + (c[:, 1] + dy)
                j = np.clip(np.searchsorted(uk, key), 0, len(uk) - 1)
                best = np.maximum(best, np.where(uk[j] == key, cnt[j], 0))
        return best

    return count
