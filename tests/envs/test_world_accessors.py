"""The World accessors the environments use instead of reaching into it (issue 17): camera
options, intrinsics, hand commands, noise-free scans."""

import numpy as np
import pytest

from polar_sim.sim import World
from polar_sim.sim.sensors import RangeNoise


# An RGB-only render is the full render's RGB, bit for bit; depth and labels are then None, and
# camera_intrinsics gives the frame's K at any size.
def test_camera_options_and_intrinsics():
    w = World("rover_flat", seed=0)
    full = w.camera("front", width=160, height=120)
    rgb = w.camera("front", width=160, height=120, depth=False, labels=False)
    np.testing.assert_array_equal(full.rgb, rgb.rgb)
    assert rgb.depth is None and rgb.labels is None and rgb.geom_ids is None and full.depth is not None
    np.testing.assert_array_equal(w.camera_intrinsics("front", width=160, height=120), full.K)
    with pytest.raises(ValueError, match="unknown camera"):
        w.camera_intrinsics("back")
    w.close()


# The exact scan ignores the noise model and draws nothing from its generator: the noisy scans
# around it are those of a world that never cast it.
def test_noise_free_lidar():
    noise = {"lidar": RangeNoise(sigma=0.01, dropout=0.05)}
    a, b = (World("navworld", seed=1, rooms=1, room_size=6.0, clutter=2, noise=noise) for _ in range(2))
    exact = a.lidar("lidar", noise=False).ranges
    s1, s2 = a.lidar("lidar").ranges, b.lidar("lidar").ranges
    np.testing.assert_array_equal(s1, s2)
    ok = np.isfinite(exact) & np.isfinite(s1)
    assert 0.005 < np.std(s1[ok] - exact[ok]) < 0.02 and np.all(np.isfinite(exact) | (exact == np.inf))
    a.close()
    b.close()


# Hand commands: tabletop's reach script moves the hand; a scene without a commanded hand and
# non-finite commands raise ValueError.
def test_command_hand():
    w = World("tabletop", seed=0, script="reach")
    p0 = w.truth()["hand_pose"][:3, 3].copy()
    w.command_hand([0.1, 0.0, 0.0], 0.0)
    for _ in range(5):
        w.step()
    assert w.truth()["hand_pose"][0, 3] - p0[0] > 0.005
    with pytest.raises(ValueError, match="velocity"):
        w.command_hand([np.nan, 0.0, 0.0], 0.0)
    w.close()
    nav = World("navworld", seed=0, rooms=1)
    with pytest.raises(ValueError, match="command_hand"):
        nav.command_hand([0.1, 0.0, 0.0], 0.0)
    nav.close()
