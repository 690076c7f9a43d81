"""A clutter curriculum for training on the GPISNav tiers (gymnasium only).

:class:`ClutterCurriculum` chooses which worlds a learner trains on: each episode is drawn from an
env of the same id and arguments but with ``clutter`` pieces, ``clutter`` following a
:class:`Ramp` that a training callback moves forward with the learner's environment
steps (from few pieces to the tier's own). Early training then meets the progress and success
terms of the reward before it has learned to avoid clutter. The observation, action and reward
are the env's own; evaluation never wraps. (A goal-distance curriculum does not fit these tiers:
their start and goal are drawn at least 4.8 m apart, 4.8-6.6 m on the room tier.)
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from polar_sim._validation import as_int
from polar_sim.envs.lidar_nav import resolve_tier

#: Episode seeds a curriculum draws from (the training split; dev worlds are 1000-9999, held-out
#: worlds 10,000 and more).
TRAIN_SEEDS = (0, 1000)

__all__ = ["Ramp", "ClutterCurriculum", "TRAIN_SEEDS"]


class Ramp:
    """Training progress: ``fraction`` grows linearly from 0 at step 0 to 1 at ``steps``, then stays 1.

    Parameters
    ----------
    steps : int
        Environment steps of the ramp (>= 1).
    """

    def __init__(self, steps):
        self.steps = as_int(steps, "steps", minimum=1)
        self.t = 0

    def update(self, t):
        """Set the learner's environment step count (int >= 0)."""
        self.t = as_int(t, "t", minimum=0)

    @property
    def fraction(self):
        """The current progress in [0, 1]."""
        return min(self.t / self.steps, 1.0)


class ClutterCurriculum(gym.Wrapper):
    """Each episode in a world with ``round(start + ramp.fraction * (max_clutter - start))``
    pieces of clutter, ``max_clutter`` being the wrapped env's own; the env otherwise as made.

    The env of each clutter level is made once, with the wrapped env's id and ``gym.make``
    arguments, when first needed. Each episode's seed is drawn from the training seeds
    (:data:`TRAIN_SEEDS`, 0-999) by a stream that the first reset's seed seeds, so a seeded run
    trains on the same worlds every time and never on dev or held-out ones.

    Parameters
    ----------
    env : gymnasium.Env
        A GPISNav env made by ``gym.make`` (its ``spec`` names the id and arguments).
    ramp : Ramp
        Shared with the callback that advances it (one process, e.g. SB3's ``DummyVecEnv``).
    start : int, default=0
        Pieces of clutter at the start of the ramp (at most the env's own).

    Examples
    --------
    >>> import gymnasium as gym, polar_sim.envs
    >>> env = ClutterCurriculum(gym.make("polar_sim/GPISNav-Room-v2", pose_source="truth",
    ...                                  sdf_source="truth"), Ramp(100_000))
    >>> _ = env.reset(seed=0)
    >>> env.clutter
    0
    """

    def __init__(self, env, ramp, start=0):
        if not isinstance(ramp, Ramp):
            raise TypeError(f"ramp: expected a Ramp, got {type(ramp).__name__}")
        spec = env.spec
        if spec is None:
            raise ValueError("env: expected an env made by gym.make (its spec names the id and arguments)")
        super().__init__(env)
        kw = spec.kwargs
        self.max_clutter = resolve_tier(kw.get("tier"), kw.get("rooms"), kw.get("room_size"), kw.get("clutter"))[2]
        self.ramp, self.start = ramp, as_int(start, "start", minimum=0, maximum=self.max_clutter)
        self._envs = {self.max_clutter: env}
        self._spec = spec
        self._rng = None
        self.clutter = self.max_clutter

    def _env_of(self, clutter):
        if clutter not in self._envs:
            self._envs[clutter] = gym.make(self._spec.id, **{**self._spec.kwargs, "clutter": clutter})
        return self._envs[clutter]

    def reset(self, *, seed=None, options=None):
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        self.clutter = int(round(self.start + self.ramp.fraction * (self.max_clutter - self.start)))
        self.env = self._env_of(self.clutter)
        return self.env.reset(seed=int(self._rng.integers(*TRAIN_SEEDS)), options=options)

    def close(self):
        for e in self._envs.values():
            e.close()
