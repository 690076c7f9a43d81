"""GroundVO-v0: a rover follows a route knowing where it is only from its own monocular odometry."""

from __future__ import annotations

import cv2
import numpy as np
from gymnasium import spaces

from polar_sim.envs.base import check_kwargs
from polar_sim.envs.module_env import ModuleEnv
from polar_sim.envs.observers import VOOdometry
from polar_sim.envs.rover_drive_v0 import RoverDriveEnv

__all__ = ["GroundVOEnv"]


class GroundVOEnv(ModuleEnv):
    """## Description
    ``RoverDrive-v0`` composed with monocular visual odometry: the robot knows where it is only
    from its own VO. Every camera image goes to :class:`polar_sim.ground.GroundVO` (scale from the ground
    and the known camera height, a colour ground model learned online), whose pose, chained onto
    the known start pose, is the robot's estimated pose. The agent sees the estimated pose, the
    next waypoint in the estimated robot frame, the VO's speed and yaw rate and a downsampled
    ground-probability image; the reward and the termination come from the true pose, and the drift
    of the estimate is scored in ``info``.

    ## Observation Space
    ``Dict``, keys sorted:

    | key | shape | dtype | meaning |
    |---|---|---|---|
    | ``ground_prob`` | (24, 80) | float32 | the VO's learned P(ground \\| colour), [0, 1], downsampled (``ground_prob_size``) |
    | ``pose`` | (3,) | float32 | estimated (x, y, yaw), world frame, m and rad (x, y clipped to +-1000) |
    | ``rgb`` | (188, 621, 3) | uint8 | the camera image, only with ``image_obs=True`` |
    | ``twist`` | (2,) | float32 | the VO's speed (m/s) and yaw rate (rad/s, > 0 turning left) |
    | ``waypoint`` | (2,) | float32 | the route point ``waypoint_lookahead`` m ahead of the estimated position along the route, in the estimated robot frame (x forward, y left), m |

    ## Action Space, Reward, Episode End
    As ``RoverDrive-v0``: normalised ``(v, omega)`` (speed set-point reached at <= 3 m/s^2);
    0.1 x progress (m) - 0.02 x cross-track error (m) - 10 on failure + 10 on success, all from
    the true pose; terminated at the end of the route (true progress >= ``route_length``), more
    than ``max_cross_track`` m off the route or on a collision; truncated at 1000 steps.

    ## Arguments
    ``RoverDrive-v0``'s, plus:

    | argument | default | meaning |
    |---|---|---|
    | ``image_obs`` | False | also observe the RGB image |
    | ``vo`` | ``"groundvo"`` | or a factory ``vo(K, camera_height, seed=..., **vo_params)`` of an object with ``process(rgb, t)`` (see :class:`polar_sim.envs.observers.VOOdometry`) |
    | ``vo_params`` | None | keyword arguments of the VO (default ``GroundVO`` settings: ``downsample=1``, ``integration="3d"``) |
    | ``waypoint_lookahead`` | 10.0 | m along the route from the estimated position to the waypoint |
    | ``ground_prob_size`` | (80, 24) | width, height of the ground-probability observation, px |

    ## Truth in ``info``
    ``RoverDrive-v0``'s (true ``robot_pose2d``, ``progress``, ``cross_track_error``, ...), plus
    ``est_pose2d`` (the estimate, x, y, yaw), ``drift`` (m, horizontal distance between the
    estimated and the true position), ``drift_pct`` (% of the distance travelled),
    ``heading_error`` (rad, estimated - true), ``est_progress`` (m along the route, estimated) and
    ``vo_status``.

    ## Version History
    - v0: first release. (Since then, without a version bump: built as the composition of
      ``RoverDrive-v0`` and the VO, with the same observations bit for bit; actions within the
      box's 1e-6 tolerance are clipped to it.)
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, *, render_mode=None, render_size=(640, 360), image_obs=False, vo="groundvo", vo_params=None,
                 waypoint_lookahead=10.0, ground_prob_size=(80, 24), route_length=300.0, scene="rover_terrain",
                 max_speed=10.0, max_yaw_rate=1.0, max_accel=3.0, max_cross_track=6.0, camera_size=(621, 188),
                 supersample=True, **unknown):
        check_kwargs(type(self), unknown)
        self._image_obs = bool(image_obs)
        self._odometry = VOOdometry(vo, vo_params=vo_params, waypoint_lookahead=waypoint_lookahead,
                                    ground_prob_size=ground_prob_size)
        super().__init__(RoverDriveEnv(render_mode=render_mode, render_size=render_size, route_length=route_length,
                                       scene=scene, max_speed=max_speed, max_yaw_rate=max_yaw_rate,
                                       max_accel=max_accel, max_cross_track=max_cross_track,
                                       camera_size=camera_size, supersample=supersample))
        obs = self._odometry.observation_spaces()
        if self._image_obs:
            obs["rgb"] = self.base.observation_space["rgb"]
        self.observation_space = spaces.Dict(dict(sorted(obs.items())))

    # -- the module -----------------------------------------------------------------------
    def _module_reset(self, obs, info):
        self._rgb = obs["rgb"]
        self._odometry.reset(self.task, obs["rgb"], info["time"])
        self._trail = [(info["robot_pose2d"][:2].copy(), self._odometry.pose2d[:2].copy())]  # for render()

    def _module_step(self, obs, info):
        self._rgb = obs["rgb"]
        self._odometry.update(obs["rgb"], info["time"])
        self._trail.append((info["robot_pose2d"][:2].copy(), self._odometry.pose2d[:2].copy()))

    def _get_obs(self, raw):
        obs = self._odometry.observation()
        if self._image_obs:
            obs["rgb"] = raw["rgb"]
        return dict(sorted(obs.items()))

    def _get_info(self, info):
        info.update(self._odometry.info(info["robot_pose2d"], info["path_length"]))
        return info

    def _render_frame(self):
        """Chase view | camera image with the VO's ground probability | top-down route map
        (route grey, true path green, estimated path orange)."""
        chase = self.base.render()
        h, w = chase.shape[:2]
        cam = self._rgb.astype(np.float32)
        gp = cv2.resize(self._odometry.ground_prob, (cam.shape[1], cam.shape[0]), interpolation=cv2.INTER_LINEAR)
        tint = np.array([255.0, 40.0, 200.0], np.float32)
        cam = (cam * (1 - 0.5 * gp[..., None]) + tint * 0.5 * gp[..., None]).astype(np.uint8)
        cam = cv2.resize(cam, (w, int(round(w * cam.shape[0] / cam.shape[1]))), interpolation=cv2.INTER_AREA)
        return np.hstack([chase, _vstack_fit(cam, self._route_map(w, h - cam.shape[0]), h)])

    def _route_map(self, w, h):
        img = np.full((h, w, 3), 245, np.uint8)
        true_xy, est_xy = self._trail[-1]
        pts = self.task.route
        lo, hi = pts.min(0) - 5, pts.max(0) + 5
        scale = min((w - 10) / (hi[0] - lo[0]), (h - 10) / (hi[1] - lo[1]))

        def px(p):
            q = (np.asarray(p) - lo) * scale
            return np.stack([5 + q[..., 0], h - 5 - q[..., 1]], -1).astype(np.int32)

        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        end = int(np.searchsorted(s, self.task.route_length))
        cv2.polylines(img, [px(pts[: end + 1])], False, (150, 150, 150), 3)
        tr = np.array([t for t, _ in self._trail])
        es = np.array([e for _, e in self._trail])
        cv2.polylines(img, [px(tr)], False, (40, 170, 60), 2)
        cv2.polylines(img, [px(es)], False, (240, 130, 20), 2)
        cv2.circle(img, tuple(px(true_xy)), 4, (40, 170, 60), -1)
        cv2.circle(img, tuple(px(est_xy)), 4, (240, 130, 20), -1)
        return img


def _vstack_fit(top, bottom, h):
    out = np.vstack([top, bottom])
    return out[:h] if len(out) >= h else np.vstack([out, np.full((h - len(out), out.shape[1], 3), 245, np.uint8)])
