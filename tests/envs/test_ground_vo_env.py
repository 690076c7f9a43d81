"""GroundVO-v0 and its raw base RoverDrive-v0: the gymnasium contract, seeding, bad input, the
composition, vector environments and the pure-pursuit baseline, scored against truth."""

import os
import warnings

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from gymnasium.utils.env_checker import check_env, data_equivalence  # noqa: E402
from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv  # noqa: E402

import polar_sim.envs  # noqa: E402, F401
from polar_sim.envs.policies import PurePursuitVO  # noqa: E402
from polar_sim.envs.rover_drive_v0 import RoverDriveEnv  # noqa: E402

ENV_ID = "polar_sim/GroundVO-v0"
KEYS = ["ground_prob", "pose", "twist", "waypoint"]


def _rollout(env, seed, actions):
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    for a in actions:
        obs, _, _, _, info = env.step(a)
        out.append((obs, info))
    return out


def test_check_env_gymnasium_and_sb3():
    # gymnasium's checker (determinism, fresh data, every render mode, double close) raises no
    # warning; SB3's only notes that the ground-probability image is a float 2D array.
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(ENV_ID, render_mode="rgb_array", route_length=100.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert [str(w.message) for w in caught] == []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(env.unwrapped, warn=True, skip_render_check=True)
    assert all("ground_prob" in str(w.message) and "unconventional shape" in str(w.message) for w in caught)
    frame = env.unwrapped.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    env.close()
    env.close()


def test_seeded_episodes_replay_and_the_composition_is_its_raw_base():
    # reset(seed=s) replays bit for bit over several steps, and GroundVO-v0 is RoverDrive-v0 plus
    # the VO: its base is the raw env, whose truth it replays exactly.
    actions = [np.array([0.3, 0.05], np.float32)] * 4
    env = gym.make(ENV_ID, route_length=100.0)
    a = _rollout(env, 11, actions)
    b = _rollout(env, 11, actions)
    assert isinstance(env.unwrapped.base, RoverDriveEnv)
    raw = gym.make("polar_sim/RoverDrive-v0", route_length=100.0)
    c = _rollout(raw, 11, actions)
    for (oa, ia), (ob, ib), (oc, ic) in zip(a, b, c):
        assert sorted(oa) == KEYS and sorted(oc) == ["rgb"]
        assert data_equivalence(oa, ob, exact=True) and data_equivalence(ia, ib, exact=True)
        for k in ("robot_pose2d", "progress", "cross_track_error", "time"):
            assert data_equivalence(ia[k], ic[k], exact=True)
        assert oa in env.observation_space
    assert not data_equivalence(_rollout(env, 12, [])[0][0], a[0][0])  # another seed, another world
    env.close()
    raw.close()


def test_actions_at_the_bound_are_clipped_and_rejected_ones_change_nothing():
    # Issue 17, finding 5: float32 [1.0000001] * 2 lies within the box's tolerance; it is the
    # bound, on the raw env and the composition alike. An action beyond it raises and leaves the
    # speed command as it was: the next step equals that of an env that never saw it.
    for env_id in ("polar_sim/RoverDrive-v0", ENV_ID):
        a, b = gym.make(env_id, route_length=50.0), gym.make(env_id, route_length=50.0)
        a.reset(seed=3)
        b.reset(seed=3)
        oa = a.step(np.float32([1.0000001] * 2))[0]
        ob = b.step(np.float32([1.0, 1.0]))[0]
        assert data_equivalence(oa, ob, exact=True)
        with pytest.raises(ValueError, match="outside the action space"):
            a.step(np.float32([1.2, 0.0]))
        step = np.float32([0.5, -0.2])
        assert data_equivalence(a.step(step), b.step(step), exact=True)
        a.close()
        b.close()


def test_image_obs_adds_the_camera_image():
    # image_obs=True adds the uint8 RGB image, in the space; the raw env observes only the image.
    env = gym.make(ENV_ID, image_obs=True, route_length=50.0)
    obs, _ = env.reset(seed=0)
    assert sorted(obs) == sorted(KEYS + ["rgb"]) and obs["rgb"].dtype == np.uint8
    assert obs in env.observation_space and obs["rgb"].shape == (188, 621, 3)
    env.close()
    raw = gym.make("polar_sim/RoverDrive-v0")
    assert list(raw.observation_space.spaces) == ["rgb"]
    raw.close()


def test_bad_input_raises_clearly():
    # Unknown kwargs list the valid ones; bad values, actions outside the box or with NaN raise
    # ValueError; stepping before reset or after close raises; a second close is safe.
    with pytest.raises(TypeError, match="valid:.*waypoint_lookahead"):
        gym.make(ENV_ID, lookahead=5)
    for kw in ({"route_length": -1.0}, {"max_speed": 20.0}, {"scene": "office2d"}, {"vo": "orbslam"},
               {"camera_size": (10, 10)}):
        with pytest.raises((ValueError, TypeError)):
            gym.make(ENV_ID, **kw)
    env = gym.make(ENV_ID, route_length=50.0)
    with pytest.raises(RuntimeError, match="reset"):
        env.unwrapped.step(np.zeros(2, np.float32))
    env.reset(seed=0)
    for bad in ([1.5, 0.0], [0.0, np.nan], [0.1, 0.1, 0.1], ["a", "b"]):
        with pytest.raises(ValueError, match="action"):
            env.step(np.array(bad, dtype=object if isinstance(bad[0], str) else np.float64))
    env.close()
    env.close()
    with pytest.raises(RuntimeError, match="close"):
        env.step(np.zeros(2, np.float32))


def test_vector_envs_sync_and_async_spawn():
    # Both vector envs run the id (Async in spawned children, module-prefixed id); a child's
    # seeded reset equals the parent's, bit for bit, across processes.
    make = lambda: gym.make("polar_sim.envs:polar_sim/GroundVO-v0", route_length=50.0)  # noqa: E731
    ref = make()
    obs0, _ = ref.reset(seed=21)
    ref.close()
    for vec in (SyncVectorEnv([make, make], autoreset_mode=AutoresetMode.NEXT_STEP),
                AsyncVectorEnv([make, make], context="spawn", autoreset_mode=AutoresetMode.NEXT_STEP)):
        obs, info = vec.reset(seed=[21, 22])
        assert np.array_equal(obs["pose"][0], obs0["pose"])
        assert np.array_equal(obs["ground_prob"][0], obs0["ground_prob"])
        for _ in range(2):
            obs, rew, term, trunc, info = vec.step(np.tile(np.array([0.3, 0.0], np.float32), (2, 1)))
        assert obs["waypoint"].shape == (2, 2) and np.isfinite(rew).all() and "drift" in info
        vec.close()


def test_pure_pursuit_on_vo_makes_progress_against_truth():
    # The scripted baseline drives 12 s on its own odometry: it follows the route (true progress
    # and cross-track error) and the estimate stays near the truth; info holds the truth.
    env = gym.make(ENV_ID, route_length=300.0)
    policy = PurePursuitVO()
    obs, info = env.reset(seed=3)
    policy.reset()
    assert info["progress"] < 1.0 and not info["is_success"] and info["drift"] < 1e-6
    for _ in range(120):
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        assert not terminated
    assert info["progress"] > 40.0 and info["cross_track_error"] < 2.0
    assert info["drift"] == pytest.approx(np.hypot(*(info["est_pose2d"][:2] - info["robot_pose2d"][:2])))
    # Early drift is mostly along the route: the VO's speed filter lags the start (about 7 %
    # after 50 m); the heading, which decides where the rover ends up, stays within 0.05 rad.
    assert info["drift"] < 0.12 * info["path_length"] and abs(info["heading_error"]) < 0.05
    assert set(info["reward_terms"]) == {"progress", "cross_track", "fail", "success"}
    assert reward == pytest.approx(sum(info["reward_terms"].values()))
    env.close()


class _StandStillVO:
    """A VO of one's own: always at the first camera pose, not moving."""

    def __init__(self, K, camera_height, seed=None):
        self.K = K

    def process(self, rgb, t):
        from types import SimpleNamespace

        return SimpleNamespace(pose=np.eye(4), speed=0.0, yaw_rate=0.0, status="mine")


def test_a_vo_of_ones_own_plugs_in():
    # A factory passed as vo= replaces GroundVO: its pose, chained onto the start pose, is the
    # estimate; without a ground_prob the image is zeros.
    env = gym.make(ENV_ID, vo=_StandStillVO, route_length=50.0)
    obs, info = env.reset(seed=0)
    obs, _, _, _, info = env.step(np.array([0.5, 0.0], np.float32))
    start = env.unwrapped.task.start_pose
    np.testing.assert_allclose(info["est_pose2d"][:2], start[:2, 3], atol=1e-9)
    assert info["vo_status"] == "mine" and not obs["ground_prob"].any() and obs in env.observation_space
    env.close()


def test_the_default_vo_is_set_for_the_rover():
    # The environment's GroundVO knows the rover's sideways slip (a constant of the robot, as its camera
    # height is); a vo_params entry still wins.
    from polar_sim.envs.observers import _make_groundvo
    from polar_sim.ground import MotionConfig
    from polar_sim.sim.recorders.rover_sequences import ROVER_SLIP

    K = np.array([[300.0, 0.0, 310.0], [0.0, 300.0, 94.0], [0.0, 0.0, 1.0]])
    assert ROVER_SLIP > 0 and _make_groundvo(K, 1.65, seed=0).motion.slip == ROVER_SLIP
    assert _make_groundvo(K, 1.65, seed=0, motion=MotionConfig(slip=0.0)).motion.slip == 0.0
