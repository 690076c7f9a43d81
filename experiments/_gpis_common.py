"""Shared pieces of the GPIS-chapter experiments (not an experiment itself: the leading underscore
keeps it out of ``polar-sim list``).

- :func:`route` plans a seeded drive through ``office2d`` rooms via the doors, on the exact
  clearance map (``World.sdf``), and :func:`drive` follows it with the kinematic rover, recording
  true sensor poses, noisy scans and the noise-free scans of the same instants.
- :class:`Observation` defines what "observed" means for the 2D figures (see its docstring);
  :func:`score_sdf_2d`, :func:`score_surface_2d` and :func:`classify_worst` score a map with it.
- :func:`exact_grad` is the gradient of the exact SDF by central differences.

Everything is seeded; the same arguments give the same arrays bit for bit.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from polar_sim.geometry import T_to_pose2d

__all__ = ["Drive", "route", "drive", "office_world", "exact_grad", "load_now",
           "Follower", "clearance_map", "Observation", "corners", "scan_counts", "orbit_capture", "score_3d",
           "eval_points_2d", "score_sdf_2d", "score_surface_2d", "classify_worst", "polyline_points"]

LIDAR_SIGMA = 0.01          # issue 3: 2D lidar noise sigma 1 cm
ROBOT_CLEARANCE = 0.45      # m, clearance below which a route cell costs 1e6 (crossed only in doors)


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
    minimum-cost path, cost growing near obstacles and 1e6 per cell within ``ROBOT_CLEARANCE``,
    which only the narrowest doors force: 0.75 m wide, 0.375 m clearance at their centre) goes
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


class Observation:
    """What the noise-free beams of a drive observed; defines "observed" for every 2D figure.

    The definition uses the beams only, never a map:

    - ``crossed(P)``: P lies in a 2 cm cell that a beam crossed or ended in (observed free space
      and the observed surface);
    - ``reached(P)``: the same with every beam lengthened by ``behind`` (0.3 m): P is observed
      free space or at most 0.3 m behind an observed surface point, along a beam;
    - ``nearest_hit(P, gt)``: the true surface point nearest to P was hit by a beam: some beam end
      point lies within ``|gt| + tol`` of P (``tol`` = 3 cm covers the gap between 0.25 deg beams
      up to about 12 m). This drops, e.g., points inside or beyond a wall whose far face no beam
      reached;
    - ``hits``: the noise-free beam end points, a dense sampling of the observed true surface;
    - ``count(Q)``: how many scans hit within about 7 cm of surface points Q (:func:`scan_counts`).
    """

    def __init__(self, d: Drive, *, tol=0.03, behind=0.3):
        from scipy.spatial import cKDTree

        self.tol, self.behind = float(tol), float(behind)
        self.hits = hit_points(d.angles, d.poses, d.clean)
        b = d.poses[:, :2]
        lo = np.minimum(self.hits.min(0), b.min(0)) - behind - 0.1
        hi = np.maximum(self.hits.max(0), b.max(0)) + behind + 0.1
        bounds = (lo[0], lo[1], hi[0], hi[1])
        self._crossed = beam_grid(d.angles, d.poses, d.clean, bounds=bounds)
        self._reached = beam_grid(d.angles, d.poses, d.clean, extend=behind, bounds=bounds)
        self._kd = cKDTree(self.hits)
        self.count = scan_counts(d)

    def crossed(self, P):
        return _known(self._crossed, P)

    def reached(self, P):
        return _known(self._reached, P)

    def nearest_hit(self, P, gt):
        return self._kd.query(P)[0] <= np.abs(gt) + self.tol

    def sets(self, P, gt):
        """Masks ``near`` = reached & nearest_hit & |gt| < 0.3 m (the SDF and gradient set
        "within 0.3 m of the observed walls", both sides) and ``far`` = crossed & nearest_hit &
        0.3 < gt < 2 m ("observed free space 0.3-2 m from the nearest wall")."""
        nh = self.nearest_hit(P, gt)
        return {"near": self.reached(P) & nh & (np.abs(gt) < 0.3),
                "far": self.crossed(P) & nh & (gt > 0.3) & (gt < 2.0)}


def eval_points_2d(world, obs: Observation, n, seed, margin=0.5):
    """``n`` uniform points over the box of the observed surface (plus ``margin``), with the exact
    SDF ``gt``, its exact gradient ``G`` and the masks ``near``/``far`` (:meth:`Observation.sets`)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 3131]))
    lo, hi = obs.hits.min(0) - margin, obs.hits.max(0) + margin
    P = rng.uniform(lo, hi, (int(n), 2))
    gt = world.sdf(P)
    out = {"P": P, "gt": gt}
    out.update(obs.sets(P, gt))
    G = np.zeros_like(P)
    sel = out["near"] | out["far"]
    G[sel] = exact_grad(world, P[sel])   # the angles and the near-set split need it there only
    out["G"] = G
    return out


def score_sdf_2d(m, E):
    """SDF and gradient errors of a map ``m`` (anything with ``query``) on evaluation points
    :func:`eval_points_2d`: RMSE / median / p90 of |SDF error| on ``near``, mean on ``far``, the
    median gradient angle on each (medial-axis points, where the exact gradient has norm < 0.5 by
    central differences, are left out of the angles)."""
    sd, g, _ = m.query(E["P"])
    e = sd - E["gt"]
    near, far = E["near"], E["far"]
    ok = np.linalg.norm(E["G"], axis=1) > 0.5
    ang = angle_deg(g, E["G"])
    a = np.abs(e)
    return {"near_rmse_m": float(np.sqrt(np.mean(e[near] ** 2))), "near_median_abs_m": float(np.median(a[near])),
            "near_p90_abs_m": float(np.percentile(a[near], 90)), "far_mae_m": float(a[far].mean()),
            "far_median_abs_m": float(np.median(a[far])),
            "grad_near_median_deg": float(np.median(ang[near & ok])), "grad_far_median_deg": float(np.median(ang[far & ok])),
            "n_near": int(near.sum()), "n_far": int(far.sum())}, e


def polyline_points(lines, spacing=0.01):
    """Points every ``spacing`` metres along a list of polylines (k, 2)."""
    from polar_sim.metrics import sample_polyline

    pts = [sample_polyline(ln, spacing) for ln in lines if len(ln) >= 2]
    return np.vstack(pts) if pts else np.zeros((0, 2))


def score_surface_2d(world, est, obs: Observation, well_k=None):
    """Surface errors of estimated surface points ``est`` (m, 2) against the exact geometry.

    - surface -> truth: |exact SDF| at the estimated points inside the observed area
      (``obs.reached``); its RMS is the *surface RMSE*, its max the directed Hausdorff distance;
    - truth -> surface: distance from every observed true surface point (noise-free beam end
      point) to the nearest estimated point;
    - *Hausdorff* = the larger of the two maxima;
    - with ``well_k``: ``hausdorff_wellseen_m``, the same restricted to the part of the surface hit
      by at least ``well_k`` scans (true points, and estimated points within ~7 cm of such).

    Returns (metrics, details) where details holds the per-point errors for
    :func:`classify_worst`.
    """
    from scipy.spatial import cKDTree

    est = est[obs.reached(est)] if len(est) else est
    if len(est) == 0:
        nan = float("nan")
        return {"surface_rmse_m": nan, "hausdorff_m": nan, "h_est_to_true_m": nan, "h_true_to_est_m": nan,
                "n_surface_points": 0}, None
    dA = np.abs(world.sdf(est))
    dB = cKDTree(est).query(obs.hits)[0]
    m = {"surface_rmse_m": float(np.sqrt(np.mean(dA ** 2))), "h_est_to_true_m": float(dA.max()),
         "h_true_to_est_m": float(dB.max()), "hausdorff_m": float(max(dA.max(), dB.max())),
         "p99_est_to_true_m": float(np.percentile(dA, 99)), "p99_true_to_est_m": float(np.percentile(dB, 99)),
         "n_surface_points": int(len(est))}
    if well_k is not None:
        # the same on the well-seen part: surface within ~7 cm of true points hit by >= well_k scans
        wa = obs.count(est) >= well_k
        wb = obs.count(obs.hits) >= well_k
        ha = float(dA[wa].max()) if wa.any() else 0.0
        hb = float(dB[wb].max()) if wb.any() else 0.0
        m.update(hausdorff_wellseen_m=max(ha, hb), surface_rmse_wellseen_m=float(np.sqrt(np.mean(dA[wa] ** 2)))
                 if wa.any() else float("nan"))
    return m, {"est": est, "dA": dA, "dB": dB}


def classify_worst(world, details, obs: Observation, corner_pts, *, top=0.01, corner_r=0.3, sparse_k=3):
    """Where the worst surface errors are: the top ``top`` fraction of both directed errors of
    :func:`score_surface_2d`, each located at its true surface point (an estimated point is
    moved onto the true surface along the exact gradient; an observed true point is itself) and
    classified as ``corner`` (within ``corner_r`` of a true corner, :func:`corners`), ``sparse``
    (hit by fewer than ``sparse_k`` scans; the experiments use the number of scans taken over
    1 m of travel, at least 2: "seen from less than a metre of the drive") or ``wall`` (a
    well-seen flat stretch).

    Returns the shares of each class and the located worst points (k, 2) with their class.
    """
    from scipy.spatial import cKDTree

    if details is None:
        return {"worst_corner_share": float("nan"), "worst_sparse_share": float("nan"),
                "worst_wall_share": float("nan")}, (np.zeros((0, 2)), np.zeros(0, int))
    est, dA, dB = details["est"], details["dA"], details["dB"]
    kA = max(1, int(np.ceil(top * len(dA))))
    kB = max(1, int(np.ceil(top * len(dB))))
    ia = np.argsort(-dA)[:kA]
    ib = np.argsort(-dB)[:kB]
    qa = est[ia]
    sd = world.sdf(qa)
    g = exact_grad(world, qa)
    g /= np.maximum(np.linalg.norm(g, axis=1), 1e-9)[:, None]
    qa = qa - sd[:, None] * g
    q = np.vstack([qa, obs.hits[ib]])
    dc = cKDTree(corner_pts).query(q)[0] if len(corner_pts) else np.full(len(q), np.inf)
    cnt = obs.count(q)
    cls = np.where(dc < corner_r, 0, np.where(cnt < sparse_k, 1, 2))
    n = len(cls)
    return {"worst_corner_share": float(np.mean(cls == 0)), "worst_sparse_share": float(np.mean(cls == 1)),
            "worst_wall_share": float(np.mean(cls == 2))}, (q, cls)


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


# -- 3D: an RGB-D orbit around one object ----------------------------------------------------------
@dataclasses.dataclass
class Orbit:
    """Masked depth frames of one object: per frame the noisy depth (inf off the object), K, the
    camera pose, and the noise-free back-projected object points (the observed true surface)."""

    name: str
    depths: list
    Ks: list
    poses: list
    observed: np.ndarray        # (m, 3) noise-free object points seen by some pixel, world frame
    mesh: object                # trimesh.Trimesh of the object in the world frame
    render_s: float


def orbit_capture(world, n_frames, seed, *, turns=1.0):
    """Render ``n_frames`` RGB-D frames spread over ``turns`` orbits of ``object_orbit``.

    The depth is masked to the object with the exact labels (as the published BigBird demo uses
    masked depth) and corrupted with Kinect-like :class:`DepthNoise`, seeded by ``seed``.
    """
    import time

    from polar_sim.sim import LABELS
    from polar_sim.sim.sensors import DepthNoise

    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 5151]))
    noise = DepthNoise()
    name = world.meta["target"]
    period = float(world.meta["script"].period)
    steps = max(1, int(round(turns * period / world.dt / n_frames)))
    depths, Ks, poses, obs = [], [], [], []
    t_render = 0.0
    for k in range(n_frames):
        if k:
            for _ in range(steps):
                world.step()
        t0 = time.perf_counter()
        f = world.camera("rgbd")
        t_render += time.perf_counter() - t0
        mask = f.labels == LABELS["target"]
        _, dn = noise.apply(f.rgb, f.depth, f.K[0, 0], rng)
        depths.append(np.where(mask, dn, np.inf).astype(np.float64))
        Ks.append(f.K.copy())
        poses.append(f.T_world_cam.copy())
        z = np.where(mask, f.depth, np.inf).astype(np.float64)
        H, W = z.shape
        v, u = np.mgrid[0:H, 0:W]
        ok = np.isfinite(z)
        pc = np.stack([(u - f.K[0, 2]) / f.K[0, 0] * z, (v - f.K[1, 2]) / f.K[1, 1] * z, z], -1)[ok]
        obs.append(pc @ f.T_world_cam[:3, :3].T + f.T_world_cam[:3, 3])
    mesh = world.object_mesh(name)
    mesh.apply_transform(world.truth()["objects"][name])
    return Orbit(name, depths, Ks, poses, np.vstack(obs), mesh, t_render)


def score_3d(world, m, orbit, *, n_eval=4000, seed=0, seen_tol=0.002):
    """Accuracy of a 3D map ``m`` of the orbited object against the exact geometry.

    - SDF: points within 1 cm of the true surface, offset along the true normal from uniform
      samples of the object's mesh, whose mesh point was observed (a noise-free object pixel
      within ``seen_tol`` = 2 mm), and whose nearest static surface is the object itself
      (``World.nearest_surface``); ground truth ``World.sdf``.
    - Surface: ``m.surface()`` (marching cubes), on its observed part: the vertices whose
      nearest true mesh point was seen (within ``seen_tol``; the unseen underside is closed by
      the map with a guess). Directed mean distance surface -> true mesh (exact point-to-mesh
      distance of each such vertex), and observed true mesh -> surface (uniform mesh samples to
      dense samples of the reconstruction); Chamfer = their mean (``metrics.chamfer``'s
      definition). ``surface_to_mesh_all_m`` is the first figure over every vertex.
    - Normals: angle between the map's gradient at each observed reconstructed vertex and the
      true face normal at its nearest true mesh point.
    """
    import trimesh
    from scipy.spatial import cKDTree

    from polar_sim.sim import LABELS

    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 6161]))
    mesh = orbit.mesh
    pts, fi = trimesh.sample.sample_surface(mesh, n_eval, seed=int(rng.integers(2**31)))
    nrm = mesh.face_normals[fi]
    seen = cKDTree(orbit.observed).query(pts)[0] <= seen_tol
    P = pts + rng.uniform(-0.01, 0.01, len(pts))[:, None] * nrm
    gt = world.sdf(P)
    own = world.nearest_surface(P) == LABELS["target"]
    sel = seen & own & (np.abs(gt) < 0.01)
    d, g, _ = m.query(P[sel])
    e = d - gt[sel]
    S = m.surface()
    out = {"n_sdf_points": int(sel.sum()), "seen_fraction": float(seen.mean()),
           "sdf_rmse_m": float(np.sqrt(np.mean(e * e))) if len(e) else float("nan"),
           "sdf_median_abs_m": float(np.median(np.abs(e))) if len(e) else float("nan"),
           "sdf_p90_abs_m": float(np.percentile(np.abs(e), 90)) if len(e) else float("nan")}
    if len(S.faces) == 0:
        out.update(n_vertices=0, chamfer_m=float("nan"), surface_to_mesh_m=float("nan"),
                   mesh_to_surface_m=float("nan"), normal_median_deg=float("nan"), normal_mean_deg=float("nan"))
        return out, S
    V = np.asarray(S.vertices)
    cp, dA_all, tri = trimesh.proximity.closest_point(mesh, V)
    # the observed part of the reconstruction: vertices whose nearest true point was seen
    vis = cKDTree(orbit.observed).query(cp)[0] <= seen_tol
    dA = dA_all[vis]
    dense = np.vstack([V, np.asarray(trimesh.sample.sample_surface(S, 100_000, seed=1)[0])])
    dB = cKDTree(dense).query(pts[seen])[0]
    gv = m.query(V[vis])[1]
    ang = angle_deg(gv, mesh.face_normals[tri[vis]])
    out.update(n_vertices=int(len(V)), n_vertices_observed=int(vis.sum()), surface_to_mesh_m=float(dA.mean()),
               mesh_to_surface_m=float(dB.mean()), chamfer_m=float(0.5 * (dA.mean() + dB.mean())),
               surface_to_mesh_max_m=float(dA.max()), surface_to_mesh_all_m=float(dA_all.mean()),
               normal_median_deg=float(np.median(ang)), normal_mean_deg=float(np.mean(ang)),
               normal_p90_deg=float(np.percentile(ang, 90)))
    return out, S
