"""LidarNav-v0 / GPISNav-v0 (the GPS+compass variant): gymnasium and SB3 checks, seeding, bad input,
the composition, vector envs."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import polar_sim.envs  # noqa: F401  (registers the ids)
from polar_sim.envs.lidar_nav import LidarNavEnv
from polar_sim.envs.policies import SDFNavigator, SDFReactive

SMALL = dict(rooms=2, room_size=4.0, clutter=3)


def _checked(env):
    with warnings.catch_warnings(record=True) as ws:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
        from stable_baselines3.common.env_checker import check_env as sb3_check

        sb3_check(env.unwrapped)
    return [str(w.message) for w in ws]


# gymnasium's and SB3's checkers pass without warnings, for the raw env and every SDF source.
@pytest.mark.parametrize("env_id,kw", [("polar_sim/LidarNav-v0", {}),
                                       ("polar_sim/GPISNav-v0", {"sdf_source": "gpis"}),
                                       ("polar_sim/GPISNav-v0", {"sdf_source": "truth"}),
                                       ("polar_sim/GPISNav-v0", {"sdf_source": "occupancy_edt"})])
def test_check_env(env_id, kw):
    env = gym.make(env_id, render_mode="rgb_array", **SMALL, **kw)
    try:
        assert _checked(env) == []
    finally:
        env.close()


# reset(seed=s) rebuilds the same world and replays bit for bit; another seed gives another world.
def test_seeded_replay():
    def run(seed):
        env = gym.make("polar_sim/GPISNav-v0", **SMALL)
        obs, info = env.reset(seed=seed)
        out = [obs]
        for k in range(6):
            obs, *_ = env.step(np.array([0.5, 0.3 * np.sin(k)], np.float32))
            out.append(obs)
        env.close()
        return out, info["layout_seed"]
    a, sa = run(3)
    b, sb = run(3)
    _, sc = run(4)
    for oa, ob in zip(a, b):
        for k in oa:
            np.testing.assert_array_equal(oa[k], ob[k])
    assert sa == sb != sc


# The stencil SDF from the "truth" source equals the exact SDF in info; the map error is zero.
def test_truth_source_is_exact():
    env = gym.make("polar_sim/GPISNav-v0", sdf_source="truth", **SMALL)
    obs, info = env.reset(seed=1)
    np.testing.assert_allclose(obs["sdf"], np.clip(info["sdf_true"], -50, 50), atol=1e-6)
    assert np.all(info["sdf_error"] == 0)
    env.close()


# The online GPIS map is close to the exact SDF near the robot after a few scans.
def test_gpis_source_close_to_truth():
    env = gym.make("polar_sim/GPISNav-v0", sdf_source="gpis", **SMALL)
    obs, info = env.reset(seed=2)
    for _ in range(10):
        obs, r, term, trunc, info = env.step(np.array([0.0, 0.5], np.float32))
    known = obs["sdf_var"] < 0.5
    assert known.sum() > 20
    assert np.median(np.abs(info["sdf_error"][known])) < 0.05
    env.close()


# Bad input: actions outside the box or NaN raise; unknown kwargs list the valid ones;
# stepping before reset or after close raises; close twice is safe.
def test_bad_input_and_lifecycle():
    with pytest.raises(TypeError, match="valid: .*sdf_source"):
        gym.make("polar_sim/GPISNav-v0", sdf_sorce="gpis")
    with pytest.raises(ValueError, match="sdf_source"):
        gym.make("polar_sim/GPISNav-v0", sdf_source="lidar")
    with pytest.raises(ValueError, match="pose_source: version 0"):
        gym.make("polar_sim/GPISNav-v0", pose_source="slam")
    with pytest.raises(ValueError, match="lidar_noise: version 0"):
        gym.make("polar_sim/GPISNav-v0", lidar_noise=(0.01, 0.0))
    env = gym.make("polar_sim/GPISNav-v0", sdf_source="truth", **SMALL)
    with pytest.raises(RuntimeError, match="reset"):
        env.unwrapped.step(np.zeros(2, np.float32))
    env.reset(seed=0)
    for bad in (np.array([1.5, 0.0]), np.array([np.nan, 0.0]), np.zeros(3)):
        with pytest.raises(ValueError, match="action"):
            env.step(bad)
    env.step(np.zeros(2, np.float32))
    env.close()
    env.close()
    with pytest.raises(RuntimeError, match="close"):
        env.unwrapped.step(np.zeros(2, np.float32))


# GPISNav-v0 is the composition of the raw LidarNav-v0 and the map: its goal and twist are the
# base's observation, and its unwrapped env is the composition itself (what check_env sees).
def test_gpisnav_is_lidarnav_plus_map():
    a = gym.make("polar_sim/LidarNav-v0", **SMALL)
    b = gym.make("polar_sim/GPISNav-v0", sdf_source="truth", **SMALL)
    assert isinstance(b.unwrapped.base, LidarNavEnv) and b.unwrapped is not b.unwrapped.base
    oa, _ = a.reset(seed=7)
    ob, _ = b.reset(seed=7)
    for _ in range(3):
        act = np.array([0.4, 0.2], np.float32)
        oa, *_ = a.step(act)
        ob, *_ = b.step(act)
    for k in ("goal", "twist"):
        np.testing.assert_array_equal(oa[k], ob[k])
    assert sorted(ob) == ["goal", "sdf", "sdf_grad", "sdf_var", "twist"]
    a.close()
    b.close()


# The SDF-reactive baseline reaches the goal in a small world with the exact SDF.
def test_reactive_baseline_reaches_goal():
    env = gym.make("polar_sim/GPISNav-v0", sdf_source="truth", **SMALL)
    pol = SDFReactive()
    reached = 0
    for seed in range(3):
        obs, info = env.reset(seed=seed)
        pol.reset()
        start = info["goal_distance"]
        done = False
        while not done:
            obs, r, term, trunc, info = env.step(pol(obs))
            done = term or trunc
        reached += info["is_success"]
        assert not info["collision"]
        assert info["goal_distance"] < start
    assert reached >= 2
    env.close()


def _run(env, pol, seed):
    obs, info = env.reset(seed=seed)
    start = info["geodesic_distance"]
    pol.reset()
    done = False
    while not done:
        obs, r, term, trunc, info = env.step(pol(obs))
        done = term or trunc
    return info, start


# Held-out worlds (default size) where the goal lies rooms away: the pure reactive controller
# times out in both (checked on the exact SDF); the navigator, planning on what the map has
# shown it, gets there without touching anything, on either map, by a path at most 1.3x the
# shortest one (the geodesic distance at the start).
@pytest.mark.parametrize("source", ["truth", "gpis"])
def test_navigator_reaches_goals_the_reactive_controller_misses(source):
    env = gym.make("polar_sim/GPISNav-v0", sdf_source=source)
    for seed in (10006, 10009):
        if source == "truth":
            assert not _run(env, SDFReactive(), seed)[0]["is_success"]
        info, shortest = _run(env, SDFNavigator(), seed)
        assert info["is_success"] and not info["collision"]
        assert info["path_length"] < 1.3 * shortest
    env.close()


# render() gives the top-down view beside the map's SDF.
def test_render():
    env = gym.make("polar_sim/GPISNav-v0", sdf_source="truth", render_mode="rgb_array", **SMALL)
    env.reset(seed=0)
    img = env.render()
    assert img.dtype == np.uint8 and img.shape == (480, 960, 3) and img.std() > 10
    env.close()


# Sync and Async (spawn) vector environments step in lockstep and autoreset.
def test_vector_envs():
    kw = dict(sdf_source="truth", **SMALL)
    fns = [lambda: gym.make("polar_sim.envs:polar_sim/GPISNav-v0", **kw) for _ in range(2)]
    sync = gym.vector.SyncVectorEnv(fns)
    asyn = gym.vector.AsyncVectorEnv(fns, context="spawn")
    try:
        o1, _ = sync.reset(seed=[0, 1])
        o2, _ = asyn.reset(seed=[0, 1])
        act = np.tile(np.array([0.3, 0.1], np.float32), (2, 1))
        for _ in range(3):
            o1, r1, *_ = sync.step(act)
            o2, r2, *_ = asyn.step(act)
        for k in o1:
            np.testing.assert_array_equal(o1[k], o2[k])
        np.testing.assert_array_equal(r1, r2)
    finally:
        sync.close()
        asyn.close()


# The progress term is the decrease of the geodesic distance in info, which is never shorter than
# the straight line (less the grid's half-cell) and sums to the distance covered toward the goal.
def test_progress_reward_is_geodesic():
    env = gym.make("polar_sim/GPISNav-v0", sdf_source="truth", **SMALL)
    obs, info = env.reset(seed=2)
    pol = SDFNavigator()
    pol.reset()
    start, total, done = info["geodesic_distance"], 0.0, False
    while not done:
        obs, r, term, trunc, info = env.step(pol(obs))
        done = term or trunc
        total += info["reward_terms"]["progress"]
        assert info["geodesic_distance"] >= info["goal_distance"] - 0.071
    assert total == pytest.approx(start - info["geodesic_distance"], abs=1e-9)
    env.close()


# make_async_vector_env: workers pinned one per CPU, same observations as a SyncVectorEnv.
def test_pinned_async_vector_env():
    import os

    from polar_sim.envs.vector import make_async_vector_env

    with pytest.raises(ValueError, match="num_envs"):
        make_async_vector_env("polar_sim/GPISNav-v0", 0)
    kw = dict(sdf_source="truth", **SMALL)
    cpus = sorted(os.sched_getaffinity(0))
    venv = make_async_vector_env("polar_sim/GPISNav-v0", 2, **kw)
    sync = gym.vector.SyncVectorEnv([lambda: gym.make("polar_sim/GPISNav-v0", **kw)] * 2)
    try:
        assert sorted(os.sched_getaffinity(0)) == cpus  # the parent is not pinned
        for k, proc in enumerate(venv.processes):
            assert os.sched_getaffinity(proc.pid) == {cpus[k % len(cpus)]}
        o1, _ = venv.reset(seed=[3, 4])
        o2, _ = sync.reset(seed=[3, 4])
        act = np.tile(np.array([0.3, -0.2], np.float32), (2, 1))
        for _ in range(3):
            o1, *_ = venv.step(act)
            o2, *_ = sync.step(act)
        for key in o1:
            np.testing.assert_array_equal(o1[key], o2[key])
    finally:
        venv.close()
        sync.close()
