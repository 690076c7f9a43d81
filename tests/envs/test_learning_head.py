"""The discrete action head (two-hot labels, decoding within one mode) exact against its definition,
the numpy policies with a head against their torch twins, and the one DAgger loop with a bins head at
CI size (train, save, load, the same actions; the same seed, the same policy)."""

import gymnasium as gym
import numpy as np
import pytest
import torch

import polar_sim.envs  # noqa: F401
from polar_sim.envs import recipes
from polar_sim.envs.action_head import BINS, check_head, decode, head_outputs, two_hot
from polar_sim.envs.evaluate import load_policy
from polar_sim.envs.imitation import DAggerConfig, _mlp, to_policy, train_dagger
from polar_sim.envs.imitation_map import MapDAggerConfig, MapNet, _to_policy
from polar_sim.envs.mlp_policy import MLPPolicy

ROOM = "polar_sim/GPISNav-Room-v2"
HEAD = {"name": "bins", "v": [0.0, 0.5, 1.0], "omega": [-1.0, 0.0, 1.0]}


# Two-hot labels: each value split linearly between its two nearest centres (outside the range: all
# on the end centre), the joint label the outer product; each label sums to 1 and its mean is the action.
def test_two_hot_is_exact():
    a = np.array([[0.25, 0.0], [1.0, -0.5], [-0.3, 2.0], [0.5, 0.75]])
    y = two_hot(HEAD, a).reshape(4, 3, 3)
    np.testing.assert_allclose(y[0], np.outer([0.5, 0.5, 0], [0, 1, 0]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(y[1], np.outer([0, 0, 1], [0.5, 0.5, 0]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(y[2], np.outer([1, 0, 0], [0, 0, 1]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(y[3], np.outer([0, 1, 0], [0, 0.25, 0.75]), rtol=0, atol=1e-12)
    v, w = np.meshgrid(HEAD["v"], HEAD["omega"], indexing="ij")
    inside = a[[0, 1, 3]]
    np.testing.assert_allclose(np.c_[(y[[0, 1, 3]] * v).sum((1, 2)), (y[[0, 1, 3]] * w).sum((1, 2))], inside,
                               rtol=0, atol=1e-12)


# Decoding: a two-hot label's log-probabilities decode to the action itself; a bimodal output (turn
# left or right at full speed, right slightly likelier) decodes to the right turn, not to the
# straight-ahead average a regression would give; regression passes through.
def test_decode_stays_in_one_mode():
    a = np.array([0.8, 0.3])
    y = two_hot(BINS, a[None])[0]
    np.testing.assert_allclose(decode(BINS, np.log(y + 1e-300)), a, rtol=0, atol=1e-9)
    p = np.zeros((len(BINS["v"]), len(BINS["omega"])))
    p[3, 0], p[3, -1] = 0.45, 0.55
    got = decode(BINS, np.log(p.ravel() + 1e-12))
    np.testing.assert_allclose(got, [0.9, 1.0], rtol=0, atol=1e-9)
    assert decode(None, [0.1, -0.2]).tolist() == [0.1, -0.2]
    assert head_outputs(BINS) == 36 and head_outputs(None) == 2


@pytest.mark.parametrize("bad", [{"name": "gauss"}, {"name": "bins", "v": [0.0], "omega": [-1, 1]},
                                 {"name": "bins", "v": [0.5, 0.0], "omega": [-1, 1]},
                                 {"name": "bins", "v": [0.0, 2.0], "omega": [-1, 1]},
                                 {"name": "bins", "v": ["a", "b"], "omega": [-1, 1]}, "bins", [1, 2]])
def test_bad_head_is_refused(bad):
    with pytest.raises(ValueError, match="head"):
        check_head(bad)
    with pytest.raises(ValueError, match="head"):
        DAggerConfig(head=bad)


# The numpy policies with a bins head compute their torch twins' logits, decode them, and save and
# load with the head; a file whose last layer does not match its head is refused.
def test_policies_with_a_head_match_torch_and_round_trip(tmp_path):
    torch.manual_seed(0)
    env = gym.make(ROOM, pose_source="truth")
    obs, _ = env.reset(seed=1000)
    cfg = DAggerConfig(hidden=(16,), head=BINS)
    n = sum(int(np.prod(env.observation_space[k].shape)) for k in cfg.obs_keys)
    net = _mlp(n, (16,), "tanh", 36)
    mean, std = np.zeros(n), np.ones(n)
    pol = to_policy(net, mean, std, cfg, env, ROOM, {}, {})
    ref = net(torch.as_tensor(pol.features(obs), dtype=torch.float32)).detach().numpy()
    np.testing.assert_allclose(pol.raw_output(obs), ref, rtol=0, atol=1e-5)
    np.testing.assert_allclose(pol(obs), np.clip(decode(BINS, pol.raw_output(obs)), -1, 1), rtol=0, atol=1e-6)
    back = MLPPolicy.load(pol.save(tmp_path / "m.npz"))
    assert back.head == BINS and np.array_equal(back(obs), pol(obs))
    with pytest.raises(ValueError, match="outputs 36 values, expected 2"):
        MLPPolicy(pol.weights, pol.biases, obs_keys=pol.obs_keys, obs_shapes=pol.obs_shapes, mean=mean, std=std,
                  known_var=pol.known_var)
    mcfg = MapDAggerConfig(convs=((4, 2),), hidden=(8,), head=BINS)
    mnet = MapNet((8, 16, 16), n, mcfg)
    memory = {"half": 18.0, "cell": 0.2, "max_var": 0.5, "scales": [[16, 0.3], [16, 1.2]], "stencil_rays": 16,
              "stencil_radii": [0.5, 1.0, 2.0, 3.0]}
    mpol = _to_policy(mnet, mean, std, memory, mcfg, env, ROOM, {}, {})
    img, vec = mpol.observe(obs)
    logits = mnet(torch.as_tensor(img[None]), torch.as_tensor(vec[None], dtype=torch.float32))[0].detach().numpy()
    np.testing.assert_allclose(mpol.act(img, vec), np.clip(decode(BINS, logits), -1, 1), rtol=0, atol=1e-4)
    mback = load_policy(mpol.save(tmp_path / "c.npz"))
    assert mback.head == BINS
    mpol.reset()
    mback.reset()
    assert np.array_equal(mpol(obs), mback(obs))
    env.close()


# The dagger recipe with the bins head at CI size: behaviour cloning and one DAgger round through the
# shared loop, saved and loaded to the same actions; the same seed gives the same weights.
def test_dagger_with_bins_head_trains_saves_loads_and_repeats(tmp_path):
    torch.set_num_threads(1)
    params = {"rounds": 2, "steps_per_round": 150, "epochs": 2, "hidden": [16], "head": "bins",
              "train_pose_source": "truth"}
    policy, summary = recipes.train("dagger", ROOM, params=params, out=tmp_path, progress=False)
    assert summary["steps"] == 300 and policy.head == BINS and policy.weights[-1].shape == (36, 16)
    loaded = load_policy(str(tmp_path / "policy.npz"), gym.make(ROOM))
    env = gym.make(ROOM, pose_source="truth")
    obs, _ = env.reset(seed=1000)
    for _ in range(20):
        a, b = policy(obs), loaded(obs)
        assert np.array_equal(a, b) and env.action_space.contains(a)
        obs, _, term, trunc, _ = env.step(a)
        if term or trunc:
            break
    again, hist = train_dagger(ROOM, config=DAggerConfig(rounds=2, steps_per_round=150, epochs=2, hidden=(16,),
                                                         head=BINS),
                               env_kwargs={"pose_source": "truth"}, progress=False)
    assert all(np.array_equal(w, v) for w, v in zip(again.weights, policy.weights))
    assert [r["steps"] for r in hist] == [150, 300] and hist[1]["loss"] > 0
    with pytest.raises(ValueError, match="head"):
        recipes.check_recipe("dagger", {"head": "gauss"}, ROOM)
    env.close()


# The near-obstacle weighting: equal weights are the unweighted fit (the weighted mean of equal
# weights is the mean), and the sdf columns are where the stencil's distances sit in the features.
def test_weighted_fit_and_sdf_columns():
    from polar_sim.envs.dagger import _per_sample, fit_net, key_columns

    rng = np.random.default_rng(0)
    x, y = torch.as_tensor(rng.normal(size=(64, 5)), dtype=torch.float32), torch.as_tensor(rng.normal(size=(64, 2)),
                                                                                           dtype=torch.float32)
    nets = []
    for weights in (None, torch.full((64,), 3.0)):
        torch.manual_seed(0)
        net = torch.nn.Linear(5, 2)
        loss_fn = torch.nn.functional.mse_loss if weights is None else _per_sample(torch.nn.functional.mse_loss)
        fit_net(net, [x], y, loss_fn, epochs=3, batch_size=16, lr=1e-2, generator=torch.Generator().manual_seed(1),
                weights=weights)
        nets.append(net)
    for a, b in zip(nets[0].parameters(), nets[1].parameters()):
        np.testing.assert_allclose(a.detach().numpy(), b.detach().numpy(), rtol=0, atol=1e-6)
    space = gym.spaces.Dict({"goal": gym.spaces.Box(-1, 1, (2,)), "sdf": gym.spaces.Box(-1, 1, (64,)),
                             "twist": gym.spaces.Box(-1, 1, (2,))})
    assert key_columns(("goal", "sdf", "twist"), space) == slice(2, 66)
    assert key_columns(("goal", "twist"), space) == slice(0, 0)
    with pytest.raises(ValueError, match="near_weight"):
        DAggerConfig(near_weight=0.5)
