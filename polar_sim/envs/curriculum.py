"""A goal-distance curriculum for training on the GPISNav tiers (gymnasium only).

:class:`GoalDistanceCurriculum` keeps the env as it is (its worlds, reward and observations) and
only chooses which episodes a learner trains on: it resets until the episode's straight-line goal
distance is within the current limit of a :class:`LinearSchedule`, which a training callback moves
forward with the learner's environment steps. Early training then sees near goals, where the
progress and success terms of the reward are met by a policy that has not yet learned to avoid
clutter; the limit grows to every goal. Evaluation never wraps: it scores every episode.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from polar_sim._validation import as_float, as_int

__all__ = ["LinearSchedule", "GoalDistanceCurriculum"]


class LinearSchedule:
    """The goal-distance limit (m) against training steps: ``start`` at step 0, growing linearly
    to ``far`` at ``steps``, then unlimited (``inf``).

    Parameters
    ----------
    start : float
        Limit at step 0, m (> 0).
    steps : int
        Environment steps until the limit is lifted (>= 1).
    far : float, default=10.0
        Limit just before ``steps``, m (>= ``start``).
    """

    def __init__(self, start, steps, far=10.0):
        self.start = as_float(start, "start", minimum=0.0, maximum=1e3, exclusive_minimum=True)
        self.steps = as_int(steps, "steps", minimum=1)
        self.far = as_float(far, "far", minimum=self.start, maximum=1e3)
        self.t = 0

    def update(self, t):
        """Set the learner's environment step count (int >= 0)."""
        self.t = as_int(t, "t", minimum=0)

    @property
    def limit(self):
        """The current limit on the goal distance, m."""
        if self.t >= self.steps:
            return np.inf
        return self.start + (self.far - self.start) * self.t / self.steps


class GoalDistanceCurriculum(gym.Wrapper):
    """Reset until ``info["goal_distance"] <= schedule.limit`` (at most ``max_tries`` resets, then
    the last episode is kept); the redraws continue the env's own seeded stream, so a seeded run
    trains on the same episodes every time.

    Parameters
    ----------
    env : gymnasium.Env
        An env whose reset ``info`` holds ``goal_distance`` (m), e.g. any GPISNav id.
    schedule : LinearSchedule
        Shared with the callback that advances it (one process, e.g. SB3's ``DummyVecEnv``).
    max_tries : int, default=50

    Examples
    --------
    >>> import gymnasium as gym, polar_sim.envs
    >>> sched = LinearSchedule(start=2.0, steps=100_000)
    >>> env = GoalDistanceCurriculum(gym.make("polar_sim/GPISNav-Room-v2", pose_source="truth",
    ...                                       sdf_source="truth"), sched)
    >>> _, info = env.reset(seed=0)
    >>> bool(info["goal_distance"] <= 2.0)
    True
    """

    def __init__(self, env, schedule, max_tries=50):
        if not isinstance(schedule, LinearSchedule):
            raise TypeError(f"schedule: expected a LinearSchedule, got {type(schedule).__name__}")
        super().__init__(env)
        self.schedule = schedule
        self.max_tries = as_int(max_tries, "max_tries", minimum=1, maximum=10_000)

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        for _ in range(self.max_tries - 1):
            if info["goal_distance"] <= self.schedule.limit:
                break
            obs, info = self.env.reset(options=options)
        return obs, info
