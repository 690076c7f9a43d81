"""Module wrappers: add a module's outputs to a raw environment's observation.

Each wrapper is one small class in gymnasium's style. It checks its own arguments, changes only
the observation space and the observations, and keeps the raw keys it does not replace.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from polar_sim.envs.gpis_nav_v0 import GRAD_BOUND, SDF_BOUND, stencil_observation
from polar_sim.envs.observers import SDFStencil, TruthSource, make_sdf_source
from polar_sim.geometry import T_to_pose2d

__all__ = ["GPISObservation"]


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
