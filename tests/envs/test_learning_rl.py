"""RL from scratch on GPISNav-Room-v2: the masked-stencil observation, the training modes, the
clutter curriculum, the far mask, PPO fine-tuning from a shipped policy, and the baselines' policy files. Tiny runs check the loop, the save and
the load, never a learning threshold."""

import gymnasium as gym
import numpy as np
import pytest
import torch

import polar_sim.envs  # noqa: F401
from polar_sim.envs import recipes
from polar_sim.envs.curriculum import ClutterCurriculum, Ramp
from polar_sim.envs.evaluate import load_policy
from polar_sim.envs.features import stencil_vector

ROOM = "polar_sim/GPISNav-Room-v2"
FAST = {"pose_source": "truth", "sdf_source": "truth"}


# The ramp's fraction grows linearly from 0 to 1 over its steps, then stays 1.
def test_ramp():
    r = Ramp(100)
    assert r.fraction == 0.0
    r.update(25)
    assert r.fraction == 0.25
    r.update(1000)
    assert r.fraction == 1.0
    with pytest.raises(ValueError, match="steps"):
        Ramp(0)
    with pytest.raises(ValueError, match="t"):
        r.update(-1)
    assert r.fraction == 1.0  # a refused update leaves the ramp as it was


# The curriculum draws each episode from a world with the ramp's clutter (start -> the tier's 6
# pieces), seeded from the training worlds: the same seed gives the same episodes, and the ramp's
# end is the env as made.
def test_clutter_curriculum_follows_the_ramp_deterministically():
    ramp = Ramp(100)
    runs = []
    for _ in range(2):
        made = gym.make(ROOM, **FAST)
        env = ClutterCurriculum(made, ramp, start=1)
        ramp.update(0)
        first = env.reset(seed=5)[0]
        levels, inner = [env.clutter], [env.env.spec.kwargs["clutter"]]
        for t in (50, 100):
            ramp.update(t)
            env.reset()
            levels.append(env.clutter)
        runs.append((levels, inner, first["sdf"].copy(), env.env is made))
        env.close()
    assert runs[0][0] == runs[1][0] == [1, 4, 6]  # 1 + 0.5 * 5 = 3.5 rounds to 4 (half to even)
    assert runs[0][1] == [1] and runs[0][3]  # a world of 1 piece first, the env as made at the end
    np.testing.assert_array_equal(runs[0][2], runs[1][2])
    with pytest.raises(TypeError, match="ramp"):
        ClutterCurriculum(gym.make(ROOM, **FAST), 0.5)
    with pytest.raises(ValueError, match="start"):
        ClutterCurriculum(gym.make(ROOM, **FAST), ramp, start=7)


@pytest.fixture
def made_kwargs(monkeypatch):
    """The keyword arguments of every ``gym.make`` call the test makes, in order."""
    made = []
    real_make = gym.make

    def spy(*a, **k):
        made.append(k)
        return real_make(*a, **k)

    monkeypatch.setattr(gym, "make", spy)
    return made


# PPO from scratch trains with the true pose and the exact SDF, on the masked stencil, with a
# curriculum, and its policy file is made for the default slam mode and reads the same vector
# (without the far mask: the numpy MLP file).
def test_ppo_from_scratch_masked_stencil_loop(tmp_path, made_kwargs):
    torch.set_num_threads(1)
    made = made_kwargs
    params = {"steps": 256, "n_envs": 2, "n_steps": 64, "batch_size": 64, "n_epochs": 1, "eval_every": 256,
              "eval_episodes": 1, "curriculum_steps": 128, "curriculum_start": 2, "far_unknown": False}
    policy, summary = recipes.train("ppo", ROOM, params=params, out=tmp_path, progress=False)
    assert any(k.get("pose_source") == "truth" and k.get("sdf_source") == "truth" for k in made)
    assert policy.env_kwargs == {} and policy.known_var == 0.5
    assert list(policy.obs_keys) == ["goal", "sdf", "sdf_grad", "sdf_var", "twist"]
    assert summary["steps"] == 256 and len(summary["curve"]) == 1
    env = gym.make(ROOM)
    loaded = load_policy(tmp_path / "policy.npz", env)
    obs, _ = env.reset(seed=10_000)
    for _ in range(3):
        a = loaded(obs)
        np.testing.assert_allclose(a, policy(obs), rtol=0, atol=1e-6)
        assert env.action_space.contains(a)
        obs, *_ = env.step(a)
    env.close()


# The baselines read the same masked stencil as one vector; the policy file records it, and an
# action depends only on that vector (unknown-space values beyond the mask do not reach it).
@pytest.mark.parametrize("name,params", [
    ("recurrent_ppo", {"steps": 128, "n_envs": 2, "n_steps": 32, "batch_size": 64, "n_epochs": 1}),
    ("ppo", {"steps": 128, "n_envs": 2, "n_steps": 64, "batch_size": 64, "n_epochs": 1}),
    ("sac", {"steps": 120, "learning_starts": 50, "batch_size": 32}),
])
def test_baselines_read_the_masked_stencil(name, params, tmp_path):
    torch.set_num_threads(1)
    policy, _ = recipes.train(name, ROOM, params=params, out=tmp_path, progress=False)
    assert policy.recipe["features"] == {"keys": ["goal", "sdf", "sdf_grad", "sdf_var", "twist"], "known_var": 0.5,
                                         "far_unknown": params.get("far_unknown", True)}
    env = gym.make(ROOM)
    loaded = load_policy(tmp_path / "policy.npz", env)
    obs, _ = env.reset(seed=10_001)
    other = dict(obs)
    unknown = obs["sdf_var"] >= 0.5
    other["sdf"] = np.where(unknown, -3.0, obs["sdf"]).astype(np.float32)  # unknown space: any value
    np.testing.assert_array_equal(stencil_vector(obs, policy.recipe["features"]["keys"], 0.5),
                                  stencil_vector(other, policy.recipe["features"]["keys"], 0.5))
    policy.reset()
    loaded.reset()
    np.testing.assert_allclose(loaded(obs), policy(other), rtol=0, atol=1e-6)
    env.close()


# Far points read as unknown: sdf FAR, gradient 0, mask 0, whatever their variance; near points
# keep the masked stencil's values; the input is not changed.
def test_far_as_unknown_exact_values():
    from polar_sim.envs.far_mask import far_as_unknown, feature_vector

    obs = {"sdf": np.array([0.2, 1.5, 3.0, -0.4], np.float32), "sdf_var": np.array([0.0, 0.0, 0.1, 0.9], np.float32),
           "sdf_grad": np.arange(8, dtype=np.float32)}
    out = far_as_unknown(obs)
    np.testing.assert_array_equal(out["sdf_var"], np.float32([0.0, 1e6, 1e6, 0.9]))
    np.testing.assert_array_equal(obs["sdf_var"], np.float32([0.0, 0.0, 0.1, 0.9]))
    v = feature_vector(obs, ["sdf", "sdf_grad", "sdf_var"], known_var=0.5, far_unknown=True)
    np.testing.assert_allclose(v, [0.2, 1.5, 1.5, 1.5, 0, 1, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0], atol=1e-7)


# PPO fine-tuning can start from a shipped imitation policy instead of running DAgger first: no
# expert steps, the same network widths, an env-action policy for the default slam mode.
def test_dagger_ppo_from_the_shipped_policy(tmp_path):
    from polar_sim.envs import pretrained

    torch.set_num_threads(1)
    params = {"init_policy": "pretrained", "finetune_steps": 128, "n_envs": 2, "n_steps": 64, "batch_size": 64,
              "n_epochs": 1, "critic_warmup_steps": 128}
    with pytest.raises(ValueError, match="init_policy: the policy shipped for .* is a MapCNNPolicy"):
        recipes.train("dagger_ppo", ROOM, params=params, out=tmp_path, progress=False)  # the v2 tiers ship map CNNs
    room = "polar_sim/GPISNav-Room-v1"  # ships an MLP
    policy, summary = recipes.train("dagger_ppo", room, params=params, out=tmp_path, progress=False)
    ref = pretrained(room)
    assert summary["steps"] == 128 + 128  # warm-up and fine-tuning, no DAgger steps
    assert [w.shape for w in policy.weights] == [w.shape for w in ref.weights] and policy.action is None
    assert policy.known_var == ref.known_var and policy.env_kwargs == ref.env_kwargs
    env = gym.make(room, **policy.env_kwargs)
    obs, _ = env.reset(seed=10_002)
    np.testing.assert_allclose(load_policy(tmp_path / "policy.npz", env)(obs), policy(obs), rtol=0, atol=1e-6)
    env.close()


# The training episodes' outcomes since the last checkpoint, exactly: means over the ended
# episodes only (Monitor's length and return), nan when none ended, and a row empties the tally.
def test_episode_tally_exact():
    from polar_sim.envs._train import _EpisodeTally

    t = _EpisodeTally()
    t.add([False, True], [{}, {"is_success": True, "collision": False, "episode": {"l": 40, "r": 9.0}}])
    t.add([True, True, False], [{"is_success": False, "collision": True, "episode": {"l": 10, "r": -1.0}},
                                {"is_success": False, "collision": False, "episode": {"l": 300, "r": 1.0}}, {}])
    assert t.row() == {"train_episodes": 3, "train_success": 1 / 3, "train_collision": 1 / 3,
                       "train_length": 350 / 3, "train_return": 3.0}
    empty = t.row()
    assert empty["train_episodes"] == 0 and np.isnan(empty["train_success"])


# train_reward reweights the training envs' reward only (the policy is scored with the env's
# own), and eval_mode "train" scores the dev checkpoints in the training mode; each checkpoint
# row carries the training episodes' outcomes.
def test_train_reward_and_eval_mode(tmp_path, made_kwargs):
    torch.set_num_threads(1)
    made = made_kwargs
    weights = {"collision": 2.5, "proximity": 0.1, "proximity_radius": 0.5}
    params = {"steps": 256, "n_envs": 2, "n_steps": 64, "batch_size": 64, "n_epochs": 1, "eval_every": 128,
              "eval_episodes": 1, "eval_mode": "train", "train_reward": weights}
    policy, summary = recipes.train("ppo", ROOM, params=params, out=tmp_path, progress=False)
    train_kw = [k for k in made if "reward_weights" in k]
    assert train_kw and all(k["reward_weights"] == weights and k["pose_source"] == "truth" for k in train_kw)
    assert policy.env_kwargs == {"obs_mode": "stencil"}  # scored with the env's own reward
    eval_kw = [k for k in made if "reward_weights" not in k]
    assert eval_kw and all(k.get("pose_source") == "truth" and k.get("sdf_source") == "truth" for k in eval_kw)
    assert [r["steps"] for r in summary["curve"]] == [128, 256]
    assert all(r["train_episodes"] >= 0 and set(r) >= {"train_success", "train_collision"} for r in summary["curve"])
    with pytest.raises(ValueError, match="train_reward"):
        recipes.check_recipe("ppo", {"train_reward": {"collision": -1.0}})
    with pytest.raises(ValueError, match="eval_mode"):
        recipes.check_recipe("ppo", {"eval_mode": "odometry"})


# Wrong RL parameters are refused with a ValueError naming them, before any env is built.
@pytest.mark.parametrize("name,params,match", [
    ("ppo", {"train_sdf_source": "slam"}, "train_sdf_source"),
    ("ppo", {"curriculum_start": -1}, "curriculum_start"),
    ("ppo", {"curriculum_steps": -5}, "curriculum_steps"),
    ("ppo", {"env_kwargs": {"sdf_source": "truth"}}, "train_sdf_source"),
    ("ppo", {"obs_keys": ["goal", "sdf", "twist"]}, "known_var"),
    ("sac", {"known_var": 0.0}, "known_var"),
    ("recurrent_ppo", {"curriculum": 3}, "curriculum"),
    ("ppo", {"far_unknown": True, "known_var": None}, "far_unknown"),
    ("dagger_ppo", {"init_policy": "no_such_file.npz"}, "init_policy"),
    ("dagger_ppo", {"init_policy": 3}, "init_policy"),
])
def test_bad_rl_params_refused_before_training(name, params, match, monkeypatch):
    monkeypatch.setattr(gym, "make", lambda *a, **k: pytest.fail("an env was built"))
    with pytest.raises(ValueError, match=match):
        recipes.train(name, ROOM, params=params, progress=False)
