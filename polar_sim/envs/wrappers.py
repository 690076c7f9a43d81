"""Module wrappers: add a module's outputs to a raw environment's observation.

Each wrapper is one small class in gymnasium's style. It checks its own arguments, changes only
the observation space and the observations, and keeps the raw keys it does not replace.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from polar_sim.envs.appearance import AppearanceRandomization  # noqa: F401 (exported here)
from polar_sim.envs.gpis_nav_v0 import GRAD_BOUND, SDF_BOUND, stencil_observation
from polar_sim.envs.observers import SDFStencil, TrackerPose, TruthSource, VOOdometry, make_sdf_source
from polar_sim.geometry import T_to_pose2d

__all__ = ["GPISObservation", "GroundOdometry", "TrackerObservation"]


class GPISObservation(gym.Wrapper):
    """Replace a lidar environment's ``ranges`` by SDF observations from an online map.

    Every step, the wrapped environment's scan (taken from ``env.unwrapped``'s last scan and the
    true sensor pose, i.e. mapping with known poses) updates the map, and the observation gains
    ``sdf``, ``sdf_grad`` and ``sdf_var`` at a robot-centred stencil. Pass any object with
    ``reset()``, ``update(angles, ranges, sensor_pose2d)`` and ``query(points)`` as ``sdf_source``
    to evaluate your own map in place of ours.

    Example
    -------
    >>> import gymnasium as gym, polar_sim
    >>> from polar_sim.envs.wrappers import GPISObservation
    >>> env = GPISObservation(gym.make("polar_sim/LidarNav-v0"), sdf_source="gpis")
    >>> obs, info = env.reset(seed=0)
    >>> sorted(obs)
    ['goal', 'sdf', 'sdf_grad', 'sdf_var', 'twist']
    """

    def __init__(self, env, sdf_source="gpis", *, sdf_params=None, stencil_rays=16,
                 stencil_radii=(0.5, 1.0, 2.0, 3.0)):
        super().__init__(env)
        base = env.observation_space
        if not isinstance(base, spaces.Dict) or "ranges" not in base.spaces:
            raise TypeError(f"env: expected a lidar environment with a 'ranges' observation, got {base}")
        self._stencil = SDFStencil(stencil_rays, stencil_radii)
        self._source = make_sdf_source(sdf_source, **(sdf_params or {}))
        n = self._stencil.size
        obs = {k: v for k, v in base.spaces.items() if k != "ranges"}
        obs.update({
            "sdf": spaces.Box(-SDF_BOUND, SDF_BOUND, (n,), np.float32),
            "sdf_grad": spaces.Box(-GRAD_BOUND, GRAD_BOUND, (2 * n,), np.float32),
            "sdf_var": spaces.Box(0.0, 1e6, (n,), np.float32),
        })
        self.observation_space = spaces.Dict(dict(sorted(obs.items())))

    def _observe(self, obs, info):
        raw = self.env.unwrapped
        scan = raw._scan
        self._source.update(scan.angles, scan.ranges, T_to_pose2d(scan.T_world_sensor))
        out = {k: v for k, v in obs.items() if k != "ranges"}
        out.update(stencil_observation(self._source, self._stencil, info["robot_pose2d"]))
        return dict(sorted(out.items()))

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._source.reset()
        if isinstance(self._source, TruthSource):
            self._source.world = self.env.unwrapped.world
        return self._observe(obs, info), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._observe(obs, info), reward, terminated, truncated, info


class GroundOdometry(gym.Wrapper):
    """Add monocular visual odometry to a camera rover environment (``RoverDrive-v0``).

    Every image of the wrapped environment goes to the VO; the observation gains the estimated
    ``pose``, the ``waypoint`` ahead on the route in the estimated robot frame, the VO's ``twist``
    and a downsampled ``ground_prob`` image, exactly as ``GroundVO-v0`` has them, and ``info``
    gains the estimate and its drift against the true pose. The image itself is dropped from the
    observation unless ``image_obs=True``. Pass a factory as ``vo`` (see
    :class:`polar_sim.envs.observers.VOOdometry`) to evaluate your own odometry in place of ours.
    With the same seed and actions, ``GroundOdometry(RoverDrive-v0)`` and ``GroundVO-v0`` give the
    same observations.

    Example
    -------
    >>> import gymnasium as gym, polar_sim
    >>> from polar_sim.envs.wrappers import GroundOdometry
    >>> env = GroundOdometry(gym.make("polar_sim/RoverDrive-v0"))
    >>> obs, info = env.reset(seed=0)
    >>> sorted(obs)
    ['ground_prob', 'pose', 'twist', 'waypoint']
    """

    def __init__(self, env, vo="groundvo", *, vo_params=None, waypoint_lookahead=10.0, ground_prob_size=(80, 24),
                 image_obs=False):
        super().__init__(env)
        base = env.observation_space
        if not isinstance(base, spaces.Dict) or "rgb" not in base.spaces or not hasattr(env.unwrapped, "task"):
            raise TypeError(f"env: expected a camera rover environment (RoverDrive-v0) with an 'rgb' observation, "
                            f"got {env}")
        self._odometry = VOOdometry(vo, vo_params=vo_params, waypoint_lookahead=waypoint_lookahead,
                                    ground_prob_size=ground_prob_size)
        self._image_obs = bool(image_obs)
        obs = {k: v for k, v in base.spaces.items() if k != "rgb" or self._image_obs}
        obs.update(self._odometry.observation_spaces())
        self.observation_space = spaces.Dict(dict(sorted(obs.items())))

    def _observe(self, obs, info):
        out = {k: v for k, v in obs.items() if k != "rgb" or self._image_obs}
        out.update(self._odometry.observation())
        info.update(self._odometry.info(info["robot_pose2d"], info["path_length"]))
        return dict(sorted(out.items()))

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._odometry.reset(self.env.unwrapped.task, obs["rgb"], info["time"])
        return self._observe(obs, info), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._odometry.update(obs["rgb"], info["time"])
        return self._observe(obs, info), reward, terminated, truncated, info


class TrackerObservation(gym.Wrapper):
    """Add a model-based object tracker to an RGB-D reaching environment (``TabletopReach-v0``).

    Every RGB-D frame of the wrapped environment goes to the tracker, initialised with the task's
    initial object pose; the observation gains the estimated ``object_pose``, its uncertainty
    ``object_std`` and the estimated ``pregrasp`` pose relative to the hand, exactly as
    ``ObjectTrack-v0`` has them, and ``info`` gains the estimate and the tracking error. The
    images are dropped from the observation unless ``image_obs=True``. Pass a factory as
    ``tracker`` (see :class:`polar_sim.envs.observers.TrackerPose`) to evaluate your own tracker
    in place of ours. With the same seed and actions, ``TrackerObservation(TabletopReach-v0)``
    and ``ObjectTrack-v0`` give the same observations.

    Example
    -------
    >>> import gymnasium as gym, polar_sim
    >>> from polar_sim.envs.wrappers import TrackerObservation
    >>> env = TrackerObservation(gym.make("polar_sim/TabletopReach-v0"))
    >>> obs, info = env.reset(seed=0)
    >>> sorted(obs)
    ['hand_pose', 'object_pose', 'object_std', 'pregrasp']
    """

    def __init__(self, env, tracker="objecttracker", *, tracker_params=None, image_obs=False):
        super().__init__(env)
        base = env.observation_space
        if (not isinstance(base, spaces.Dict) or not {"rgb", "depth", "hand_pose"} <= set(base.spaces)
                or not hasattr(env.unwrapped, "task")):
            raise TypeError(f"env: expected an RGB-D reaching environment (TabletopReach-v0) with 'rgb', 'depth' "
                            f"and 'hand_pose' observations, got {env}")
        self._tracking = TrackerPose(tracker, tracker_params=tracker_params)
        self._image_obs = bool(image_obs)
        obs = {k: v for k, v in base.spaces.items() if k not in ("rgb", "depth") or self._image_obs}
        obs.update(self._tracking.observation_spaces())
        self.observation_space = spaces.Dict(dict(sorted(obs.items())))

    def _observe(self, obs, info):
        out = {k: v for k, v in obs.items() if k not in ("rgb", "depth") or self._image_obs}
        out.update(self._tracking.observation(obs["hand_pose"]))
        info.update(self._tracking.info(info["object_pose"]))
        return dict(sorted(out.items()))

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._tracking.reset(self.env.unwrapped.task, obs["rgb"], obs["depth"], info["time"])
        return self._observe(obs, info), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._tracking.update(obs["rgb"], obs["depth"], info["time"])
        return self._observe(obs, info), reward, terminated, truncated, info
