"""A real client: stable-baselines3 / sb3-contrib train on GPISNav-v1 with the recipes of
polar_sim.envs.learning (short runs check the integration, never a learning threshold)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

import polar_sim.envs  # noqa: F401
from polar_sim.envs.learning import ObsNormaliser, load_model, make_model, ppo_recipe, save_policy

ROOT = Path(__file__).resolve().parents[2]


# Each recipe (stencil MLP, grid CNN, LSTM) trains a few thousand steps, saves its weights, recipe
# and normalisation to one .npz without pickle, and the reloaded policy acts exactly as the trained
# one, inside the action space.
@pytest.mark.parametrize("obs_mode,recurrent", [("stencil", False), ("grid", False), ("stencil", True)])
def test_recipe_trains_saves_and_loads(obs_mode, recurrent, tmp_path):
    torch.set_num_threads(1)
    kw = {"obs_mode": obs_mode, "pose_source": "truth"}
    venv = VecNormalize(make_vec_env("polar_sim.envs:polar_sim/GPISNav-Room-v1", n_envs=2, seed=0, env_kwargs=kw))
    recipe = ppo_recipe(obs_mode, recurrent)
    recipe["kwargs"].update(n_steps=256, batch_size=128, n_epochs=2)
    model = make_model(recipe, venv)
    model.learn(total_timesteps=2048)
    assert model.num_timesteps >= 2048
    norm = ObsNormaliser.from_vecnormalize(venv)
    save_policy(tmp_path / "policy.npz", model, recipe, norm)
    with np.load(tmp_path / "policy.npz", allow_pickle=False) as f:  # no object arrays in the file
        assert all(f[k].dtype != object for k in f.files)
    env = gym.make("polar_sim/GPISNav-Room-v1", **kw)
    loaded, norm2, _ = load_model(tmp_path / "policy.npz", env)
    obs, _ = env.reset(seed=10_000)
    o = {k: v[None] for k, v in norm(obs).items()}
    np.testing.assert_array_equal(norm(obs)["goal"], norm2(obs)["goal"])
    extra = {"episode_start": np.array([True])} if recurrent else {}
    a, _ = model.predict(o, deterministic=True, **extra)
    b, _ = loaded.predict(o, deterministic=True, **extra)
    np.testing.assert_array_equal(a, b)
    assert env.action_space.contains(np.clip(b[0], -1, 1).astype(np.float32))
    venv.close()
    env.close()


# A policy file of another format version is refused.
def test_policy_file_version_is_checked(tmp_path):
    p = tmp_path / "bad.npz"
    np.savez(p, meta=np.array(json.dumps({"format_version": 99})))
    with pytest.raises(ValueError, match="format version"):
        load_model(p, gym.make("polar_sim/GPISNav-Room-v1"))


# The example script runs its whole loop at a tiny size: training, the curve, the baselines, the
# saved and reloaded policy on held-out worlds, the plot.
def test_training_script_loop(tmp_path):
    cmd = [sys.executable, str(ROOT / "examples" / "train_ppo_gpisnav.py"), "--tier", "room", "--steps", "1024",
           "--envs", "2", "--eval-every", "512", "--curve-episodes", "1", "--test-episodes", "1",
           "--baselines", "random", "--pose-source", "truth", "--out", str(tmp_path / "run"),
           "--docs", str(tmp_path / "docs")]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env={**os.environ, "MUJOCO_GL": "egl"})
    assert out.returncode == 0, out.stderr[-3000:]
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["steps"] >= 1024 and summary["test_seeds"][0] == 10_000 and summary["dev_seeds"][0] < 10_000
    assert 0.0 <= summary["ppo_test"]["success"] <= 1.0 and len(summary["curve"]) >= 2
    assert (tmp_path / "run" / "policy.npz").exists() and (tmp_path / "docs" / "ppo_gpisnav_room_stencil.png").exists()


# With no checkpoint inside the run (--skip-start-eval, --eval-every beyond --steps) the final
# policy is still scored, once, at the step count it reached.
def test_training_script_without_checkpoints(tmp_path):
    cmd = [sys.executable, str(ROOT / "examples" / "train_ppo_gpisnav.py"), "--tier", "room", "--steps", "512",
           "--envs", "1", "--eval-every", "100000", "--skip-start-eval", "--curve-episodes", "1",
           "--test-episodes", "1", "--baselines", "", "--pose-source", "truth", "--out", str(tmp_path / "run")]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env={**os.environ, "MUJOCO_GL": "egl"})
    assert out.returncode == 0, out.stderr[-3000:]
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert [r["steps"] for r in summary["curve"]] == [summary["steps"]] and summary["steps"] >= 512


# ForwardDriveAction maps the policy's action exactly: v = m + (1 - m)(b0 + 1)/2, omega = b1,
# after clipping b to the box; the env receives that action.
def test_forward_drive_action_mapping_is_exact():
    from polar_sim.envs.learning import ForwardDriveAction, env_action

    F = ForwardDriveAction.map_action
    np.testing.assert_array_equal(F([0.0, 0.0]), np.float32([0.5, 0.0]))
    np.testing.assert_array_equal(F([-1.0, 1.0]), np.float32([0.0, 1.0]))
    np.testing.assert_array_equal(F([1.0, -1.0]), np.float32([1.0, -1.0]))
    np.testing.assert_array_equal(F([3.0, -7.0]), np.float32([1.0, -1.0]))  # clipped first
    np.testing.assert_allclose(F([0.0, 0.25], 0.2), [0.6, 0.25], rtol=0, atol=1e-7)
    np.testing.assert_allclose(F([-0.5, 0.0], 0.5), [0.5 + 0.5 * 0.25, 0.0], rtol=0, atol=1e-7)
    act = {"name": "forward_drive", "kwargs": {"min_drive": 0.2}}
    np.testing.assert_array_equal(env_action(act, [0.0, 0.25]), F([0.0, 0.25], 0.2))
    np.testing.assert_array_equal(env_action(None, [2.0, -0.5]), np.float32([1.0, -0.5]))

    seen = []
    env = gym.make("polar_sim/GPISNav-Room-v1", pose_source="truth")
    base = env.unwrapped.base
    base._apply_action = (lambda apply: lambda a: (seen.append(np.array(a)), apply(a))[1])(base._apply_action)
    w = ForwardDriveAction(env, min_drive=0.2)
    w.reset(seed=1000)
    w.step(np.float32([0.0, -0.5]))
    np.testing.assert_allclose(seen[-1], [0.6, -0.5], rtol=0, atol=1e-7)
    assert w.action_space == gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    env.close()


# Bad arguments raise ValueError naming them; the wrapped env is untouched.
@pytest.mark.parametrize("bad", [-0.1, 1.0, 1.5, float("nan"), True, "0.2", None])
def test_forward_drive_action_rejects_bad_min_drive(bad):
    from polar_sim.envs.learning import ForwardDriveAction

    env = gym.make("polar_sim/GPISNav-Room-v1", pose_source="truth")
    with pytest.raises(ValueError, match="min_drive"):
        ForwardDriveAction(env, min_drive=bad)
    with pytest.raises(ValueError, match="min_drive"):
        ForwardDriveAction.map_action([0.0, 0.0], bad)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    env.close()


def test_action_parametrisation_names_are_checked():
    from polar_sim.envs.learning import ForwardDriveAction, env_action, wrap_action

    env = gym.make("polar_sim/GPISNav-Room-v1", pose_source="truth")
    with pytest.raises(ValueError, match="action"):
        wrap_action(env, {"name": "nope"})
    with pytest.raises(ValueError, match="action"):
        env_action({"name": "nope"}, [0.0, 0.0])
    with pytest.raises(ValueError, match="env"):
        ForwardDriveAction(gym.wrappers.RescaleAction(env, -2.0, 2.0))
    assert wrap_action(env, None) is env
    env.close()
