"""Recorded 2D lidar drives: seeded routes through ``office2d`` and ``warehouse2d``, followed by the
kinematic indoor rover, cached as recordings.

- :func:`plan_route` visits a scene's named regions (office2d: its rooms; warehouse2d: its
  aisles, main aisle, partition zone and yard) in a seeded random order, each at a random point
  with 0.9 m clearance, along the cheapest path on the exact clearance map (``World.sdf``);
- :func:`drive` follows a path (:class:`polar_sim.control.PurePursuit` on waypoints: forward only,
  slowing in turns, on the spot when the target is behind) and takes scans: noisy and noise-free
  ranges of the same instant, the true sensor pose, the travelled distance;
- :func:`recorded_drives` records one or more legs in one world (a leg after the first starts from
  a reset world whose noise stream continues) through :mod:`polar_sim.sim.recorders.sequences`, so an
  experiment replays a drive without MuJoCo;
- :func:`snake_route` is the snake through a tiled office (``office2d`` with ``tiles=n``);
- :func:`section_corners` gives the corners of a scene's section in the lidar plane.

Everything is seeded: the same arguments give the same arrays bit for bit.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from polar_sim.control import PurePursuit
from polar_sim.geometry import T_to_pose2d
from polar_sim.sim.meta import Office2DMeta, Warehouse2DMeta

__all__ = ["LIDAR_SIGMA", "ROBOT_CLEARANCE", "Drive", "lidar_world", "clearance_map", "plan_route", "drive",
           "recorded_drives", "snake_route", "section_corners", "regions"]

LIDAR_SIGMA = 0.01          # 2D lidar range noise of the GPIS experiments, m (issue 3)
ROBOT_CLEARANCE = 0.45      # m, clearance below which a route cell costs 1e6 (crossed only in doors)
_VERSION = 1                # bump when the recorded drives change


@dataclasses.dataclass
class Drive:
    """A recorded drive: per scan the true sensor pose (x, y, theta), the noisy and the noise-free
    ranges (same instant), the beam angles, the true travelled distance and the robot base pose."""

    angles: np.ndarray          # (n_beams,) rad
    poses: np.ndarray           # (n, 3) true lidar pose in the world, m, rad
    ranges: np.ndarray          # (n, n_beams) m, with noise (inf = no return)
    clean: np.ndarray           # (n, n_beams) m, without noise
    travelled: np.ndarray       # (n,) m
    base_poses: np.ndarray      # (n, 3) true robot base pose


def lidar_world(scene, seed, *, noise=True, **options):
    """``World(scene, seed, kinematic=True)`` with 1 cm lidar range noise (or none)."""
    from polar_sim.sim.sensors import RangeNoise
    from polar_sim.sim.world import World

    nz = {"lidar": RangeNoise(sigma=LIDAR_SIGMA)} if noise else None
    return World(scene, seed=seed, kinematic=True, noise=nz, **options)


def regions(world):
    """The named regions (x0, x1, y0, y1) a route visits: office2d's rooms, warehouse2d's regions."""
    meta = world.meta
    if isinstance(meta, Warehouse2DMeta):
        return dict(meta.regions)
    if isinstance(meta, Office2DMeta):
        return dict(meta.rooms)
    raise ValueError(f"world: scene {world.scene!r} has no rooms or regions to plan a route through")


def clearance_map(world, res=0.1, bounds=None):
    """Exact clearance (signed distance) on a grid over the scene: ``(xs, ys, C[ix, iy])``, m."""
    x0, x1, y0, y1 = bounds if bounds is not None else world.meta.bounds
    xs = np.arange(x0 + res / 2, x1, res)
    ys = np.arange(y0 + res / 2, y1, res)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    C = world.sdf(np.column_stack([X.ravel(), Y.ravel()])).reshape(X.shape)
    return xs, ys, C


def plan_route(world, seed, *, n_rooms=5, start=None, clearance=None, res=0.1):
    """A seeded route (n, 2) through the regions of the scene, 0.1 m between points.

    The regions (:func:`regions`) are visited in a seeded random order, each at a random point with
    at least 0.9 m clearance (or the region's largest clearance less 5 cm, in a narrower aisle);
    between them the cheapest path on the exact clearance map (``skimage.graph`` minimum-cost
    path; the cost grows near obstacles and is 1e6 per cell within ``ROBOT_CLEARANCE``, which only
    the narrowest doors force) goes through the doors. The path is smoothed (Gaussian, 0.3 m).
    ``n_rooms`` regions are visited (repeating the order if there are fewer).
    """
    from scipy.ndimage import gaussian_filter1d
    from skimage.graph import route_through_array

    if clearance is None:
        clearance = clearance_map(world, res)
    xs, ys, C = clearance
    cost = np.where(C > ROBOT_CLEARANCE, 1.0 + 5.0 * np.clip(1.2 - C, 0.0, None), 1e6)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 4242]))
    rooms = regions(world)

    def ij(p):
        return (int(np.clip(np.round((p[0] - xs[0]) / res), 0, len(xs) - 1)),
                int(np.clip(np.round((p[1] - ys[0]) / res), 0, len(ys) - 1)))

    start = np.asarray(world.meta.start_pose2d[:2] if start is None else start, float)
    pts = [start]
    names = list(rooms)
    order = []
    while len(order) < n_rooms:
        order += [names[i] for i in rng.permutation(len(names))]
    for name in order[:n_rooms]:
        x0, x1, y0, y1 = rooms[name]
        sel = (xs[:, None] >= x0) & (xs[:, None] <= x1) & (ys[None, :] >= y0) & (ys[None, :] <= y1)
        need = min(0.9, float(C[sel].max()) - 0.05) if sel.any() else 0.9
        for _ in range(200):
            goal = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)])
            if C[ij(goal)] > need:
                break
        idx, _ = route_through_array(cost, ij(pts[-1]), ij(goal), fully_connected=True, geometric=True)
        idx = np.asarray(idx)
        pts += list(np.column_stack([xs[idx[:, 0]], ys[idx[:, 1]]])[1:])
    p = np.asarray(pts)
    return np.column_stack([gaussian_filter1d(p[:, 0], 3, mode="nearest"),
                            gaussian_filter1d(p[:, 1], 3, mode="nearest")])


def drive(world, path, *, duration=60.0, speed=1.0, every_m=None, every_steps=1, lookahead=0.5, clean=True):
    """Follow ``path`` with the kinematic rover for ``duration`` seconds at up to ``speed`` m/s.

    A scan is taken every ``every_steps`` control steps, or (when ``every_m`` is given) each
    time the rover has travelled ``every_m`` metres since the last scan, plus one at the start.
    Stops early at the end of the path. ``clean=False`` skips the noise-free twin scans (their
    ranges are then NaN). Returns a :class:`Drive`.
    """
    follow = PurePursuit(path, lookahead, target="waypoint", max_yaw_rate=2.0, turn_in_place=np.pi / 3,
                         min_speed=0.05)
    n_steps = int(round(duration / world.dt))
    angles = None
    poses, noisy, twins, trav, base = [], [], [], [], []
    dist, last = 0.0, -np.inf
    prev = world.truth()["robot_pose2d"]
    for k in range(n_steps + 1):
        if k:
            world.step(follow.command(prev, speed))
            cur = world.truth()["robot_pose2d"]
            dist += float(np.hypot(*(cur[:2] - prev[:2])))
            prev = cur
        take = (dist - last >= every_m - 1e-9) if every_m is not None else (k % every_steps == 0)
        if k == 0 or take:
            last = dist
            s = world.lidar("lidar")
            if clean:
                # The twin scan without noise; switching the noise off draws nothing from its stream.
                noise = world._noise.get("lidar")
                world.set_noise("lidar", None)
                twins.append(world.lidar("lidar").ranges)
                if noise is not None:
                    world.set_noise("lidar", noise)
            else:
                twins.append(np.full(len(s.ranges), np.nan))
            angles = s.angles
            poses.append(T_to_pose2d(s.T_world_sensor))
            noisy.append(s.ranges)
            trav.append(dist)
            base.append(prev.copy())
        if follow.done:
            break
    return Drive(np.asarray(angles), np.asarray(poses), np.asarray(noisy), np.asarray(twins),
                 np.asarray(trav), np.asarray(base))


def _leg_path(world, leg, clearance):
    if leg.get("route") == "snake":
        return snake_route(world.meta.tiles)
    return plan_route(world, int(leg["route_seed"]), n_rooms=int(leg.get("n_rooms", 5)), clearance=clearance)


_LEG_KEYS = {"route", "route_seed", "n_rooms", "duration", "speed", "every_m", "every_steps", "lookahead", "clean"}


def recorded_drives(scene, seed, legs, *, noise=True, **options):
    """The drives ``legs`` in ``World(scene, seed, **options)``, recorded once and then replayed.

    Each leg is a dict: ``route_seed`` (int; the route :func:`plan_route` plans) and ``n_rooms``,
    or ``route="snake"`` (:func:`snake_route` of a tiled office); ``duration`` (s), ``speed``
    (m/s), ``every_m`` or ``every_steps``, ``lookahead`` (m), ``clean`` (bool), as in
    :func:`drive`. Leg k > 0 starts from the reset world (the rover at the start, the noise stream
    continuing). Returns a list of :class:`Drive`, one per leg. The recording is cached under
    ``$POLAR_SIM_CACHE/lidar_drive`` keyed by all of the above.
    """
    from polar_sim.sim.recorders import sequences
    from polar_sim.sim.recorders.recording import Recording

    legs = [dict(leg) for leg in legs]
    for leg in legs:
        bad = set(leg) - _LEG_KEYS
        if bad:
            raise ValueError(f"legs: unknown keys {sorted(bad)}; valid: {sorted(_LEG_KEYS)}")
    key = {"scene": scene, "seed": int(seed), "legs": legs, "noise": bool(noise),
           "options": {k: list(v) if isinstance(v, tuple) else v for k, v in sorted(options.items())}}

    def build():
        w = lidar_world(scene, seed, noise=noise, **options)
        clear = clearance_map(w) if any(leg.get("route") != "snake" for leg in legs) else None
        rec = None
        for j, leg in enumerate(legs):
            if j:
                w.reset()
            d = drive(w, _leg_path(w, leg, clear), duration=float(leg.get("duration", 60.0)),
                      speed=float(leg.get("speed", 1.0)), every_m=leg.get("every_m"),
                      every_steps=int(leg.get("every_steps", 1)), lookahead=float(leg.get("lookahead", 0.5)),
                      clean=bool(leg.get("clean", True)))
            if rec is None:
                rec = Recording(meta={"scene": scene, "seed": int(seed), "angles": d.angles.tolist()})
            for i in range(len(d.poses)):
                rec.append({"leg": np.int64(j), "pose": d.poses[i], "ranges": d.ranges[i], "clean": d.clean[i],
                            "travelled": np.float64(d.travelled[i]), "base_pose": d.base_poses[i]})
        w.close()
        return rec

    with sequences.cached("lidar_drive", key, build, version=_VERSION) as r:
        angles = np.asarray(r.meta["angles"], float)
        leg = r.stack("leg")
        cols = {k: r.stack(k) for k in ("pose", "ranges", "clean", "travelled", "base_pose")}
    return [Drive(angles, cols["pose"][leg == j], cols["ranges"][leg == j], cols["clean"][leg == j],
                  cols["travelled"][leg == j], cols["base_pose"][leg == j]) for j in range(len(legs))]


def snake_route(n, tile=30.0):
    """Waypoints (k, 2), 0.1 m apart, of the snake through an n x n tiled office: east along the
    corridor of the first row of tiles, north through an office, a door in the tile wall and a
    store room into the next row's corridor, west along it, and so on."""
    from polar_sim.sim.builders.office import LANE_X

    pts = [(-13.0, 0.0)]
    for j in range(n):
        y = tile * j
        east = j % 2 == 0
        if j == n - 1:
            pts.append((tile * (n - 1) + 13.0 if east else -13.0, y))
        else:
            x_lane = tile * (n - 1) + LANE_X if east else LANE_X
            pts += [(x_lane, y), (x_lane, y + tile)]
    p = np.asarray(pts, float)
    out = [p[0]]
    for a, b in zip(p[:-1], p[1:]):
        k = max(1, int(np.ceil(np.linalg.norm(b - a) / 0.1)))
        out += list(a + (b - a) * (np.arange(1, k + 1) / k)[:, None])
    return np.asarray(out)


def section_corners(world):
    """Corner points (m, 2) of the scene's section in the lidar plane.

    warehouse2d lists its corners (``meta.corners``: convex box vertices on the boundary and
    the concave corners). Otherwise: the vertices of every vertical box that the plane cuts
    (walls, desks, cabinets, shelves); where boxes join (a wall junction), the concave corner lies
    within a wall thickness of such a vertex.
    """
    import mujoco

    from polar_sim.sim.truth import static_geoms

    if isinstance(world.meta, Warehouse2DMeta):
        return np.asarray(world.meta.corners, float).copy()
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
