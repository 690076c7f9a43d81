"""reset(seed=...) and step(action) refuse bad values by name, before any state changes (issue 17)."""

import gymnasium as gym
import numpy as np
import pytest

import polar_sim.envs  # noqa: F401  (registers the ids)
from polar_sim.testing.digest import state_digest


@pytest.mark.parametrize("env_id", ["polar_sim/LidarNav-v1", "polar_sim/GPISNav-Room-v1"])
def test_bad_seed_and_action_leave_the_env_unchanged(env_id):
    env = gym.make(env_id, disable_env_checker=True, pose_source="truth") if "GPIS" in env_id else \
        gym.make(env_id, disable_env_checker=True, tier="room")
    env.reset(seed=np.int64(4))          # a numpy integer is a seed
    before = state_digest(env.unwrapped, ignore=("_renderer",))
    for seed, exc in (("abc", TypeError), (True, TypeError), (1.0, TypeError), (-1, ValueError), (1e300, TypeError),
                      ([1], TypeError)):
        with pytest.raises(exc, match="seed"):
            env.reset(seed=seed)
    for action in (np.array([0.5 + 1j, 0.0]), np.array([True, False]), "ab", np.array([None, None])):
        with pytest.raises(ValueError, match="action"):
            env.step(action)
    assert state_digest(env.unwrapped, ignore=("_renderer",)) == before
    # float32 round-off just above the bound is the bound (issue 17, finding 5)
    env.step(np.float32([1.0000001] * 2))
    env.close()
