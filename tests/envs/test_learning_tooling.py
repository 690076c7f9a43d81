"""The standard tooling around the recipes: rl-zoo3's train and enjoy with the shipped
hyperparameter module, one RLlib iteration on a local Ray, and the rliable report."""

import os
import subprocess
import sys

import numpy as np
import pytest

import polar_sim.envs  # noqa: F401
from polar_sim.envs.rl_report import iqm_with_ci, plot_learning_curves

ROOM = "polar_sim/GPISNav-Room-v1"
ENV = {**os.environ, "MUJOCO_GL": "egl", "OMP_NUM_THREADS": "1"}


# `python -m rl_zoo3.train ... --conf-file polar_sim.envs.zoo_ppo` trains (tiny size) and saves a
# model; `rl_zoo3.enjoy` loads it and runs an episode in the default slam mode.
def test_rl_zoo3_train_and_enjoy(tmp_path):
    common = ["--algo", "ppo", "--env", ROOM, "--gym-packages", "polar_sim.envs", "-f", str(tmp_path)]
    train = [sys.executable, "-m", "rl_zoo3.train", *common, "--conf-file", "polar_sim.envs.zoo_ppo", "-n", "128",
             "--eval-freq", "-1", "--seed", "0", "--hyperparams", "n_envs:1", "n_steps:64", "batch_size:64",
             "n_epochs:1"]
    out = subprocess.run(train, capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    run = tmp_path / "ppo" / "polar_sim-GPISNav-Room-v1_1"
    assert (run / "polar_sim-GPISNav-Room-v1.zip").exists()
    config = (run / "polar_sim-GPISNav-Room-v1" / "config.yml").read_text()
    assert "pose_source: truth" in config and "sdf_source: truth" in config and "known_var: 0.5" in config
    enjoy = [sys.executable, "-m", "rl_zoo3.enjoy", *common, "--no-render", "-n", "20", "--env-kwargs",
             "pose_source:'slam'", "sdf_source:'gpis'"]
    out = subprocess.run(enjoy, capture_output=True, text=True, timeout=600, env=ENV, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]


# The hyperparameter module holds the ppo recipe's defaults for each learning tier: the masked
# stencil, the forward-drive action, the training modes and PPO's settings.
def test_zoo_hyperparameters_are_the_recipes():
    from polar_sim.envs.recipes import LEARNING_ENV_IDS, RECIPES
    from polar_sim.envs.zoo_ppo import hyperparams

    assert set(hyperparams) == set(LEARNING_ENV_IDS)
    p = RECIPES["ppo"]
    for h in hyperparams.values():
        assert h["policy"] == "MlpPolicy" and h["normalize"] and h["n_envs"] == p["n_envs"]
        assert all(h[k] == p[k] for k in ("n_steps", "batch_size", "n_epochs", "learning_rate", "clip_range",
                                          "ent_coef", "gamma", "gae_lambda"))
        assert h["policy_kwargs"]["net_arch"]["pi"] == p["hidden"]
        assert h["policy_kwargs"]["log_std_init"] == p["log_std_init"]
        assert h["env_wrapper"] == ["polar_sim.envs.action_maps.ForwardDriveAction",
                                    "polar_sim.envs.far_mask.FarAsUnknown",
                                    {"polar_sim.envs.features.FeatureObservation":
                                     {"keys": list(p["obs_keys"]), "known_var": p["known_var"]}}]
        assert h["env_kwargs"] == {"pose_source": "truth", "sdf_source": "truth"}


# One RLlib PPO iteration on a local Ray with one env runner samples the batch it was asked for
# from the GPISNav env (flat stencil features, forward-drive action).
def test_rllib_one_iteration_on_local_ray():
    import ray
    from polar_sim.envs.rllib import make_rllib_env, rllib_config

    env = make_rllib_env({"env_id": ROOM, "env_kwargs": {"pose_source": "truth"}})
    assert env.observation_space.shape == (2 + 64 + 128 + 2,)
    env.close()
    with pytest.raises(ValueError, match="env_id"):
        rllib_config("polar_sim/GPISNav-v0")
    with pytest.raises(ValueError, match="minibatch_size"):
        rllib_config(ROOM, train_batch_size=64, minibatch_size=128)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, ignore_reinit_error=True)
    try:
        algo = rllib_config(ROOM, num_env_runners=1, train_batch_size=128, minibatch_size=64, num_epochs=1).build_algo()
        # The env runner's first sample can outlast RLlib's sample timeout (a fresh install
        # compiles the env's numba kernels inside the Ray worker): such an iteration returns
        # without training, so train until the learner reports, at most 5 iterations.
        for _ in range(5):
            result = algo.train()
            if "learners" in result:
                break
        assert "learners" in result, f"no training step in {result['training_iteration']} iterations"
        assert result["learners"]["__all_modules__"]["num_env_steps_trained_lifetime"] >= 128
        # The env runners' own metrics are fetched with a timeout and may be absent under load.
        if "env_runners" in result:
            assert result["env_runners"]["num_env_steps_sampled_lifetime"] >= 128
        algo.stop()
    finally:
        ray.shutdown()


# rliable's IQM with a stratified bootstrap CI: the IQM of 1..8 is the mean of 3..6 (4.5), inside
# its interval; identical runs give a zero-width interval; bad shapes are refused.
def test_iqm_with_ci_and_curves(tmp_path):
    out = iqm_with_ci({"a": np.arange(1.0, 9.0)[:, None], "b": np.full((3, 2), 0.75)}, reps=500)
    iqm, lo, hi = out["a"]
    assert iqm == pytest.approx(4.5) and lo <= iqm <= hi and lo >= 1 and hi <= 8
    assert out["b"] == (pytest.approx(0.75), pytest.approx(0.75), pytest.approx(0.75))
    assert iqm_with_ci({"a": np.arange(1.0, 9.0)[:, None]}, reps=500, seed=3) == \
        iqm_with_ci({"a": np.arange(1.0, 9.0)[:, None]}, reps=500, seed=3)
    with pytest.raises(ValueError, match="n_runs"):
        iqm_with_ci({"a": np.ones(3)})
    rows = [{"steps": 0, "wall_s": 0.0, "success": 0.1}, {"steps": 10, "wall_s": 60.0, "success": 0.9}]
    p = plot_learning_curves({"dagger": [rows, rows]}, tmp_path / "c.png", title="t", baselines={"expert": 0.9})
    assert p.stat().st_size > 1000
