"""ObjectTrack-v0 and its raw base TabletopReach-v0: the gymnasium contract, seeding, bad input,
the composition, vector environments and the visual-servo baseline, scored
against truth."""

import os
import warnings

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from gymnasium.utils.env_checker import check_env, data_equivalence  # noqa: E402
from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv  # noqa: E402

import polar_sim.envs  # noqa: E402, F401
from polar_sim.envs.policies import VisualServoReach  # noqa: E402
from polar_sim.envs.tabletop_reach_v0 import TabletopReachEnv  # noqa: E402

ENV_ID = "polar_sim/ObjectTrack-v0"
KEYS = ["hand_pose", "object_pose", "object_std", "pregrasp"]


def _rollout(env, seed, actions):
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    for a in actions:
        obs, _, _, _, info = env.step(a)
        out.append((obs, info))
    return out


def test_check_env_gymnasium_and_sb3():
    # gymnasium's checker (determinism, fresh data, every render mode, double close) and SB3's
    # checker pass without a warning.
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(ENV_ID, render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
        sb3_check_env(env.unwrapped, warn=True, skip_render_check=True)
    assert [str(w.message) for w in caught] == []
    frame = env.unwrapped.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    env.close()
    env.close()


def test_seeded_episodes_replay_and_the_composition_is_its_raw_base():
    # reset(seed=s) replays bit for bit over several steps (physics, disturbance, noise, tracker),
    # and ObjectTrack-v0 is TabletopReach-v0 plus the tracker: its base is the raw env, whose
    # observation (hand pose) and truth it replays exactly.
    actions = [np.array([-0.5, -0.5, -0.3, 0.2], np.float32)] * 4
    env = gym.make(ENV_ID)
    a = _rollout(env, 5, actions)
    b = _rollout(env, 5, actions)
    assert isinstance(env.unwrapped.base, TabletopReachEnv)
    raw = gym.make("polar_sim/TabletopReach-v0")
    c = _rollout(raw, 5, actions)
    for (oa, ia), (ob, ib), (oc, ic) in zip(a, b, c):
        assert sorted(oa) == KEYS and sorted(oc) == ["depth", "hand_pose", "rgb"]
        assert data_equivalence(oa, ob, exact=True) and data_equivalence(ia, ib, exact=True)
        assert data_equivalence(oa["hand_pose"], oc["hand_pose"], exact=True)
        for k in ("object_pose", "position_error", "time"):
            assert data_equivalence(ia[k], ic[k], exact=True)
        assert oa in env.observation_space
    assert not data_equivalence(_rollout(env, 6, [])[0][1]["object_pose"], a[0][1]["object_pose"])
    env.close()
    raw.close()


def test_image_obs_and_the_raw_env_give_rgbd():
    # image_obs=True adds uint8 RGB and float32 metric depth (0 = no return, within [0, 10] m) at
    # the reduced 320x240 size, whose intrinsics are the scene's scaled by 1/2.
    env = gym.make(ENV_ID, image_obs=True)
    obs, _ = env.reset(seed=1)
    assert sorted(obs) == sorted(KEYS + ["depth", "rgb"]) and obs in env.observation_space
    assert obs["rgb"].dtype == np.uint8 and obs["rgb"].shape == (240, 320, 3)
    assert obs["depth"].dtype == np.float32 and 0.5 < np.median(obs["depth"]) < 3.0
    K = env.unwrapped.task.K
    assert K[0, 0] == pytest.approx(585.0 / 2, rel=1e-3) and K[0, 2] == pytest.approx(159.5)
    env.close()
    raw = gym.make("polar_sim/TabletopReach-v0")
    assert sorted(raw.observation_space.spaces) == ["depth", "hand_pose", "rgb"]
    raw.close()


def test_bad_input_raises_clearly():
    # Unknown kwargs list the valid ones; bad values, actions outside the box or with NaN raise
    # ValueError; stepping before reset or after close raises; a second close is safe.
    with pytest.raises(TypeError, match="valid:.*tracker_params"):
        gym.make(ENV_ID, speed=1.0)
    for kw in ({"target": "teapot"}, {"n_objects": 7}, {"max_speed": 0.0}, {"tracker": "icg"},
               {"camera_size": (10, 10)}, {"tracker": 3}):
        with pytest.raises((ValueError, TypeError)):
            gym.make(ENV_ID, **kw)
    env = gym.make(ENV_ID)
    with pytest.raises(RuntimeError, match="reset"):
        env.unwrapped.step(np.zeros(4, np.float32))
    env.reset(seed=0)
    for bad in ([0.0, 0.0, 1.2, 0.0], [np.nan, 0.0, 0.0, 0.0], [0.1, 0.1]):
        with pytest.raises(ValueError, match="action"):
            env.step(np.array(bad))
    env.close()
    env.close()
    with pytest.raises(RuntimeError, match="close"):
        env.step(np.zeros(4, np.float32))


def test_vector_envs_sync_and_async_spawn():
    # Both vector envs run the id (Async in spawned children, module-prefixed id); a child's
    # seeded reset equals the parent's, bit for bit, across processes.
    make = lambda: gym.make("polar_sim.envs:polar_sim/ObjectTrack-v0")  # noqa: E731
    ref = make()
    obs0, _ = ref.reset(seed=31)
    ref.close()
    for vec in (SyncVectorEnv([make, make], autoreset_mode=AutoresetMode.NEXT_STEP),
                AsyncVectorEnv([make, make], context="spawn", autoreset_mode=AutoresetMode.NEXT_STEP)):
        obs, info = vec.reset(seed=[31, 32])
        assert np.array_equal(obs["object_pose"][0], obs0["object_pose"])
        for _ in range(2):
            obs, rew, term, trunc, info = vec.step(np.zeros((2, 4), np.float32))
        assert obs["pregrasp"].shape == (2, 4) and np.isfinite(rew).all() and "tracking_error" in info
        vec.close()


def test_visual_servo_reaches_the_moving_object_against_truth():
    # The scripted baseline, acting on the tracker's estimate only, closes most of the distance
    # to the true pre-grasp pose while the disturbance slides the object; the tracker follows it.
    env = gym.make(ENV_ID)
    policy = VisualServoReach()
    obs, info = env.reset(seed=2)
    policy.reset()
    start, d0 = info["object_pose"][:3, 3].copy(), info["position_error"]
    moved, worst = 0.0, 0.0
    for _ in range(60):
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        moved = max(moved, float(np.linalg.norm(info["object_pose"][:3, 3] - start)))
        worst = max(worst, info["tracking_error"])
        if terminated:
            break
    assert moved > 0.02  # the disturbance slid the object
    assert worst < 0.01  # tracked within 1 cm (object origin) all the way
    assert info["position_error"] < 0.25 * d0
    G, H = info["pregrasp_pose"], info["hand_pose"]
    assert info["position_error"] == pytest.approx(np.linalg.norm(G[:3, 3] - H[:3, 3]))
    assert info["is_success"] == (info["position_error"] < 0.02 and abs(info["yaw_error"]) < np.radians(10))
    assert set(info["reward_terms"]) == {"distance", "success", "dropped"} and not info["dropped"]
    assert reward == pytest.approx(sum(info["reward_terms"].values()))
    env.close()


class _FrozenTracker:
    """A tracker of one's own: always reports the initial pose, with no covariance."""

    def __init__(self, model_points, K, initial_pose, model_normals=None, random_state=0):
        self.T = np.array(initial_pose)

    def process(self, rgb, depth, t):
        from types import SimpleNamespace

        return SimpleNamespace(pose=self.T.copy())


def test_a_tracker_of_ones_own_plugs_in():
    # A factory passed as tracker= replaces ObjectTracker: its pose, mapped through the camera
    # pose, is the estimate; without a covariance the uncertainty reads as the bound (unknown).
    env = gym.make(ENV_ID, tracker=_FrozenTracker)
    obs, info = env.reset(seed=0)
    np.testing.assert_allclose(info["est_object_pose"], env.unwrapped.task.initial_object_pose, atol=1e-9)
    assert np.all(obs["object_std"] == 10.0) and obs in env.observation_space
    env.close()
