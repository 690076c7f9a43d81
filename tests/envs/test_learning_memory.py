"""The map-memory policy: the memory against hand-made geometry, the numpy network against its torch
twin, the DAgger loop with saving and loading, and bad files refused with a ValueError naming the
mismatch."""

import json

import gymnasium as gym
import numpy as np
import pytest
import torch

import polar_sim.envs  # noqa: F401
from polar_sim.envs import recipes
from polar_sim.envs.evaluate import load_policy
from polar_sim.envs.imitation_map import MapDAggerConfig, MapNet, _to_policy
from polar_sim.envs.map_memory import MapMemory
from polar_sim.envs.map_policy import MapCNNPolicy, conv2d
from polar_sim.envs.observers import SDFStencil
from polar_sim.envs.policy_file import read_policy_file, write_policy_file
from polar_sim.envs.shipped import load_numpy_policy

ROOM = "polar_sim/GPISNav-Room-v2"
STENCIL = SDFStencil(16, (0.5, 1.0, 2.0, 3.0))


def _wall_obs(goal, theta, wall_x=1.25):
    """A stencil observation of a straight wall at x = ``wall_x`` m ahead of the robot (robot frame),
    everything known: the exact distance to the wall's plane, the gradient pointing away from it."""
    p = STENCIL.points_robot
    d = wall_x - p[:, 0]  # signed: positive on the robot's side
    g = np.tile([-1.0, 0.0], (len(p), 1))
    return {"goal": np.asarray(goal, np.float32), "pose": np.array([0.0, 0.0, theta], np.float32),
            "sdf": d.astype(np.float32), "sdf_grad": g.reshape(-1).astype(np.float32),
            "sdf_var": np.zeros(len(p), np.float32), "twist": np.zeros(2, np.float32)}


# The wall's surface estimates land in the cells of the wall's points in the goal-anchored frame,
# the robot's cell becomes visited and known free, and nothing is marked behind the robot.
@pytest.mark.parametrize("theta", [0.0, 0.7, -2.0])
def test_memory_marks_the_wall_where_it_is(theta):
    mem = MapMemory(STENCIL.points_robot)
    goal = np.array([3.0, -1.0])
    mem.update(_wall_obs(goal, theta))
    R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    robot = -R @ goal
    assert np.allclose(mem.position, robot)
    # Stencil points with distance < 1.5 m: s = p - d g = (1.25, y).
    p = STENCIL.points_robot
    near = 1.25 - p[:, 0] < 1.5
    wall = np.c_[np.full(near.sum(), 1.25), p[near, 1]]
    expected = {tuple(ij) for ij in mem.index(robot + wall @ R.T)}
    marked = {tuple(ij) for ij in np.argwhere(mem.hits > 0)}
    assert marked == expected
    here = tuple(mem.index(robot[None])[0])
    assert mem.visited[here] and mem.free[here] and mem.visited.sum() == 1
    assert not (mem.free & (mem.hits > 0)).any()


# The crops are egocentric: the wall 1.25 m ahead fills the fine crop's row floor(8 - 1.25 / 0.3) = 3
# and nothing behind the robot, where space is known free; the goal's channel holds one cell, where the goal vector points.
def test_crops_are_egocentric():
    mem = MapMemory(STENCIL.points_robot, scales=((16, 0.3), (16, 1.2)))
    goal = np.array([2.0, 0.5])  # robot frame: 2 m ahead, 0.5 m to the left
    for theta in (0.0, 1.1):
        mem.reset()
        mem.update(_wall_obs(goal, theta))
        img = mem.crops()
        assert img.shape == (8, 16, 16) and img.dtype == np.float32
        obstacle = img[0]
        rows = np.flatnonzero(obstacle.max(1) > 0)
        assert set(rows) <= {2, 3, 4} and 3 in rows  # the wall's cells, up to the grid's rounding
        assert obstacle[8:].sum() == 0  # no obstacle behind the robot
        # Known free: behind the robot (the disks of the far stencil points), not beyond the wall.
        assert img[1][8:].mean() > 0.9 and img[1][:2].sum() == 0
        assert img[2, 7:9, 7:9].sum() > 0  # visited: the robot's cell at the centre
        # The goal: fine row floor(8 - 2 / 0.3) = 1, column floor(8 - 0.5 / 0.3) = 6; coarse
        # row floor(8 - 2 / 1.2) = 6, column floor(8 - 0.5 / 1.2) = 7.
        assert np.argwhere(img[3]).tolist() == [[1, 6]]
        assert np.argwhere(img[7]).tolist() == [[6, 7]]


# A goal beyond the crop marks the border cell toward it; reset forgets everything.
def test_far_goal_and_reset():
    mem = MapMemory(STENCIL.points_robot)
    mem.update(_wall_obs([0.0, -30.0], 0.0))  # 30 m to the right
    img = mem.crops()
    assert np.argwhere(img[3]).tolist() == [[8, 15]] and np.argwhere(img[7]).tolist() == [[8, 15]]
    mem.reset()
    assert not mem.hits.any() and not mem.free.any() and not mem.visited.any()


# A bad observation or parameter is refused, naming it, and the memory is left as it was.
def test_memory_bad_input():
    mem = MapMemory(STENCIL.points_robot)
    mem.update(_wall_obs([3.0, 0.0], 0.0))
    before = (mem.hits.copy(), mem.free.copy(), mem.visited.copy())
    obs = _wall_obs([3.0, 0.0], 0.0)
    del obs["pose"]
    with pytest.raises(ValueError, match="pose"):
        mem.update(obs)
    obs = _wall_obs([3.0, 0.0], 0.0)
    obs["sdf"] = obs["sdf"][:10]
    with pytest.raises(ValueError, match="stencil of 64 points"):
        mem.update(obs)
    assert all((a == b).all() for a, b in zip(before, (mem.hits, mem.free, mem.visited)))
    for bad in [((15, 0.3),), ((16, 0.1),), (), "x"]:
        with pytest.raises(ValueError, match="scales"):
            MapMemory(STENCIL.points_robot, scales=bad)
    with pytest.raises(ValueError, match="points"):
        MapMemory(np.zeros((3, 3)))


# numpy's convolution is torch's Conv2d (padding 1, stride 1 and 2, odd and even sizes).
@pytest.mark.parametrize("stride,size", [(1, 16), (2, 16), (2, 7)])
def test_conv2d_is_torchs(stride, size):
    rng = np.random.default_rng(0)
    conv = torch.nn.Conv2d(3, 5, 3, stride=stride, padding=1).double()
    x = rng.normal(size=(3, size, size))
    ref = conv(torch.as_tensor(x)[None])[0].detach().numpy()
    got = conv2d(x, conv.weight.detach().numpy(), conv.bias.detach().numpy(), stride)
    assert got.shape == ref.shape and np.allclose(got, ref, atol=1e-10)


def _small_policy(env, seed=0):
    torch.manual_seed(seed)
    cfg = MapDAggerConfig(convs=((4, 1), (4, 2)), hidden=(8,), head=None)
    mean = np.random.default_rng(seed).normal(size=260)
    std = np.full(260, 2.0)
    net = MapNet((8, 16, 16), 260, cfg)
    memory = {"half": 18.0, "cell": 0.2, "max_var": 0.5, "scales": [[16, 0.3], [16, 1.2]], "stencil_rays": 16,
              "stencil_radii": [0.5, 1.0, 2.0, 3.0]}
    return net, _to_policy(net, mean, std, memory, cfg, env, ROOM, {}, {"name": "test"})


# The exported numpy policy computes its torch twin's output (before the clip to the action box).
def test_numpy_policy_is_the_torch_net():
    env = gym.make(ROOM, pose_source="truth")
    net, policy = _small_policy(env)
    obs, _ = env.reset(seed=1000)
    for _ in range(3):
        img, vec = policy.observe(obs)
        ref = net(torch.as_tensor(img[None]), torch.as_tensor(vec[None], dtype=torch.float32))[0].detach().numpy()
        assert np.allclose(policy.act(img, vec), np.clip(ref, -1, 1), atol=1e-5)
        obs, *_ = env.step(policy.act(img, vec))
    env.close()


# The dagger_map recipe at CI size: behaviour cloning, one DAgger round, a dev checkpoint,
# policy.npz saved and loaded (through the one load_policy) to the same actions over an episode,
# memory included.
def test_dagger_map_recipe_trains_saves_and_loads(tmp_path):
    torch.set_num_threads(1)
    params = {"rounds": 2, "steps_per_round": 150, "epochs": 1, "hidden": [16], "train_pose_source": "truth",
              "eval_every": 300, "eval_episodes": 1}
    policy, summary = recipes.train("dagger_map", ROOM, params=params, out=tmp_path, progress=False)
    assert summary["steps"] == 300 and len(summary["curve"]) == 1 and (tmp_path / "curve.csv").exists()
    assert isinstance(policy, MapCNNPolicy) and policy.env_kwargs == {}
    assert policy.recipe["name"] == "dagger_map" and policy.recipe["params"]["rounds"] == 2
    loaded = load_policy(str(tmp_path / "policy.npz"), gym.make(ROOM))
    assert isinstance(loaded, MapCNNPolicy)
    env = gym.make(ROOM, pose_source="truth")
    for p in (policy, loaded):
        p.reset()
    obs, _ = env.reset(seed=1000)
    for _ in range(30):
        a, b = policy(obs), loaded(obs)
        assert np.array_equal(a, b) and env.action_space.contains(a)
        obs, _, term, trunc, _ = env.step(a)
        if term or trunc:
            break
    assert (loaded.memory.hits == policy.memory.hits).all() and loaded.memory.visited.any()
    env.close()


# Unknown or bad recipe parameters are refused before anything is built.
@pytest.mark.parametrize("params,match", [({"expert": "reactive"}, "expert"), ({"rounds": 0}, "rounds"),
                                          ({"hidden": []}, "hidden"), ({"obs_keys": ["goal"]}, "obs_keys")])
def test_dagger_map_recipe_refuses_bad_parameters(params, match):
    with pytest.raises(ValueError, match=match):
        recipes.check_recipe("dagger_map", params, ROOM)


# A tampered file, another format version, another kind, a garbled header, and an env observing
# another stencil: each a ValueError naming the mismatch.
def test_bad_map_policy_files(tmp_path):
    env = gym.make(ROOM, pose_source="truth")
    _, policy = _small_policy(env)
    path = policy.save(tmp_path / "p.npz")
    meta, arrays = read_policy_file(path)
    tampered = dict(arrays)
    tampered["conv0/W"] = tampered["conv0/W"] + 1e-3
    np.savez(tmp_path / "t.npz", meta=np.array(json.dumps(meta)), **tampered)
    with pytest.raises(ValueError, match="digest mismatch"):
        load_numpy_policy(tmp_path / "t.npz")
    old = {**meta, "format_version": 1}
    np.savez(tmp_path / "v.npz", meta=np.array(json.dumps(old)), **arrays)
    with pytest.raises(ValueError, match="format version 1"):
        load_numpy_policy(tmp_path / "v.npz")
    plain = {k: v for k, v in meta.items() if k not in ("digest", "format_version")}
    for change, match in [({"memory": {"half": 18.0}}, "memory"), ({"strides": [1]}, "weights: layer 0"),
                          ({"strides": [1, 3]}, "stride"), ({"kind": "mlp"}, "lacks or garbles")]:
        write_policy_file(tmp_path / "c.npz", {**plain, **change}, arrays)
        with pytest.raises(ValueError, match=match):
            load_numpy_policy(tmp_path / "c.npz")
    with pytest.raises(ValueError, match="kind 'mapcnn', expected 'mlp'|lacks"):
        from polar_sim.envs.mlp_policy import MLPPolicy
        MLPPolicy.load(path)
    other = gym.make(ROOM, stencil_rays=8)
    with pytest.raises(ValueError, match="observation mismatch: 'sdf'"):
        load_numpy_policy(path, other)
    grid = gym.make(ROOM, obs_mode="grid")
    with pytest.raises(ValueError, match="observation mismatch"):
        load_numpy_policy(path, grid)
    for e in (env, other, grid):
        e.close()


# The recipe's parameters are checked before anything is built.
@pytest.mark.parametrize("bad", [{"convs": ((4, 3),)}, {"convs": ()}, {"hidden": ()}, {"epochs": 0},
                                 {"scales": ((15, 0.3),)}, {"activation": "gelu"}, {"beta_decay": 2.0}])
def test_config_refuses_bad_parameters(bad):
    with pytest.raises(ValueError):
        MapDAggerConfig(**bad)
