"""GPISNav-v0: goal-reaching navigation on SDF observations from an online map."""

from __future__ import annotations

import cv2
import numpy as np
from gymnasium import spaces

from polar_sim.envs.base import check_kwargs
from polar_sim.envs.lidar_nav_v0 import LidarNavEnv
from polar_sim.envs.observers import SDFStencil, TruthSource, make_sdf_source

__all__ = ["GPISNavEnv", "stencil_observation"]

SDF_BOUND = 50.0
GRAD_BOUND = 10.0


def stencil_observation(source, stencil, pose2d, queried=None):
    """Query an SDF source at the stencil around ``pose2d``: ``sdf`` (n,), ``sdf_grad`` (2n,) in
    the robot frame, interleaved (gx0, gy0, gx1, gy1, ...), ``sdf_var`` (n,); float32, clipped
    to the observation bounds. (Flat, because learning libraries expect 1-D vector parts.)
    ``queried`` passes an already computed ``source.query`` result at the stencil."""
    d, g, v = queried if queried is not None else source.query(stencil.world_points(pose2d))
    c, s = np.cos(pose2d[2]), np.sin(pose2d[2])
    g_robot = np.stack([c * g[:, 0] + s * g[:, 1], -s * g[:, 0] + c * g[:, 1]], 1)
    return {
        "sdf": np.clip(d, -SDF_BOUND, SDF_BOUND).astype(np.float32),
        "sdf_grad": np.clip(g_robot, -GRAD_BOUND, GRAD_BOUND).astype(np.float32).ravel(),
        "sdf_var": np.clip(np.nan_to_num(v, nan=1e6, posinf=1e6), 0, 1e6).astype(np.float32),
    }


class GPISNavEnv(LidarNavEnv):
    """## Description
    ``LidarNav-v0`` with the lidar replaced by what an online map says about the robot's
    surroundings: every step the 2D scan (270 beams) updates the map, and the observation is the
    map's signed distance, gradient and variance at a robot-centred stencil. The agent acts on
    SDF observations; the exact SDF at the same points is in ``info`` for scoring.

    ## Observation Space
    ``Dict``, keys sorted:

    | key | shape | dtype | meaning |
    |---|---|---|---|
    | ``goal`` | (2,) | float32 | goal in the robot frame, m |
    | ``sdf`` | (n,) | float32 | map distance at the stencil, m, clipped to +-50 |
    | ``sdf_grad`` | (2n,) | float32 | map gradient in the robot frame, (gx, gy) per point, clipped to +-10 |
    | ``sdf_var`` | (n,) | float32 | map variance (1e6 where the map knows nothing) |
    | ``twist`` | (2,) | float32 | forward speed (m/s), yaw rate (rad/s) |

    n = ``stencil_rays`` x len(``stencil_radii``) = 16 x 4 by default (radii 0.5, 1, 2, 3 m).

    ## Action Space, Reward, Episode End
    As ``LidarNav-v0``: normalised ``(v, omega)``; progress − time − collision + success;
    terminated on success or collision, truncated at 600 steps.

    ## Arguments
    ``LidarNav-v0``'s, plus:

    | argument | default | meaning |
    |---|---|---|
    | ``sdf_source`` | ``"gpis"`` | ``"gpis"`` (online GPIS map, faithful distance), ``"truth"`` (exact SDF), ``"occupancy_edt"`` (signed EDT of a 5 cm log-odds grid), or any object with ``reset/update/query`` |
    | ``sdf_params`` | None | keyword arguments of the map (e.g. ``{"map_scale": 1.0}``) |
    | ``stencil_rays`` | 16 | directions of the stencil |
    | ``stencil_radii`` | (0.5, 1, 2, 3) | distances of the stencil, m |

    ## Truth in ``info``
    ``LidarNav-v0``'s, plus ``sdf_true`` (n,) the exact SDF at the stencil and ``sdf_error``
    (n,) = map − exact.

    ## Version History
    - v0: first release.
    """

    def __init__(self, *, render_mode=None, render_size=(480, 480), sdf_source="gpis", sdf_params=None,
                 stencil_rays=16, stencil_radii=(0.5, 1.0, 2.0, 3.0), rooms=3, room_size=4.0, clutter=10,
                 n_beams=270, max_speed=1.0, max_yaw_rate=1.5, **unknown):
        check_kwargs(type(self), unknown)
        self._stencil = SDFStencil(stencil_rays, stencil_radii)
        self._source = make_sdf_source(sdf_source, **(sdf_params or {}))
        self._source_name = sdf_source if isinstance(sdf_source, str) else type(sdf_source).__name__
        super().__init__(render_mode=render_mode, render_size=render_size, rooms=rooms, room_size=room_size,
                         clutter=clutter, n_beams=n_beams, max_speed=max_speed, max_yaw_rate=max_yaw_rate)

    def _obs_spaces(self, half):
        base = super()._obs_spaces(half)
        n = self._stencil.size
        return {
            "goal": base["goal"],
            "sdf": spaces.Box(-SDF_BOUND, SDF_BOUND, (n,), np.float32),
            "sdf_grad": spaces.Box(-GRAD_BOUND, GRAD_BOUND, (2 * n,), np.float32),
            "sdf_var": spaces.Box(0.0, 1e6, (n,), np.float32),
            "twist": base["twist"],
        }

    def _reset_scene(self):
        super()._reset_scene()
        self._source.reset()
        if isinstance(self._source, TruthSource):
            self._source.world = self._world
        self._truth_sdf = TruthSource(self._world)
        self._after_scan()

    def _after_scan(self):
        self._source.update(self._scan.angles, self._scan.ranges, self._sensor_pose2d())
        # One map query and one exact SDF per step, shared by the observation and the info.
        pts = self._stencil.world_points(self._pose)
        self._queried = self._source.query(pts)
        self._sdf_true = self._world.sdf(pts)

    def _get_obs(self):
        obs = stencil_observation(self._source, self._stencil, self._pose, self._queried)
        obs["goal"] = self._goal_robot()
        obs["twist"] = self._twist()
        return dict(sorted(obs.items()))

    def _get_info(self):
        info = super()._get_info()
        info["sdf_true"] = self._sdf_true.astype(np.float32)
        info["sdf_error"] = (self._queried[0] - self._sdf_true).astype(np.float32)
        info["sdf_source"] = self._source_name
        return info

    def _render_frame(self):
        """Top-down view beside the map's SDF around the robot (zero level in white)."""
        top = super()._render_frame()
        h, w = top.shape[:2]
        n = 96
        span = 4.0
        xs = np.linspace(-span, span, n)
        X, Y = np.meshgrid(xs, xs[::-1])
        pts = np.stack([X.ravel() + self._pose[0], Y.ravel() + self._pose[1]], 1)
        d = self._source.query(pts)[0].reshape(n, n)
        v = np.clip((d + 1.0) / 3.0, 0, 1)
        heat = cv2.applyColorMap((255 * v).astype(np.uint8), cv2.COLORMAP_VIRIDIS)[..., ::-1].copy()
        heat[np.abs(d) < 0.05] = 255
        heat = cv2.resize(heat, (w, h), interpolation=cv2.INTER_NEAREST)
        c = (w // 2, h // 2)
        tip = (int(c[0] + 20 * np.cos(self._pose[2])), int(c[1] - 20 * np.sin(self._pose[2])))
        cv2.circle(heat, c, 6, (255, 80, 80), -1)
        cv2.line(heat, c, tip, (255, 80, 80), 2)
        g = (self._goal - self._pose[:2]) / span * (w / 2)
        cv2.circle(heat, (int(c[0] + g[0]), int(c[1] - g[1])), 8, (60, 220, 60), 2)
        return np.hstack([top, heat])
