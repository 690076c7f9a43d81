"""DAgger's rollouts, the numpy MLP policy, and the PPO export: exact against their definitions."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO

import polar_sim.envs  # noqa: F401
from polar_sim.envs.features import FAR, stencil_vector
from polar_sim.envs.dagger import rollout
from polar_sim.envs.imitation import DAggerConfig, _mlp, make_expert, to_policy
from polar_sim.envs.learning import FeatureObservation, export_mlp, load_mlp_into
from polar_sim.envs.mlp_policy import MLPPolicy
from polar_sim.envs.policies import SDFReactive

ROOM = "polar_sim/GPISNav-Room-v1"
KEYS = ("goal", "sdf", "sdf_grad", "twist")


class _Recorder(gym.Wrapper):
    """Records the actions the env receives."""

    def __init__(self, env):
        super().__init__(env)
        self.actions = []

    def step(self, action):
        self.actions.append(np.array(action))
        return self.env.step(action)


class _Constant:
    """A learner (the protocol of polar_sim.envs.dagger) whose features are the raw stencil and whose action is constant."""

    dtypes = (np.float32,)

    def __init__(self, a):
        self.a, self.resets = np.float32(a), 0

    def reset(self):
        self.resets += 1

    def observe(self, obs):
        return (np.concatenate([obs[k].ravel() for k in KEYS]),)

    def act(self, sample):
        return self.a.copy()


# beta = 1: every executed action is the expert's and every label equals it; the episode is the
# one the expert drives alone (same seed, same actions).
def test_rollout_with_beta_one_is_the_experts_episode():
    env = _Recorder(gym.make(ROOM, pose_source="truth"))
    (X,), Y, _ = rollout(env, make_expert("reactive", env), _Constant([0.0, 1.0]), beta=1.0, steps=40,
                         rng=np.random.default_rng(0), seeds=iter(range(1000, 2000)))
    np.testing.assert_array_equal(np.array(env.actions), Y)
    alone = gym.make(ROOM, pose_source="truth")
    obs, _ = alone.reset(seed=1000)
    ex = SDFReactive()
    for i in range(len(Y)):
        np.testing.assert_array_equal(np.concatenate([obs[k].ravel() for k in KEYS]), X[i])
        a = ex(obs)
        np.testing.assert_array_equal(a, Y[i])
        obs, _, term, trunc, _ = alone.step(a)
        if term or trunc:
            break
    assert X.shape == (40, 2 + 64 + 128 + 2) and Y.shape == (40, 2)


# beta = 0: the learner drives (the env receives its constant action), the expert still labels
# every visited state, and both are reset at every episode start; acting=False: the expert drives.
def test_rollout_with_beta_zero_drives_the_learner_and_labels_with_the_expert():
    env = _Recorder(gym.make(ROOM, pose_source="truth"))
    learner = _Constant([0.3, -0.2])
    expert = make_expert("reactive", env)
    _, Y, out = rollout(env, expert, learner, beta=0.0, steps=30, rng=np.random.default_rng(0),
                        seeds=iter(range(1000, 2000)))
    assert all(np.array_equal(a, np.float32([0.3, -0.2])) for a in env.actions)
    assert not np.allclose(Y, np.float32([0.3, -0.2]))  # labels are the expert's, not the executed ones
    assert learner.resets == 1 + out["episodes"]
    env.actions.clear()
    _, Y, _ = rollout(env, expert, learner, beta=0.0, steps=30, rng=np.random.default_rng(0),
                      seeds=iter(range(1000, 2000)), acting=False)
    np.testing.assert_array_equal(np.array(env.actions), Y)


# The numpy MLP policy computes exactly the torch net it was exported from (float64 vs float32
# arithmetic), after the feature normalisation, and clips the output to the action box.
def test_mlp_policy_matches_the_torch_net():
    torch.manual_seed(0)
    env = gym.make(ROOM, pose_source="truth")
    obs, _ = env.reset(seed=1000)
    n = 2 + 64 + 128 + 2
    rng = np.random.default_rng(1)
    mean, std = rng.normal(size=n), rng.uniform(0.5, 2.0, n)
    net = _mlp(n, (32, 16), "tanh")
    pol = to_policy(net, mean, std, DAggerConfig(hidden=(32, 16), obs_keys=KEYS, known_var=None), env, ROOM, {}, {})
    x = np.concatenate([obs[k].ravel() for k in KEYS]).astype(np.float64)
    z = np.clip((x - mean) / std, -10, 10)
    ref = net(torch.as_tensor(z, dtype=torch.float32)).detach().numpy()
    np.testing.assert_allclose(pol.raw_output(obs), ref, rtol=0, atol=1e-5)
    np.testing.assert_allclose(pol(obs), np.clip(ref, -1, 1), rtol=0, atol=1e-5)


# Save and load round-trip exactly (same arrays, same header); bad constructor input is refused.
def test_mlp_policy_file_round_trip_and_bad_input(tmp_path):
    w = [np.ones((3, 4)), np.full((2, 3), 0.5)]
    b = [np.zeros(3), np.array([0.1, -0.1])]
    kw = dict(obs_keys=["goal", "twist"], obs_shapes={"goal": (2,), "twist": (2,)}, mean=np.zeros(4), std=np.ones(4))
    p = MLPPolicy(w, b, **kw, env_id=ROOM)
    q = MLPPolicy.load(p.save(tmp_path / "p.npz"))
    obs = {"goal": np.float32([1, 2]), "twist": np.float32([0.5, 0.25])}
    np.testing.assert_array_equal(p(obs), q(obs))
    h = np.tanh(np.ones((3, 4)) @ np.array([1, 2, 0.5, 0.25]))
    np.testing.assert_allclose(p.raw_output(obs), np.full((2, 3), 0.5) @ h + [0.1, -0.1], rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="layer 0"):
        MLPPolicy([np.ones((3, 5)), w[1]], b, **kw)
    with pytest.raises(ValueError, match="outputs 3"):
        MLPPolicy([w[0], np.ones((3, 3))], [b[0], np.zeros(3)], **kw)
    with pytest.raises(ValueError, match="std"):
        MLPPolicy(w, b, **{**kw, "std": np.zeros(4)})
    with pytest.raises(ValueError, match="activation"):
        MLPPolicy(w, b, **kw, activation="sigmoid")
    with pytest.raises(ValueError, match="twist"):
        p({"goal": obs["goal"]})


# Masking unknown space: a point with variance >= known_var reads sdf FAR and gradient 0, known
# distances are capped at FAR, sdf_var becomes the 0/1 known mask; other keys pass unchanged.
def test_stencil_vector_masks_unknown_space_exactly(tmp_path):
    obs = {"goal": np.float32([3, -4]), "sdf": np.float32([0.2, -0.7, 2.5, 0.9]),
           "sdf_grad": np.float32([1, 0, 0, 1, -1, 0, 0.6, 0.8]), "sdf_var": np.float32([0.01, 1.01, 0.2, 1e6])}
    keys = ["goal", "sdf", "sdf_grad", "sdf_var"]
    np.testing.assert_array_equal(stencil_vector(obs, keys), np.concatenate([obs[k] for k in keys]))
    want = [3, -4, 0.2, FAR, FAR, FAR, 1, 0, 0, 0, -1, 0, 0, 0, 1, 0, 1, 0]
    np.testing.assert_allclose(stencil_vector(obs, keys, known_var=0.5), want, rtol=0, atol=1e-7)
    kw = dict(obs_keys=keys, obs_shapes={"goal": (2,), "sdf": (4,), "sdf_grad": (8,), "sdf_var": (4,)},
              mean=np.zeros(18), std=np.ones(18))
    p = MLPPolicy([np.eye(18)[:2]], [np.zeros(2)], **kw, known_var=0.5)
    q = MLPPolicy.load(p.save(tmp_path / "masked.npz"))
    assert q.known_var == 0.5
    np.testing.assert_allclose(q.features(obs), want, rtol=0, atol=1e-7)
    with pytest.raises(ValueError, match="known_var"):
        MLPPolicy([np.eye(2)], [np.zeros(2)], obs_keys=["goal"], obs_shapes={"goal": (2,)}, mean=np.zeros(2),
                  std=np.ones(2), known_var=0.5)
    with pytest.raises(ValueError, match="known_var"):
        DAggerConfig(obs_keys=KEYS, known_var=0.5)


# FeatureObservation concatenates the keys in order and normalises exactly.
def test_feature_observation_is_exact():
    env = gym.make(ROOM, pose_source="truth")
    raw = FeatureObservation(env, ["twist", "goal"])
    o = env.reset(seed=1000)[0]
    np.testing.assert_array_equal(raw.observation(o), np.concatenate([o["twist"], o["goal"]]))
    mean, std = np.array([1.0, 2, 3, 4]), np.array([2.0, 2, 4, 4])
    f = FeatureObservation(env, ["twist", "goal"], mean, std, clip=1.0)
    x = np.concatenate([o["twist"], o["goal"]]).astype(np.float64)
    np.testing.assert_allclose(f.observation(o), np.clip((x - mean) / std, -1, 1), rtol=1e-6)
    with pytest.raises(ValueError, match="keys"):
        FeatureObservation(env, ["nope"])
    with pytest.raises(ValueError, match="mean"):
        FeatureObservation(env, ["goal"], mean=np.zeros(2))


# Imitation weights copied into a PPO MlpPolicy give the same deterministic action, and the PPO
# actor exported back is the same numpy policy: the fine-tuning stage starts from the imitation.
def test_imitation_weights_into_ppo_and_back():
    torch.manual_seed(0)
    env = gym.make(ROOM, pose_source="truth")
    n = 2 + 64 + 128 + 2
    rng = np.random.default_rng(2)
    mean, std = rng.normal(size=n), rng.uniform(0.5, 2.0, n)
    pol = to_policy(_mlp(n, (16, 16), "tanh"), mean, std, DAggerConfig(hidden=(16, 16), obs_keys=KEYS, known_var=None), env, ROOM, {}, {})
    fenv = FeatureObservation(env, list(KEYS), mean, std)
    model = PPO("MlpPolicy", fenv, device="cpu", seed=0,
                policy_kwargs={"net_arch": {"pi": [16, 16], "vf": [8]}, "activation_fn": torch.nn.Tanh})
    load_mlp_into(model, pol)
    obs, _ = env.reset(seed=1001)
    a, _ = model.predict(fenv.observation(obs), deterministic=True)
    np.testing.assert_allclose(a, pol(obs), rtol=0, atol=1e-5)
    back = export_mlp(model, mean, std, keys=list(KEYS), obs_shapes=pol.obs_shapes, recipe={"action": None})
    np.testing.assert_allclose(back.raw_output(obs), pol.raw_output(obs), rtol=0, atol=1e-6)
    small = PPO("MlpPolicy", fenv, device="cpu", policy_kwargs={"net_arch": [8]})
    with pytest.raises(ValueError, match="layers"):
        load_mlp_into(small, pol)
