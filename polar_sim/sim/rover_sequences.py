"""Rover route sequences for the ground chapter: a seeded driver, a KITTI-like camera, exact truth.

Each route drives the car-sized rover round its scene's closed route with pure pursuit at a
seeded, curvature-limited speed profile, and records at 10 Hz: the camera image rendered at
1242x376 with KITTI's focal length and reduced 2x by a Gaussian pyramid (621x188, as the ground
chapter processes KITTI), the true ground mask, the camera pose and twist, the central-difference
speed, the camera height above the terrain along the camera's down axis, and the coefficients of
the second-order ground surface seen by the camera. Recordings are cached as ``.npz`` (PNG
images) and regenerate bit for bit from the route's seed.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import cv2
import mujoco
import numpy as np
from tqdm.auto import tqdm

from polar_sim.control import PurePursuit
from polar_sim.sim.recording import Recording
from polar_sim.sim.truth import LABELS
from polar_sim.sim.world import World

__all__ = ["ROUTES", "RouteSpec", "record_route", "load_route", "cache_dir", "KITTI_FOVY_DEG", "reduce2x"]

#: Vertical field of view that gives KITTI's f = 718.9 px at 376 rows.
KITTI_FOVY_DEG = float(np.degrees(2 * np.arctan(188.0 / 718.856)))
FULL_W, FULL_H = 1242, 376


@dataclasses.dataclass(frozen=True)
class RouteSpec:
    """A route: the scene and its seed, laps of the closed route, and the speed range (m/s)."""

    scene: str
    seed: int
    laps: float
    v_min: float
    v_max: float


#: Ten routes of 500-2000 m at 5-12 m/s: six over hills, four on flat ground. (One lap of the closed
#: route is 475-490 m, so the single-lap routes drive 1.1 laps to reach 500 m.)
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
}


def cache_dir() -> Path:
    """Where recorded routes are cached: ``$POLAR_SIM_CACHE`` or ``~/.cache/polar_sim``."""
    return Path(os.environ.get("POLAR_SIM_CACHE", Path.home() / ".cache" / "polar_sim")) / "routes"


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


def record_route(name, *, max_frames=None, progress=True):
    """Drive route ``name`` and return its :class:`Recording` (see the module docstring).

    Per frame: ``rgb`` (188, 621, 3) uint8, ``ground_mask`` (188, 621) bool, ``T_world_cam``
    (4, 4), ``t`` (s), ``v_cam``/``w_cam`` (3,) camera linear (m/s) and angular (rad/s) velocity
    in the camera frame (OpenCV axes: z forward, y down; yaw rate is ``w_cam[1]``, > 0 turning
    right), ``speed`` (m/s), ``h_y`` (m), ``surface_coeffs`` (6,), ``static`` (bool).
    Meta: ``K`` of the reduced image, ``dt``, ``camera_height``, ``route``, ``length_m``.
    """
    if name not in ROUTES:
        raise ValueError(f"name: unknown route {name!r}; valid: {', '.join(ROUTES)}")
    spec = ROUTES[name]
    rng = np.random.default_rng(np.random.SeedSequence([spec.seed, 7100]))
    w = World(spec.scene, seed=spec.seed, camera_fovy=KITTI_FOVY_DEG)
    try:
        route = w.meta["route"]
        follower = PurePursuit(route, lookahead=8.0, closed=True)
        loop = follower.length
        length = spec.laps * loop
        dt = w.dt
        n_max = int(length / spec.v_min / dt) + 200
        profile = _speed_profile(rng, spec, n_max, dt)
        cfg = w.meta["rover_config"]
        K_full = None
        rec = None
        frames = 0
        bar = tqdm(total=int(length), desc=name, unit="m", disable=not progress)
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
                                      "speed_range": [spec.v_min, spec.v_max]})
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


def load_route(name, *, max_frames=None, cache=None, progress=True):
    """The recording of route ``name`` from the cache, recording (and caching) it if absent.

    ``max_frames`` shortens the route (cached separately). ``cache`` overrides :func:`cache_dir`.
    """
    root = Path(cache) if cache is not None else cache_dir()
    suffix = f"_{max_frames}f" if max_frames else ""
    # v2: terrain_00, terrain_04 and flat_00 were one lap (477-487 m) in v1; the version in the name keeps
    # a stale recording from being replayed.
    path = root / f"{name}{suffix}_v2.npz"
    if path.is_file():
        return Recording.load(path)
    rec = record_route(name, max_frames=max_frames, progress=progress)
    rec.save(path)
    return rec
