"""Rover route sequences for the ground chapter: a seeded driver, a KITTI-like camera, exact truth.

Each route drives the car-sized rover round its scene's closed route with pure pursuit at a
seeded, curvature-limited speed profile, and records at 10 Hz: the camera image rendered at
1242x376 with KITTI's focal length and reduced 2x by a Gaussian pyramid (621x188, as the ground
chapter processes KITTI), the true ground mask, the camera pose and twist, the central-difference
speed, the camera height above the terrain along the camera's down axis, and the coefficients of
the second-order ground surface seen by the camera.

Routes come in two splits (the held-out protocol): :data:`ROUTES` (``dev``, the ten routes every
parameter was chosen on, default appearance, plus one route of each dev appearance family) and
:data:`TEST_ROUTES` (``test``, seeds >= 10,000, every ground family but the dev-only ``pavers``,
including two never used while tuning). :func:`load_route` returns a lazy reader from the one recording cache
(:mod:`polar_sim.sim.recorders.sequences`), recording the route first if it is absent; recordings are
deterministic in the route's spec.
"""

from __future__ import annotations

import dataclasses

import cv2
import mujoco
import numpy as np

from polar_sim.control import PurePursuit
from polar_sim.progress import progress_bar
from polar_sim.sim.recorders import sequences
from polar_sim.sim.recorders.recording import Recording
from polar_sim.sim.truth import LABELS
from polar_sim.sim.world import World

__all__ = ["ROUTES", "TEST_ROUTES", "ROVER_SLIP", "SPLITS", "DEV_FAMILIES", "TEST_ONLY_FAMILIES", "DEV_ONLY_FAMILIES", "RouteSpec", "route_spec",
           "record_route", "load_route", "route_truth", "route_layout", "route_zones",
           "settled_frames", "KITTI_FOVY_DEG", "reduce2x", "RECORDER_VERSION"]

#: Vertical field of view that gives KITTI's f = 718.9 px at 376 rows.
KITTI_FOVY_DEG = float(np.degrees(2 * np.arctan(188.0 / 718.856)))
FULL_W, FULL_H = 1242, 376


@dataclasses.dataclass(frozen=True)
class RouteSpec:
    """A route: the scene and its seed, laps of the closed route, the speed range (m/s) and the
    scene's ``appearance`` option (None: the default look; a family name or "random":
    :mod:`polar_sim.sim.builders.rover_appearance`)."""

    scene: str
    seed: int
    laps: float
    v_min: float
    v_max: float
    appearance: str | None = None


#: The ``dev`` split. Ten routes of 500-2000 m at 5-12 m/s: six over hills, four on flat ground, the
#: default appearance (one lap of the closed route is 475-490 m, so the single-lap routes drive 1.1
#: laps to reach 500 m). Then one route of each dev appearance family (four zones of the family).
ROUTES = {
    "terrain_00": RouteSpec("rover_terrain", 0, 1.1, 5.0, 9.0),
    "terrain_01": RouteSpec("rover_terrain", 1, 2.0, 6.0, 11.0),
    "terrain_02": RouteSpec("rover_terrain", 2, 1.5, 5.0, 8.0),
    "terrain_03": RouteSpec("rover_terrain", 3, 3.5, 8.0, 12.0),
    "terrain_04": RouteSpec("rover_terrain", 4, 1.1, 7.0, 12.0),
    "terrain_05": RouteSpec("rover_terrain", 5, 2.5, 6.0, 10.0),
    "flat_00": RouteSpec("rover_flat", 10, 1.1, 5.0, 8.0),
    "flat_01": RouteSpec("rover_flat", 11, 2.0, 7.0, 12.0),
    "flat_02": RouteSpec("rover_flat", 12, 1.5, 5.0, 10.0),
    "flat_03": RouteSpec("rover_flat", 13, 3.0, 8.0, 12.0),
    "dev_speckle": RouteSpec("rover_flat", 20, 1.1, 5.0, 9.0, "speckle"),
    "dev_gravel": RouteSpec("rover_terrain", 21, 1.1, 6.0, 10.0, "gravel"),
    "dev_grass": RouteSpec("rover_flat", 22, 1.1, 5.0, 10.0, "grass"),
    "dev_blotches": RouteSpec("rover_terrain", 23, 1.1, 6.0, 11.0, "blotches"),
    "dev_uniform": RouteSpec("rover_flat", 24, 1.1, 5.0, 10.0, "uniform"),
    "dev_pavers": RouteSpec("rover_flat", 25, 1.1, 5.0, 10.0, "pavers"),
}

#: Appearance families tuned on (dev) and those seen only in the test split. ``uniform`` was
#: test-only until its test failure (issue 13) was diagnosed on its own dev route, ``dev_uniform``;
#: ``stripes`` and ``checker`` have never been used while tuning.
DEV_FAMILIES = ("speckle", "gravel", "grass", "blotches", "uniform", "pavers")
TEST_ONLY_FAMILIES = ("stripes", "checker")
#: Families only the dev split has: ``pavers`` is a periodic ground (running-bond bricks) to choose
#: the aliasing guards on, so that ``checker``, the test split's periodic ground, stays never tuned on.
DEV_ONLY_FAMILIES = ("pavers",)

#: The ``test`` split: seeds >= 10,000; one route of every family but pavers (the two test-only families
#: never used while tuning), three of "random" appearances (every zone its own family, random sky and
#: light) and two of the default appearance, alternating hills and flat ground, 1.1 laps each.
TEST_ROUTES = {
    "test_speckle": RouteSpec("rover_terrain", 10_000, 1.1, 5.0, 10.0, "speckle"),
    "test_gravel": RouteSpec("rover_flat", 10_001, 1.1, 6.0, 11.0, "gravel"),
    "test_grass": RouteSpec("rover_terrain", 10_002, 1.1, 5.0, 9.0, "grass"),
    "test_uniform": RouteSpec("rover_flat", 10_003, 1.1, 5.0, 10.0, "uniform"),
    "test_stripes": RouteSpec("rover_terrain", 10_004, 1.1, 6.0, 11.0, "stripes"),
    "test_checker": RouteSpec("rover_flat", 10_005, 1.1, 5.0, 10.0, "checker"),
    "test_blotches": RouteSpec("rover_terrain", 10_006, 1.1, 6.0, 12.0, "blotches"),
    "test_random_0": RouteSpec("rover_terrain", 10_007, 1.1, 5.0, 10.0, "random"),
    "test_random_1": RouteSpec("rover_flat", 10_008, 1.1, 6.0, 12.0, "random"),
    "test_random_2": RouteSpec("rover_terrain", 10_009, 1.1, 5.0, 9.0, "random"),
    "test_default_0": RouteSpec("rover_terrain", 10_010, 1.1, 6.0, 11.0),
    "test_default_1": RouteSpec("rover_flat", 10_011, 1.1, 5.0, 10.0),
}

#: Route names per split; the first ten dev routes are the ones every result before the held-out
#: protocol was measured on.
SPLITS = {"dev": tuple(ROUTES), "test": tuple(TEST_ROUTES)}

#: The car rover's sideways slip (s) for the VO's flow model (``polar_sim.ground.MotionConfig.slip``): in
#: turns its tyres creep outward, the camera's lateral velocity about 0.0104 s x forward speed x yaw rate
#: (the truth of the dev route ``flat_00``); 0.01 was chosen on the dev routes' odometry (0, 0.005, 0.01,
#: 0.015; ``benchmarks/RESULTS.md``). A calibration constant of the robot, not read from any recording.
ROVER_SLIP = 0.01

#: Bumped whenever the recorder's output changes (the cache key holds it, so a stale recording is
#: never replayed).
RECORDER_VERSION = 3


def route_spec(name) -> RouteSpec:
    """The :class:`RouteSpec` of a dev or test route; an unknown name raises ``ValueError``."""
    if isinstance(name, str) and name in ROUTES:
        return ROUTES[name]
    if isinstance(name, str) and name in TEST_ROUTES:
        return TEST_ROUTES[name]
    raise ValueError(f"name: unknown route {name!r}; valid: {', '.join(ROUTES)}, {', '.join(TEST_ROUTES)}")


def reduce2x(img):
    """One Gaussian pyramid level, 5-tap [1 4 6 4 1]/16, keeping even rows and columns (pixel
    (i, j) of the result is centred on pixel (2i, 2j) of the input)."""
    return cv2.pyrDown(img)


def _speed_profile(rng, spec, n_steps, dt):
    """Smooth random speeds in [v_min, v_max]: a new target every 10-25 s, 1 m/s^2 ramps."""
    v = np.empty(n_steps)
    target, t_next, cur = rng.uniform(spec.v_min, spec.v_max), rng.uniform(10, 25), 0.0
    for k in range(n_steps):
        if k * dt > t_next:
            target, t_next = rng.uniform(spec.v_min, spec.v_max), k * dt + rng.uniform(10, 25)
        cur += np.clip(target - cur, -1.0 * dt, 1.0 * dt)
        v[k] = cur
    return v


def _surface_coeffs(depth, K, ground, z_near, z_far=40.0):
    """Least-squares (a1..a6) of y = a1 x^2 + a2 x + a3 z^2 + a4 z + a5 x z + a6 over ground pixels
    (camera frame, OpenCV axes) with z_near <= z <= z_far; NaN if too few pixels."""
    H, W = depth.shape
    v, u = np.mgrid[0:H:2, 0:W:2]
    z = depth[::2, ::2].astype(np.float64)
    m = ground[::2, ::2] & np.isfinite(z) & (z >= z_near) & (z <= z_far)
    if m.sum() < 20:
        return np.full(6, np.nan)
    z = z[m]
    x = (u[m] - K[0, 2]) / K[0, 0] * z
    y = (v[m] - K[1, 2]) / K[1, 1] * z
    A = np.stack([x * x, x, z * z, z, x * z, np.ones_like(z)], 1)
    return np.linalg.lstsq(A, y, rcond=None)[0]


def _height_along_down(w, T_wc):
    """Distance (m) from the optical centre to the ground along the camera's +y (down) axis."""
    ground_only = np.array([0, 1, 0, 0, 0, 0], np.uint8)
    gid = np.zeros(1, np.int32)
    d = mujoco.mj_ray(w.model, w.data, T_wc[:3, 3].copy(), T_wc[:3, 1].copy(), ground_only, 1, -1, gid)
    return float(d) if d >= 0 else np.nan


def record_route(name, *, max_frames=None, progress=None):
    """Drive route ``name`` and return its :class:`Recording` (see the module docstring).

    Per frame: ``rgb`` (188, 621, 3) uint8, ``ground_mask`` (188, 621) bool, ``T_world_cam``
    (4, 4), ``t`` (s), ``v_cam``/``w_cam`` (3,) camera linear (m/s) and angular (rad/s) velocity
    in the camera frame (OpenCV axes: z forward, y down; yaw rate is ``w_cam[1]``, > 0 turning
    right), ``speed`` (m/s), ``h_y`` (m), ``surface_coeffs`` (6,), ``static`` (bool).
    Meta: ``K`` of the reduced image, ``dt``, ``camera_height``, ``route``, ``length_m``,
    ``appearance`` (the resolved spec, None for the default look), ``zones`` (zone families).
    ``progress``: a bar of the metres driven, on stderr (:func:`polar_sim.progress.progress_bar`: by
    default on a terminal unless ``POLAR_SIM_QUIET=1``; ``False``: never); a callable is called with
    the number of frames recorded so far after each frame instead (``polar-sim demo`` draws its own
    bars from it).
    """
    spec = route_spec(name)
    if max_frames is not None and (isinstance(max_frames, bool) or not isinstance(max_frames, (int, np.integer))
                                   or max_frames < 1):
        raise ValueError(f"max_frames: expected a positive int or None, got {max_frames!r}")
    rng = np.random.default_rng(np.random.SeedSequence([spec.seed, 7100]))
    look = {} if spec.appearance is None else {"appearance": spec.appearance}
    w = World(spec.scene, seed=spec.seed, camera_fovy=KITTI_FOVY_DEG, **look)
    try:
        route = w.meta.route
        follower = PurePursuit(route, lookahead=8.0, closed=True)
        loop = follower.length
        length = spec.laps * loop
        dt = w.dt
        n_max = int(length / spec.v_min / dt) + 200
        profile = _speed_profile(rng, spec, n_max, dt)
        cfg = w.meta.rover_config
        K_full = None
        rec = None
        frames = 0
        tick = progress if callable(progress) else None
        bar = progress_bar(total=int(length), desc=f"recording {name}", unit="m",
                           enabled=False if tick is not None else progress, leave=None)
        k = 0
        while True:
            pose2d = w.truth()["robot_pose2d"]
            s = follower.progress(pose2d)
            f = w.camera("front", width=FULL_W, height=FULL_H)
            if K_full is None:
                K_full = f.K
                K = K_full.copy()
                K[:2] /= 2.0  # reduced pixel i is centred on full pixel 2i
                z_near = K_full[0, 0] * cfg.camera_height / (FULL_H - 1 - K_full[1, 2])
                rec = Recording(meta={"route": name, "scene": spec.scene, "seed": spec.seed,
                                      "K": K.tolist(), "dt": dt, "camera_height": cfg.camera_height,
                                      "fovy_deg": KITTI_FOVY_DEG, "full_size": [FULL_W, FULL_H],
                                      "length_m": length, "laps": spec.laps,
                                      "speed_range": [spec.v_min, spec.v_max],
                                      "appearance": w.meta.appearance,
                                      "zones": [str(z) for z in w.meta.zones]})
            T = f.T_world_cam
            tw = w.truth()["robot_twist"]  # body frame (v, omega); camera sits on the body's z axis
            Rb = w.truth()["robot_pose"][:3, :3]
            Rcb = T[:3, :3].T @ Rb
            offset = Rb.T @ (T[:3, 3] - w.truth()["robot_pose"][:3, 3])
            v_cam = Rcb @ (tw[:3] + np.cross(tw[3:], offset))
            w_cam = Rcb @ tw[3:]
            ground = f.labels == LABELS["ground"]
            rec.append({
                "rgb": reduce2x(f.rgb), "ground_mask": ground[::2, ::2], "T_world_cam": T, "t": f.t,
                "v_cam": v_cam, "w_cam": w_cam, "speed": float(np.linalg.norm(v_cam)),
                "h_y": _height_along_down(w, T), "surface_coeffs": _surface_coeffs(f.depth, K_full, ground, z_near),
                "static": bool(np.linalg.norm(v_cam) < 0.05 * spec.v_min),
            })
            frames += 1
            bar.update(int(s) - bar.n)
            if tick is not None:
                tick(frames)
            if s >= length or (max_frames is not None and frames >= max_frames) or k >= n_max - 1:
                break
            v = float(min(profile[k], np.sqrt(2.0 / max(abs(follower.steer(pose2d, profile[k])) / max(profile[k], 0.1), 1e-3))))
            om = float(np.clip(follower.steer(pose2d, v), -cfg.max_yaw_rate, cfg.max_yaw_rate))
            w.step((v, om))
            k += 1
        bar.close()
    finally:
        w.close()
    return rec


def load_route(name, *, max_frames=None, progress=None):
    """The recording of route ``name`` (its first ``max_frames`` frames if given) as a lazy
    :class:`~polar_sim.sim.recorders.recording.RecordingReader` from the recording cache
    (:func:`polar_sim.sim.recorders.sequences.cached`, kind ``"rover_route"``), recorded first if absent."""
    spec = route_spec(name)
    key = {"route": name, **dataclasses.asdict(spec), "max_frames": int(max_frames or 0)}
    return sequences.cached("rover_route", key, lambda: record_route(name, max_frames=max_frames, progress=progress),
                            version=RECORDER_VERSION)


def route_truth(rec):
    """Scoring truth of a route recording (a Recording or its lazy reader), small arrays only.

    A dict with ``gt`` (n, 4, 4) camera k in camera 0's frame (KITTI poses), ``t`` (n,), ``speed``
    (n,) instantaneous camera speed, ``speed_cd`` (n,) central-difference speed
    |p_{k+1} - p_{k-1}| / (t_{k+1} - t_{k-1}) (one-sided at the ends), ``step`` (n,) length of the step
    k-1 -> k (0 for k = 0), ``yaw_rate`` (n,) ``w_cam[1]``, ``K``, ``h`` (m), ``dt`` (s), ``length_m``
    (path length), ``meta``, and the rover's calibrated sideways slip ``slip`` (s, :data:`ROVER_SLIP`).
    """
    T = rec.stack("T_world_cam")
    gt = np.linalg.inv(T[0]) @ T
    p = T[:, :3, 3]
    t = rec.stack("t").astype(np.float64)
    step = np.r_[0.0, np.linalg.norm(np.diff(p, axis=0), axis=1)]
    n = len(p)
    lo, hi = np.maximum(np.arange(n) - 1, 0), np.minimum(np.arange(n) + 1, n - 1)
    speed_cd = np.linalg.norm(p[hi] - p[lo], axis=1) / np.maximum(t[hi] - t[lo], 1e-9)
    return dict(gt=gt, t=t, speed=rec.stack("speed").astype(np.float64), speed_cd=speed_cd, step=step,
                yaw_rate=rec.stack("w_cam")[:, 1].astype(np.float64), K=np.array(rec.meta["K"]),
                h=float(rec.meta["camera_height"]), dt=float(rec.meta["dt"]), length_m=float(step.sum()),
                meta=dict(rec.meta), slip=ROVER_SLIP)


def route_layout(name):
    """The scene layout of a route (built from its seed, no rendering): ``route`` (m, 2) closed-route
    waypoints 1 m apart, ``zone_of_route`` (m,) zone index per waypoint and ``zones`` (the ground type
    or family of each zone)."""
    spec = route_spec(name)
    look = {} if spec.appearance is None else {"appearance": spec.appearance}
    with World(spec.scene, seed=spec.seed, camera_fovy=KITTI_FOVY_DEG, **look) as w:
        return {"route": np.array(w.meta.route), "zone_of_route": np.array(w.meta.zone_of_route),
                "zones": [str(z) for z in w.meta.zones]}


def route_zones(rec, margin_m=40.0):
    """Per-frame zone geometry of a recorded route (a Recording or reader of :func:`load_route`).

    Returns a dict: ``progress`` (n,) arc length driven along the route (m, monotone over laps),
    ``zone`` (n,) index of the zone under the camera, ``names`` (zone families), ``boundaries``
    (arc lengths where the zone changes, unwrapped over the laps driven, within ``margin_m`` of the
    drive) and ``boundary_zones`` ((from, to) per boundary), ``lap_m``.
    """
    lay = route_layout(rec.meta["route"])
    route, zor = lay["route"], lay["zone_of_route"]
    pp = PurePursuit(route, lookahead=8.0, closed=True)
    L = pp.length
    seg = np.linalg.norm(np.diff(np.vstack([route, route[:1]]), axis=0), axis=1)
    s_wp = np.r_[0.0, np.cumsum(seg)[:-1]]  # arc length of every waypoint
    T = rec.stack("T_world_cam")
    prog = np.array([pp.progress((p[0], p[1], 0.0)) for p in T[:, :3, 3]])
    zone = zor[np.clip(np.searchsorted(s_wp, prog % L, side="right") - 1, 0, len(zor) - 1)]
    change = np.flatnonzero(np.diff(np.r_[zor, zor[:1]]) != 0) + 1  # first waypoint of the next zone
    b_s, b_z = [], []
    for lap in range(int(prog[-1] // L) + 2):
        for i in change:
            s_b = lap * L + (s_wp[i] if i < len(s_wp) else L)
            if prog[0] - margin_m < s_b < prog[-1] + margin_m:
                b_s.append(float(s_b))
                b_z.append((int(zor[i - 1]), int(zor[i % len(zor)])))
    return dict(progress=prog, zone=zone, names=lay["zones"], boundaries=np.array(b_s), boundary_zones=b_z, lap_m=L)


def settled_frames(rec, times, *, warmup_s=5.0, before_m=40.0, after_m=10.0):
    """Frames of a route where the ground's appearance has settled: at least ``warmup_s`` after the
    start and outside [-before_m, +after_m] of every zone boundary (the next zone's texture is in view
    on the far ground from about 40 m before it). Returns (settled (n,) bool, :func:`route_zones`)."""
    z = route_zones(rec, before_m)
    t, prog = np.asarray(times, dtype=np.float64), z["progress"]
    settled = (t - t[0]) >= warmup_s
    for b in z["boundaries"]:
        settled &= ~((prog >= b - before_m) & (prog <= b + after_m))
    return settled, z
