"""World: loading, stepping, kinematics, bad input, determinism."""

import numpy as np
import pytest

from polar_sim.sim import World, list_scenes


@pytest.fixture(scope="module")
def flat():
    w = World("rover_flat", seed=0, kinematic=True)
    yield w
    w.close()


# The five scenes of the issue are registered.
def test_list_scenes():
    assert {"rover_terrain", "rover_flat", "office2d", "tabletop", "object_orbit"} <= set(list_scenes())


# The kinematic rover follows the exact unicycle model to 1e-9 over turns and straights.
def test_kinematic_unicycle_exact(flat):
    flat.reset()
    x, y, th = flat.meta["start_pose2d"]
    rng = np.random.default_rng(3)
    for _ in range(50):
        v, w = rng.uniform(0, 9), rng.uniform(-0.8, 0.8)
        if rng.random() < 0.2:
            w = 0.0
        flat.step((v, w))
        dt = flat.dt
        # Closed-form unicycle integration of constant (v, w) over dt, written out independently.
        if w == 0.0:
            x, y = x + v * dt * np.cos(th), y + v * dt * np.sin(th)
        else:
            x, y = x + v / w * (np.sin(th + w * dt) - np.sin(th)), y + v / w * (np.cos(th) - np.cos(th + w * dt))
        th = th + w * dt
        T = flat.truth()["robot_pose"]
        assert abs(T[0, 3] - x) < 1e-9 and abs(T[1, 3] - y) < 1e-9
        assert abs(np.angle(np.exp(1j * (np.arctan2(T[1, 0], T[0, 0]) - th)))) < 1e-9
        tw = flat.truth()["robot_twist"]
        np.testing.assert_allclose(tw, [v, 0, 0, 0, 0, w], atol=1e-9)


# The wheel controller delivers commanded (v, omega) on flat ground within a few percent.
def test_wheel_controller_tracks_commands():
    with World("rover_flat", seed=1) as w:
        # Along the route (radius about 75 m), clear of the obstacles beside it.
        for _ in range(60):
            w.step((6.0, 0.08))
        tw = w.truth()["robot_twist"]
        assert not w.truth()["robot_collision"]
        assert abs(tw[0] - 6.0) < 0.1 and abs(tw[5] - 0.08) < 0.01


# The camera is level, forward-looking, at the configured height above flat ground.
def test_camera_height_and_level(flat):
    flat.reset()
    T = flat.truth()["cameras"]["front"]
    assert abs(T[2, 3] - 1.65) < 1e-9
    # Optical axis (OpenCV z) horizontal along the robot heading; image y points down.
    R = flat.truth()["robot_pose"][:3, :3]
    np.testing.assert_allclose(T[:3, 2], R[:, 0], atol=1e-9)
    np.testing.assert_allclose(T[:3, 1], [0, 0, -1], atol=1e-9)
    with World("rover_flat", seed=0, kinematic=True, camera_height=1.2) as w2:
        assert abs(w2.truth()["cameras"]["front"][2, 3] - 1.2) < 1e-9


# Bad input raises a clear error naming what was wrong, and the world stays usable.
def test_bad_input(flat, tmp_path):
    flat.reset()
    before = flat.truth()["robot_pose"]
    with pytest.raises(ValueError, match="action"):
        flat.step((1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match="NaN"):
        flat.step((np.nan, 0.0))
    with pytest.raises(ValueError, match="inf"):
        flat.step((np.inf, 0.0))
    with pytest.raises(ValueError, match="limits"):
        flat.step((50.0, 0.0))
    with pytest.raises(ValueError, match="unknown camera"):
        flat.camera("back")
    with pytest.raises(ValueError, match="unknown lidar"):
        flat.lidar("sonar")
    np.testing.assert_array_equal(flat.truth()["robot_pose"], before)
    flat.step((1.0, 0.0))  # still usable
    with pytest.raises(ValueError, match="unknown scene"):
        World("moon_base")
    with pytest.raises(FileNotFoundError):
        World(str(tmp_path / "missing.xml"))
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><geom type='box'")
    with pytest.raises(ValueError, match="malformed MJCF"):
        World(str(bad))
    with pytest.raises(ValueError, match="unknown scene option"):
        World("rover_flat", wheels=6)


# A user MJCF path loads as it is, with its declared lidar.
def test_mjcf_path(tmp_path):
    xml = tmp_path / "room.xml"
    xml.write_text("""<mujoco><custom><text name="sensor:scan" data="type=lidar2d site=s beams=360 fov_deg=360 min=0.05 max=10"/></custom>
    <worldbody><geom name="wall" type="box" pos="3 0 1" size="0.1 5 1"/><site name="s" pos="0 0 0.5"/>
    <camera name="cam" pos="0 0 0.5" xyaxes="0 -1 0 0 0 1"/></worldbody></mujoco>""")
    with World(str(xml)) as w:
        assert w.lidars == ("scan",) and w.cameras == ("cam",)
        s = w.lidar("scan")
        # The beam straight ahead hits the wall face at x = 2.9.
        i = np.argmin(np.abs(s.angles))
        assert abs(s.ranges[i] - 2.9) < 1e-9
        w.step()


# Same seed, same world: identical images, scans and truth; another seed, another layout.
def test_determinism():
    outs = []
    for _ in range(2):
        with World("rover_terrain", seed=5) as w:
            for _ in range(5):
                w.step((5.0, 0.1))
            f = w.camera("front", width=160, height=120)
            outs.append((f.rgb, f.depth, w.lidar("lidar3d").ranges, w.truth()["robot_pose"]))
    for a, b in zip(*outs):
        np.testing.assert_array_equal(a, b)
    with World("rover_terrain", seed=6) as w:
        assert not np.array_equal(w.meta["route"][:10], World("rover_terrain", seed=5).meta["route"][:10])


# close() frees renderers, is safe twice, and a closed world refuses to step.
def test_close():
    w = World("rover_flat", seed=0)
    w.camera("front", width=64, height=48)
    w.close()
    w.close()
    with pytest.raises(RuntimeError):
        w.step((1.0, 0.0))
