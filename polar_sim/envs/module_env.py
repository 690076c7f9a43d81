"""``ModuleEnv``: a raw task environment composed with one of the modules.

Every module environment (``GPISNav``, ``GroundVO``, ``ObjectTrack``) is built the same way: a
raw task environment (``LidarNav``, ``RoverDrive``, ``TabletopReach``), which owns the world, the
action, the reward and the end of the episode and emits raw sensors plus truth, and a module that
turns the raw sensors into the observation. The composition is itself the unwrapped environment,
so ``check_env(env.unwrapped)`` checks the module's observations too. There is one path: no
module subclasses of the task environments and no second, wrapper-based copy of them.
"""

from __future__ import annotations

import gymnasium as gym

__all__ = ["ModuleEnv"]


class ModuleEnv(gym.Env):
    """A raw task environment ``base`` plus a module.

    Subclasses build ``base`` (a :class:`~polar_sim.envs.base.PolarMujocoEnv`) and their module
    in ``__init__``, set ``observation_space``, and implement ``_module_reset(obs, info)`` and
    ``_module_step(obs, info)`` (feed the module the base's raw observation and truth),
    ``_get_obs(obs)`` and ``_get_info(info)``; ``_render_frame`` may add the module's view to the
    base's; ``_raw_obs`` may build only the part of the base's observation the module reads (the
    base's ``step`` and ``reset`` run without building it). Action, reward, termination and seeding are the base's: ``reset(seed=s)`` seeds the
    base with ``s``, so a module environment replays its base bit for bit. ``metadata`` is the
    base's, set on the class (gymnasium reads it there).
    """

    def __init__(self, base):
        if self.metadata != base.metadata:
            raise TypeError(f"{type(self).__name__}.metadata must be its base's ({base.metadata})")
        self.base = base
        self.render_mode = base.render_mode
        self.action_space = base.action_space

    # -- hooks ----------------------------------------------------------------------------
    def _module_reset(self, obs, info):
        raise NotImplementedError

    def _module_step(self, obs, info):
        raise NotImplementedError

    def _get_obs(self, obs):
        raise NotImplementedError

    def _get_info(self, info):
        raise NotImplementedError

    def _render_frame(self):
        return self.base.render()

    # -- gymnasium API --------------------------------------------------------------------
    @property
    def world(self):
        """The current episode's World (None before the first reset)."""
        return self.base.world

    @property
    def task(self):
        """What the robot is told at the start of the episode (the base's task; None before reset)."""
        return self.base.task

    def reset(self, *, seed=None, options=None):
        seed, options = self.base.check_reset(seed, options)  # before any state changes
        super().reset(seed=seed)
        self.base._reset_state(seed, options)
        raw = self._raw_obs()
        info = self.base._get_info()
        self._module_reset(raw, info)
        return self._get_obs(raw), self._get_info(info)

    def step(self, action):
        """One control period of the base, then the module. A rejected action (``ValueError``)
        leaves both as they were."""
        reward, terminated, info = self.base._step_state(action)
        raw = self._raw_obs()
        self._module_step(raw, info)
        return self._get_obs(raw), reward, terminated, False, self._get_info(info)

    def _raw_obs(self):
        """The base's observation, as far as the module reads it (default: all of it)."""
        return self.base._get_obs()

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render(): no render_mode was set; use gym.make(..., render_mode='rgb_array')")
            return None
        if self.base.world is None:
            raise RuntimeError(f"{type(self).__name__}: call reset() before render()")
        return self._render_frame()

    def close(self):
        self.base.close()
