"""gymnasium's check_env over every registered id, and over every GPISNav-v1 tier x obs_mode x
pose_source; where the ids are registered, and what ``import polar_sim`` pulls in."""

import subprocess
import sys
import warnings

import gymnasium as gym
import pytest
from gymnasium.utils.env_checker import check_env

from polar_sim.envs import ENV_IDS
from polar_sim.envs.gpis_nav import OBS_MODES
from polar_sim.envs.lidar_nav import TIERS
from polar_sim.envs.localization import POSE_SOURCES

# Shorter episodes for the camera environments (the checks do not depend on the route length).
SMALL = {"polar_sim/RoverDrive-v0": {"route_length": 50.0}, "polar_sim/GroundVO-v0": {"route_length": 50.0}}


def _check(env_id, **kw):
    env = gym.make(env_id, render_mode="rgb_array", **kw)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped)  # determinism, fresh data, spaces, every render mode, double close
        return [str(w.message) for w in caught]
    finally:
        env.close()


# Every registered id passes without a warning: module envs are checked as composed, since the
# composition is the unwrapped env.
@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_check_env_every_registered_id(env_id):
    assert _check(env_id, **SMALL.get(env_id, {})) == []


# Every tier, obs_mode and pose_source of GPISNav-v1 (and the grid's visited channel).
@pytest.mark.parametrize("tier", sorted(TIERS))
@pytest.mark.parametrize("obs_mode", OBS_MODES)
@pytest.mark.parametrize("pose_source", POSE_SOURCES)
def test_check_env_every_tier_obs_mode_pose_source(tier, obs_mode, pose_source):
    kw = {"grid_visited": True} if (obs_mode == "grid" and tier == "room") else {}
    assert _check("polar_sim/GPISNav-v1", tier=tier, obs_mode=obs_mode, pose_source=pose_source, **kw) == []


# `import polar_sim` (and its modules) imports neither gymnasium nor registers anything;
# `import polar_sim.envs` registers every id, and the module-prefixed id does so by itself.
def test_registration_lives_in_polar_sim_envs():
    code = ("import sys, polar_sim, polar_sim.metrics, polar_sim.geometry; "
            "assert 'gymnasium' not in sys.modules, 'gymnasium imported'; "
            "import gymnasium as gym; from gymnasium.envs.registration import registry; "
            "assert not [k for k in registry if k.startswith('polar_sim/')]; "
            "e = gym.make('polar_sim.envs:polar_sim/GPISNav-v1', tier='room'); "
            "import polar_sim.envs as pe; assert set(pe.ENV_IDS) <= set(registry); print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]
