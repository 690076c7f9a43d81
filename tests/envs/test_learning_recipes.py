"""The learning recipes: each trains a few hundred steps through the whole loop (rollouts, fit,
dev checkpoints, save, load), and bad recipes are refused before anything is built. Short runs
check the integration, never a learning threshold."""

import json

import gymnasium as gym
import numpy as np
import pytest
import torch

import polar_sim.envs  # noqa: F401
from polar_sim.envs import recipes
from polar_sim.envs.evaluate import load_policy

ROOM = "polar_sim/GPISNav-Room-v1"
TINY = {
    "dagger": {"rounds": 2, "steps_per_round": 150, "epochs": 2, "eval_every": 300, "eval_episodes": 1},
    "dagger_ppo": {"rounds": 1, "steps_per_round": 150, "epochs": 1, "finetune_steps": 128, "n_envs": 2,
                   "n_steps": 64, "batch_size": 64, "n_epochs": 1, "critic_warmup_steps": 128, "eval_every": 256,
                   "eval_episodes": 1},
    "ppo": {"steps": 256, "n_envs": 2, "n_steps": 64, "batch_size": 64, "n_epochs": 1, "eval_every": 128,
            "eval_episodes": 1},
    "recurrent_ppo": {"steps": 128, "n_envs": 2, "n_steps": 32, "batch_size": 64, "n_epochs": 1},
    "sac": {"steps": 150, "learning_starts": 50, "batch_size": 32},
    "tqc": {"steps": 150, "learning_starts": 50, "batch_size": 32},
}


# Every recipe runs its loop at a tiny size, writes policy.npz, curve.csv and summary.json, and the
# file reloaded through the one load_policy acts exactly as the trained policy, inside the env's
# action space, on the observation it was trained for.
@pytest.mark.parametrize("name", sorted(TINY))
def test_recipe_trains_saves_and_loads(name, tmp_path):
    torch.set_num_threads(1)
    policy, summary = recipes.train(name, ROOM, params=TINY[name], out=tmp_path, progress=False)
    assert summary["steps"] >= TINY[name].get("steps", 0) and summary["wall_s"] > 0 and summary["cpu_s"] > 0
    assert json.loads((tmp_path / "summary.json").read_text())["recipe"] == name
    if TINY[name].get("eval_every"):
        assert (tmp_path / "curve.csv").exists() and len(summary["curve"]) >= 1
        assert summary["curve"][-1]["steps"] <= summary["steps"]
        assert all(0.0 <= r["success"] <= 1.0 for r in summary["curve"])
    env = gym.make(ROOM, **policy.env_kwargs)
    assert "pose_source" not in policy.env_kwargs  # scored in the default slam mode
    loaded = load_policy(tmp_path / "policy.npz", env)
    obs, _ = env.reset(seed=10_000)
    policy.reset()
    loaded.reset()
    for _ in range(3):
        a, b = policy(obs), loaded(obs)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-5)
        assert env.action_space.contains(b)
        obs, *_ = env.step(b)
    env.close()


# Unknown recipes, unknown parameters, bad values and non-learning env ids are refused with a
# ValueError naming them, before any environment is built.
@pytest.mark.parametrize("name,params,env_id,match", [
    ("nope", {}, ROOM, "recipe"),
    ("dagger", {"roundz": 2}, ROOM, "roundz"),
    ("dagger", {"rounds": 0}, ROOM, "rounds"),
    ("dagger", {"beta_decay": 1.5}, ROOM, "beta_decay"),
    ("dagger", {"expert": "oracle"}, ROOM, "expert"),
    ("dagger", {"hidden": []}, ROOM, "hidden"),
    ("dagger", {"obs_keys": ["goal", "sdf"]}, ROOM, "known_var"),
    ("dagger", {"known_var": -1.0}, ROOM, "known_var"),
    ("dagger", {"env_kwargs": {"pose_source": "truth"}}, ROOM, "train_pose_source"),
    ("ppo", {"learning_rate": 0.0}, ROOM, "learning_rate"),
    ("ppo", {"obs_mode": "pixels"}, ROOM, "obs_mode"),
    ("sac", {"obs_mode": "grid"}, ROOM, "obs_mode"),
    ("dagger_ppo", {"finetune_steps": 10}, ROOM, "finetune_steps"),
    ("dagger", {}, "polar_sim/GPISNav-v0", "env_id"),
    ("dagger", "rounds=3", ROOM, "params"),
])
def test_bad_recipe_is_refused_before_training(name, params, env_id, match, monkeypatch):
    monkeypatch.setattr(gym, "make", lambda *a, **k: pytest.fail("an env was built"))
    with pytest.raises((ValueError, TypeError), match=match):
        recipes.train(name, env_id, params=params, progress=False)


# Bad types raise TypeError (an int expected, a float given), also before training.
def test_recipe_parameter_types_are_checked():
    with pytest.raises(TypeError, match="rounds"):
        recipes.check_recipe("dagger", {"rounds": 2.0})
    with pytest.raises(TypeError, match="seed"):
        recipes.train("dagger", ROOM, seed=1.5)
    assert recipes.check_recipe("dagger", {"rounds": 3})["rounds"] == 3
    assert recipes.check_recipe("dagger")["rounds"] == recipes.RECIPES["dagger"]["rounds"]
