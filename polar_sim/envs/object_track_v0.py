"""ObjectTrack-v0: the hand reaches a pre-grasp pose on a moving object it knows only by tracking it."""

from __future__ import annotations

import numpy as np

from gymnasium import spaces

from polar_sim.envs.base import check_kwargs
from polar_sim.envs.module_env import ModuleEnv
from polar_sim.envs.observers import TrackerPose
from polar_sim.envs.tabletop_reach_v0 import TabletopReachEnv

__all__ = ["ObjectTrackEnv"]


class ObjectTrackEnv(ModuleEnv):
    """## Description
    ``TabletopReach-v0`` composed with an object tracker: the robot knows where the object is only
    from its own tracker. Every RGB-D frame goes to :class:`polar_sim.tracking.ObjectTracker` (initialised with the
    object's pose at reset, as tracking benchmarks do), and the agent sees the tracker's pose
    estimate, its uncertainty and the pre-grasp pose that follows from it, relative to the hand.
    The reward and the success come from the true pose, and the tracking error is scored in
    ``info``. The hand that approaches the object also hides part of it from the camera.

    ## Observation Space
    ``Dict``, keys sorted:

    | key | shape | dtype | meaning |
    |---|---|---|---|
    | ``depth`` | (240, 320) | float32 | metric depth, m, 0 = no return; only with ``image_obs=True`` |
    | ``hand_pose`` | (7,) | float32 | hand position (m, world) and quaternion (w, x, y, z), w >= 0 |
    | ``object_pose`` | (7,) | float32 | the tracker's object pose, world frame: position (m) and quaternion (w >= 0) |
    | ``object_std`` | (6,) | float32 | the tracker's 1-sigma uncertainty: rotation (rad, 3) and translation (m, 3) about the model centroid, object axes (the registration covariance; the filter's when lost), clipped to 10 |
    | ``pregrasp`` | (4,) | float32 | estimated pre-grasp pose minus the hand's: (dx, dy, dz) m, world frame, and the yaw (rad) still to turn |
    | ``rgb`` | (240, 320, 3) | uint8 | camera image; only with ``image_obs=True`` |

    ## Action Space, Reward, Episode End
    As ``TabletopReach-v0``: a normalised hand velocity (vx, vy, vz, yaw rate), world frame;
    minus the true distance to the pre-grasp pose each step, +10 on success, -10 for knocking
    the object off the table; terminated on success (2 cm, 10 deg of the true pre-grasp pose) or
    when the object is off the table, truncated at 300 steps (10 s).

    ## Arguments
    ``TabletopReach-v0``'s, plus:

    | argument | default | meaning |
    |---|---|---|
    | ``image_obs`` | False | also observe the RGB-D image |
    | ``tracker`` | ``"objecttracker"`` | or a factory ``tracker(model_points, K, initial_pose, model_normals=..., random_state=..., **tracker_params)`` of an object with ``process(rgb, depth, t)`` (see :class:`polar_sim.envs.observers.TrackerPose`) |
    | ``tracker_params`` | None | keyword arguments of the tracker (e.g. ``{"appearance": "h"}``, or a stage config: ``{"guard": GuardConfig(lost_after=5)}``, :mod:`polar_sim.tracking.config`) |

    ## Truth in ``info``
    ``TabletopReach-v0``'s (true ``object_pose``, ``pregrasp_pose``, ``position_error``, ...),
    plus ``est_object_pose`` (4, 4, world), ``tracking_error`` (m, object origin),
    ``tracking_error_deg``, ``tracking_add`` (m, ADD over the model points) and
    ``tracker_lost``.

    ## Version History
    - v0: first release. (Since then, without a version bump: built as the composition of
      ``TabletopReach-v0`` and the tracker, with the same observations bit for bit; actions within
      the box's 1e-6 tolerance are clipped to it.)
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, *, render_mode=None, render_size=(480, 360), image_obs=False, tracker="objecttracker",
                 tracker_params=None, target=None, n_objects=4, camera_size=(320, 240), depth_noise=True, max_speed=0.3,
                 max_yaw_rate=1.5, pregrasp_clearance=0.08, success_position=0.02, success_yaw=10.0, **unknown):
        check_kwargs(type(self), unknown)
        self._image_obs = bool(image_obs)
        self._tracking = TrackerPose(tracker, tracker_params=tracker_params)
        super().__init__(TabletopReachEnv(render_mode=render_mode, render_size=render_size, target=target,
                                          n_objects=n_objects, camera_size=camera_size, depth_noise=depth_noise,
                                          max_speed=max_speed, max_yaw_rate=max_yaw_rate,
                                          pregrasp_clearance=pregrasp_clearance, success_position=success_position,
                                          success_yaw=success_yaw))
        raw = self.base.observation_space
        obs = {"hand_pose": raw["hand_pose"], **self._tracking.observation_spaces()}
        if self._image_obs:
            obs.update(depth=raw["depth"], rgb=raw["rgb"])
        self.observation_space = spaces.Dict(dict(sorted(obs.items())))

    # -- the module -----------------------------------------------------------------------
    def _module_reset(self, obs, info):
        self._rgb = obs["rgb"]
        self._tracking.reset(self.task, obs["rgb"], obs["depth"], info["time"])

    def _module_step(self, obs, info):
        self._rgb = obs["rgb"]
        self._tracking.update(obs["rgb"], obs["depth"], info["time"])

    def _get_obs(self, raw):
        obs = self._tracking.observation(raw["hand_pose"])
        obs["hand_pose"] = raw["hand_pose"]
        if self._image_obs:
            obs.update(depth=raw["depth"], rgb=raw["rgb"])
        return dict(sorted(obs.items()))

    def _get_info(self, info):
        info.update(self._tracking.info(info["object_pose"]))
        return info

    def _render_frame(self):
        """A third-person view of the table beside the camera image with the tracker's estimate."""
        return self.base.view_beside(self._camera_overlay())

    def _camera_overlay(self):
        """The camera image with the tracker's estimate (model points, green) and segmentation."""
        import cv2

        from polar_sim.geometry import transform_points

        img = self._rgb.copy()
        r = self._tracking.result
        mask = getattr(r, "mask", None)
        if mask is not None and mask.shape == img.shape[:2]:
            img[mask] = (0.6 * img[mask] + 0.4 * np.array([60, 200, 255])).astype(np.uint8)
        P = transform_points(self._tracking.T_cam_obj, self.task.model_points[::6])
        P = P[P[:, 2] > 0.05]
        uv = (P @ self.task.K.T)[:, :2] / P[:, 2:3]
        for u, v in np.round(uv).astype(int):
            if 0 <= u < img.shape[1] and 0 <= v < img.shape[0]:
                cv2.circle(img, (u, v), 1, (40, 230, 60), -1)
        return img
