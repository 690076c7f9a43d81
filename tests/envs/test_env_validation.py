"""Environment and World arguments the hostile probe found accepted silently (issue 34): each is
refused with a TypeError/ValueError naming the argument (and the limit, for sizes), before
anything is built or any state changes."""

import gymnasium as gym
import numpy as np
import pytest

import polar_sim.envs  # noqa: F401  (registers the ids)
from polar_sim.envs import ENV_IDS
from polar_sim.testing.digest import state_digest

MAX_SPEED_IDS = ["polar_sim/LidarNav-v1", "polar_sim/GPISNav-v1", "polar_sim/GPISNav-Room-v2", "polar_sim/RoverDrive-v0",
                 "polar_sim/GroundVO-v0", "polar_sim/TabletopReach-v0", "polar_sim/ObjectTrack-v0"]


def _make(env_id, **kw):
    return gym.make(env_id, disable_env_checker=True, **kw)


# grid_size and grid_resolution are checked whatever obs_mode is (the stencil mode ignored them).
@pytest.mark.parametrize("obs_mode", ["stencil", "grid"])
@pytest.mark.parametrize("bad, exc", [(None, TypeError), ("x", TypeError), (2**63, ValueError), (3, ValueError),
                                      (32.0, TypeError), (True, TypeError)])
def test_grid_size_is_checked_in_every_obs_mode(obs_mode, bad, exc):
    with pytest.raises(exc, match="grid_size"):
        _make("polar_sim/GPISNav-v1", obs_mode=obs_mode, grid_size=bad)
    with pytest.raises(ValueError, match="grid_resolution"):
        _make("polar_sim/GPISNav-v1", obs_mode=obs_mode, grid_resolution=1e300)


# A speed limit given as a string is refused (it was parsed) in every env that takes one.
@pytest.mark.parametrize("env_id", MAX_SPEED_IDS)
def test_max_speed_string_is_refused(env_id):
    with pytest.raises(TypeError, match="max_speed"):
        _make(env_id, max_speed="0.1")
    with pytest.raises(ValueError, match="max_speed"):
        _make(env_id, max_speed=-1.0)


# render_size is (width, height) of positive ints within the limit.
@pytest.mark.parametrize("bad, exc", [((0, 0), ValueError), ((640,), TypeError), ("640x480", TypeError),
                                      ((1.5, 2), TypeError), ((10**6, 10), ValueError), ((True, 4), TypeError)])
def test_render_size_is_checked(bad, exc):
    with pytest.raises(exc, match="render_size"):
        _make("polar_sim/LidarNav-v1", render_size=bad)
    with pytest.raises(exc, match="render_size"):
        _make("polar_sim/GPISNav-Room-v1", render_size=bad)


# The world's size options beyond what memory or time allow raise, naming the argument and the
# limit, before anything is allocated (rooms=10**12 used to hang with memory growing).
@pytest.mark.parametrize("kw, name, limit", [({"rooms": 10**12}, "rooms", "16"), ({"clutter": 10**12}, "clutter", "500"),
                                             ({"rooms": 10, "room_size": 40.0}, "room_size", "100"),
                                             ({"room_size": 1.0}, "room_size", "2.2")])
def test_world_size_limits(kw, name, limit):
    with pytest.raises(ValueError, match=name) as err:
        _make("polar_sim/GPISNav-v1", **kw)
    assert limit in str(err.value)


# Sizes of the wrong type are refused by name (a float room count, a string clutter count).
@pytest.mark.parametrize("kw, name", [({"rooms": 2.0}, "rooms"), ({"clutter": "3"}, "clutter"), ({"tier": ["room"]}, "tier")])
def test_world_size_types(kw, name):
    with pytest.raises((TypeError, ValueError), match=name):
        _make("polar_sim/GPISNav-v1", **kw)


# The stencil's shape is checked as the other sizes are.
@pytest.mark.parametrize("kw, name", [({"stencil_rays": "16"}, "stencil_rays"), ({"stencil_rays": 2**40}, "stencil_rays"),
                                      ({"stencil_radii": (0.5, -1.0)}, "stencil_radii"),
                                      ({"stencil_radii": np.ones(100)}, "stencil_radii")])
def test_stencil_shape_is_checked(kw, name):
    with pytest.raises((ValueError, TypeError), match=name):
        _make("polar_sim/GPISNav-v1", **kw)


# reset(options=...) takes only the options an env documents: any other key is refused by name,
# before the world is built or the generator reseeded; None and {} are no options.
@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_unknown_reset_options_are_refused_by_name(env_id):
    env = _make(env_id)
    try:
        with pytest.raises(ValueError, match="bogus"):
            env.reset(seed=0, options={"bogus": 1})
        with pytest.raises(TypeError, match="options"):
            env.reset(seed=0, options="bogus")
        assert env.unwrapped.world is None  # nothing was built
    finally:
        env.close()


# A refused reset leaves a running episode exactly as it was; accepted options are used.
def test_refused_reset_keeps_the_episode():
    env = _make("polar_sim/GPISNav-Room-v2", pose_source="truth", sdf_source="truth")
    env.reset(seed=3, options={})
    env.reset(seed=3, options=None)
    env.step(np.float32([0.5, 0.1]))
    before = state_digest(env.unwrapped, ignore=("_renderer",))
    with pytest.raises(ValueError, match="layout"):
        env.reset(seed=4, options={"layout": 1})
    assert state_digest(env.unwrapped, ignore=("_renderer",)) == before
    env.close()


# The RoverDrive appearance option is still taken, and checked before the world changes.
def test_rover_appearance_option_is_checked():
    env = _make("polar_sim/RoverDrive-v0", route_length=50.0)
    with pytest.raises((ValueError, TypeError), match="appearance"):
        env.reset(seed=0, options={"appearance": "no-such-look"})
    assert env.unwrapped.world is None
    env.close()


# World's boolean switches take booleans only (depth="yes" was taken by its truth value).
def test_world_switches_are_booleans():
    from polar_sim.sim import World

    with World("navworld", seed=0, rooms=1, room_size=6.0, clutter=0) as w:
        for kw, name in (({"depth": "yes"}, "depth"), ({"labels": 1}, "labels")):
            with pytest.raises(TypeError, match=name):
                w.camera("front", width=32, height=24, **kw)
        with pytest.raises(TypeError, match="noise"):
            w.lidar("lidar", noise="no")
        assert w.camera("front", width=32, height=24, depth=False, labels=False).depth is None
