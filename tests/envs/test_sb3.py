"""A real client: stable-baselines3 PPO trains on GPISNav-v0 (a short run checks the integration)."""

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO

import polar_sim  # noqa: F401


# PPO with a multi-input policy trains for a few hundred steps and acts inside the action space.
def test_ppo_short_training():
    torch.set_num_threads(1)
    env = gym.make("polar_sim/GPISNav-v0", sdf_source="gpis", rooms=2, room_size=4.0, clutter=3)
    model = PPO("MultiInputPolicy", env, n_steps=128, batch_size=64, n_epochs=2, seed=0, device="cpu", verbose=0)
    model.learn(total_timesteps=256)
    obs, _ = env.reset(seed=123)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action.astype(np.float32))
    obs, r, term, trunc, info = env.step(np.clip(action, -1, 1))
    assert np.isfinite(r) and "sdf_true" in info
    env.close()
