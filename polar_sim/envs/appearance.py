"""``AppearanceRandomization``: a new, seeded ground/sky/light appearance every episode of a rover env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

__all__ = ["AppearanceRandomization"]


class AppearanceRandomization(gym.Wrapper):
    """Draw a new appearance (:mod:`polar_sim.sim.builders.rover_appearance`) for every episode of
    ``polar_sim/RoverDrive-v0`` or ``polar_sim/GroundVO-v0``.

    Each ``reset`` draws an appearance seed from the wrapper's generator (seeded by ``reset(seed=...)``,
    so a seeded episode sequence repeats exactly) and passes the resolved spec to the env as
    ``options["appearance"]``; ``info["appearance"]`` holds it. An explicit ``options["appearance"]``
    given to ``reset`` wins (and is what ``info["appearance"]`` then holds).

    Parameters
    ----------
    env : a rover env (its unwrapped env takes ``reset(options={"appearance": ...})``)
    families : sequence of str or None
        None: every zone of a random family (``"random"``); a list: every episode picks one family
        from it for all its zones (e.g. the dev families only, to keep test families held out).

    Example
    -------
    >>> env = AppearanceRandomization(gym.make("polar_sim/GroundVO-v0"), families=["speckle", "gravel"])
    >>> obs, info = env.reset(seed=0); info["appearance"]["ground"][0]["family"]   # doctest: +SKIP
    """

    def __init__(self, env, families=None):
        super().__init__(env)
        from polar_sim.sim.builders.rover_appearance import FAMILIES

        if families is not None:
            families = [families] if isinstance(families, str) else list(families)
            bad = [f for f in families if f not in FAMILIES]
            if bad or not families:
                raise ValueError(f"families: unknown or empty {bad or families!r}; valid: {', '.join(FAMILIES)}")
        from polar_sim.envs.rover_drive_v0 import RoverDriveEnv

        if not isinstance(env.unwrapped, RoverDriveEnv):
            raise TypeError(f"env: {type(env.unwrapped).__name__} has no appearance option (a rover env is needed)")
        self.families = families
        self._rng = np.random.default_rng()
        self._look = None

    def reset(self, *, seed=None, options=None):
        from polar_sim.sim.builders.rover_appearance import resolve_appearance, sample_appearance

        from polar_sim.envs.base import check_seed

        seed = check_seed(seed)
        if seed is not None:
            self._rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7005]))
        options = dict(options or {})
        if "appearance" not in options:
            s = int(self._rng.integers(0, 2**31 - 1))
            fam = None if self.families is None else self.families[int(self._rng.integers(len(self.families)))]
            options["appearance"] = resolve_appearance(sample_appearance(s, fam), s)
        obs, info = self.env.reset(seed=seed, options=options)
        self._look = options["appearance"]
        info = dict(info, appearance=self._look)
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, dict(info, appearance=self._look)
