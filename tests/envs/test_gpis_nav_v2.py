"""GPISNav-v2 / LidarNav-v2: v1 with the kinematic rover (issue 32, item 1)."""

import gymnasium as gym
import numpy as np
import pytest

import polar_sim.envs  # noqa: F401  (registers the ids)

TRUTH = {"pose_source": "truth", "sdf_source": "truth"}


def _make(env_id, **kw):
    return gym.make(env_id, disable_env_checker=True, **kw)


# A step moves the rover along the exact unicycle arc of the commanded (v, omega): v = a0 * 1 m/s,
# omega = a1 * 1.5 rad/s for 0.1 s, written out independently of the simulator.
def test_v2_rover_follows_the_commanded_arc():
    env = _make("polar_sim/GPISNav-Room-v2", **TRUTH)
    _, info = env.reset(seed=10_000)
    x, y, th = info["robot_pose2d"]
    for a in ([0.6, 0.4], [0.3, -0.8], [0.5, 0.0], [0.0, 0.5]):
        _, _, term, _, info = env.step(np.float32(a))
        v, w, dt = float(np.float32(a[0])) * 1.0, float(np.float32(a[1])) * 1.5, 0.1
        if w == 0.0:
            x, y = x + v * dt * np.cos(th), y + v * dt * np.sin(th)
        else:
            x, y = x + v / w * (np.sin(th + w * dt) - np.sin(th)), y - v / w * (np.cos(th + w * dt) - np.cos(th))
        th += w * dt
        np.testing.assert_allclose(info["robot_pose2d"][:2], [x, y], rtol=0, atol=1e-12)
        assert abs(np.angle(np.exp(1j * (info["robot_pose2d"][2] - th)))) < 1e-12
        assert not term
    env.close()


# v2 draws v1's worlds: the same seed gives the same layout, start and goal, on every tier.
@pytest.mark.parametrize("tier", ["room", "rooms2", "rooms3"])
def test_v2_has_the_v1_worlds(tier):
    ids = {"room": "GPISNav-Room", "rooms2": "GPISNav-Rooms2", "rooms3": "GPISNav"}[tier]
    a, b = _make(f"polar_sim/{ids}-v1", **TRUTH), _make(f"polar_sim/{ids}-v2", **TRUTH)
    for seed in (10_000, 10_001):
        _, ia = a.reset(seed=seed)
        _, ib = b.reset(seed=seed)
        assert ia["layout_seed"] == ib["layout_seed"]
        np.testing.assert_array_equal(ia["goal"], ib["goal"])
        np.testing.assert_allclose(ia["robot_pose2d"][:2], ib["robot_pose2d"][:2], rtol=0, atol=1e-3)
        np.testing.assert_array_equal(a.unwrapped.world.meta.occupancy, b.unwrapped.world.meta.occupancy)
    a.close()
    b.close()


# Driving straight into the outer wall ends the episode with a collision, found by MuJoCo's
# contacts, and the same seed replays the same episode after other episodes (the world is reused).
def test_v2_collision_and_replay_after_reuse():
    env = _make("polar_sim/GPISNav-Room-v2", **TRUTH)

    def episode(seed):
        env.reset(seed=seed)
        rows = []
        for _ in range(300):
            obs, r, term, trunc, info = env.step(np.float32([1.0, 0.0]))
            rows.append((r, obs["sdf"].copy(), info["robot_pose2d"].copy()))
            if term or trunc:
                return rows, info
        return rows, info

    first, info = episode(10_003)
    assert info["collision"] and not info["is_success"]
    episode(10_004)
    again, _ = episode(10_003)
    assert len(first) == len(again)
    for (r1, s1, p1), (r2, s2, p2) in zip(first, again):
        assert r1 == r2
        np.testing.assert_array_equal(s1, s2)
        np.testing.assert_array_equal(p1, p2)
    env.close()


# kinematic is a bool (or None, the version's default); v1 stays on the wheel physics.
def test_kinematic_argument():
    with pytest.raises(TypeError, match="kinematic"):
        _make("polar_sim/GPISNav-v1", kinematic="yes")
    assert _make("polar_sim/GPISNav-v1").unwrapped.base._kinematic is False
    assert _make("polar_sim/GPISNav-v2").unwrapped.base._kinematic is True
    assert _make("polar_sim/GPISNav-v1", kinematic=True).unwrapped.base._kinematic is True


# The registered versions are frozen: their map keeps the re-evaluation their episodes were recorded
# with (GPISMap2D's default became "on_returns" after them); sdf_params can still choose.
@pytest.mark.parametrize("env_id", ["polar_sim/GPISNav-v0", "polar_sim/GPISNav-Room-v1", "polar_sim/GPISNav-Room-v2"])
def test_registered_versions_keep_the_gated_reevaluation(env_id):
    from polar_sim.gpis import GPISMap2D

    assert GPISMap2D().get_params()["noise"].reevaluation == "on_returns"
    noise = lambda env: env.unwrapped._source.map.get_params()["noise"]  # noqa: E731
    assert noise(_make(env_id)).reevaluation == "gated"
    chosen = noise(_make(env_id, sdf_params={"noise__reevaluation": "on_returns", "noise__range_noise": 0.02}))
    assert (chosen.reevaluation, chosen.range_noise) == ("on_returns", 0.02)
