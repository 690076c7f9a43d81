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
    x, y, th = flat.meta.start_pose2d
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


# kinematic="planar" is the same exact unicycle as kinematic=True on flat ground: the same pose,
# twist, sensor poses and scans to 1e-12 over turns and straights (its orientation is set in closed
# form instead of through a rotation matrix); on terrain it is refused.
def test_planar_kinematic_equals_the_kinematic_mode():
    a = World("rover_flat", seed=0, kinematic=True)
    b = World("rover_flat", seed=0, kinematic="planar")
    rng = np.random.default_rng(5)
    for _ in range(40):
        v, w = rng.uniform(0, 9), (0.0 if rng.random() < 0.2 else rng.uniform(-0.8, 0.8))
        a.step((v, w))
        b.step((v, w))
        ta, tb = a.truth(), b.truth()
        np.testing.assert_allclose(tb["robot_pose"], ta["robot_pose"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(tb["robot_twist"], ta["robot_twist"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(tb["lidars"]["lidar"], ta["lidars"]["lidar"], rtol=0, atol=1e-12)
        assert tb["robot_collision"] == ta["robot_collision"]
    np.testing.assert_allclose(b.lidar("lidar").ranges, a.lidar("lidar").ranges, rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="planar"):
        World("rover_terrain", seed=0, kinematic="planar")
    with pytest.raises(TypeError, match="kinematic"):
        World("rover_flat", seed=0, kinematic="plane")


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
        assert not np.array_equal(w.meta.route[:10], World("rover_terrain", seed=5).meta.route[:10])


# close() frees renderers, is safe twice, and a closed world refuses to step.
def test_close():
    w = World("rover_flat", seed=0)
    w.camera("front", width=64, height=48)
    w.close()
    w.close()
    with pytest.raises(RuntimeError):
        w.step((1.0, 0.0))


# World options are validated by name before anything is built (issue 17, finding 7).
@pytest.mark.parametrize("kwargs, exc, match", [
    ({"camera_height": -1.0}, ValueError, "camera_height"),
    ({"camera_height": "1.2"}, TypeError, "camera_height"),
    ({"camera_fovy": float("nan")}, ValueError, "camera_fovy"),
    ({"camera_fovy": 180.0}, ValueError, "camera_fovy"),
    ({"control_dt": "0.1"}, TypeError, "control_dt"),
    ({"control_dt": 0.0}, ValueError, "control_dt"),
    ({"control_dt": float("inf")}, ValueError, "control_dt"),
    ({"kinematic": "no"}, TypeError, "kinematic"),
    ({"kinematic": 1}, TypeError, "kinematic"),
    ({"seed": -1}, ValueError, "seed"),
    ({"seed": 1.5}, TypeError, "seed"),
    ({"seed": True}, TypeError, "seed"),
    ({"noise": ["lidar"]}, TypeError, "noise"),
    ({"rover": "tank"}, ValueError, "rover"),
    ({"rover": 3}, TypeError, "rover"),
])
def test_world_options_validated(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        World("rover_flat", **kwargs)


# Generic rover options of the indoor scenes are validated centrally too.
def test_indoor_options_validated():
    with pytest.raises(ValueError, match="lidar_beams"):
        World("navworld", lidar_beams=0)
    with pytest.raises(TypeError, match="lidar_beams"):
        World("navworld", lidar_beams=10.5)
    with pytest.raises(ValueError, match="camera_height"):
        World("office2d", camera_height=-0.5)


# Camera sizes are whole positive pixels within the offscreen buffer; names are strings.
def test_camera_size_and_names(flat):
    for w, h, exc in ((0, 24, ValueError), (32, 31.5, TypeError), (-4, 24, ValueError), (True, 24, TypeError),
                      (32, "24", TypeError), (100_000, 24, ValueError)):
        with pytest.raises(exc, match="width|height"):
            flat.camera("front", width=w, height=h)
    with pytest.raises(TypeError, match="name"):
        flat.camera(["front"])
    with pytest.raises(TypeError, match="name"):
        flat.lidar(0)
    with pytest.raises(ValueError, match="name"):
        flat.object_mesh("nope")
    f = flat.camera("front", width=33, height=21)
    assert f.rgb.shape == (21, 33, 3) and f.depth.shape == (21, 33)
    with pytest.raises(ValueError, match="elevation"):
        flat.render_view(width=32, height=24, elevation=float("nan"))


# Actions of the wrong kind are refused by name and leave the world as it was.
def test_action_kinds_refused(flat):
    flat.reset()
    before = (flat.data.qpos.copy(), flat.time)
    for bad in ([1 + 1j, 0.0], [True, False], np.array([None, 0.0], object), "1, 0", ["1", "0"]):
        with pytest.raises(TypeError, match="action"):
            flat.step(bad)
    np.testing.assert_array_equal(flat.data.qpos, before[0])
    assert flat.time == before[1]


def _mjcf(tmp_path, body="", custom="", option="", asset="", name="s.xml"):
    p = tmp_path / name
    p.write_text(f"<mujoco>{option}<asset>{asset}</asset><worldbody><site name='s'/><geom type='plane' size='5 5 .1'/>"
                 f"{body}</worldbody><custom>{custom}</custom></mujoco>")
    return str(p)


# Malformed lidar declarations in user MJCF fail with a message naming the key.
@pytest.mark.parametrize("decl, match", [
    ("type=lidar2d site=s beams=abc", "beams='abc' is not an integer"),
    ("type=lidar2d site=s beams=-5", "beams='-5' is out of range"),
    ("type=lidar2d site=s beams=1e9", "beams='1e9' is not an integer"),
    ("type=lidar2d site=s beams=2000000", "beams='2000000' is out of range"),
    ("type=lidar2d site=s fov_deg=nan", "fov_deg"),
    ("type=lidar2d site=s min=5 max=1", "min=5.0 must be smaller than max=1.0"),
    ("type=lidar2d site=s bogus=1", "unknown key"),
    ("type=lidar3d site=s rows=2000 cols=2000", "MAX_LIDAR_RAYS"),
    ("type=lidar3d site=s vfov_min_deg=20 vfov_max_deg=-20", "vfov_min_deg"),
    ("type=sonar site=s", "unknown sensor type"),
    ("type=lidar2d site=nope", "site 'nope' does not exist"),
])
def test_mjcf_lidar_declarations(tmp_path, decl, match):
    p = _mjcf(tmp_path, custom=f"<text name='sensor:l' data='{decl}'/>")
    with pytest.raises(ValueError, match=match):
        World(p)


# Malformed scenes fail before anything renders: bad XML, a zero timestep, a missing mesh, files
# outside the scene folder, a huge asset.
def test_malformed_mjcf(tmp_path, monkeypatch):
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><geom type='sphere' size='.1'></worldbody>")
    with pytest.raises(ValueError, match="malformed MJCF"):
        World(str(bad))
    with pytest.raises(ValueError, match="timestep"):
        World(_mjcf(tmp_path, option="<option timestep='0'/>"))
    with pytest.raises(FileNotFoundError, match="nope.stl"):
        World(_mjcf(tmp_path, asset="<mesh name='m' file='nope.stl'/>", body="<geom type='mesh' mesh='m'/>"))
    with pytest.raises(ValueError, match="outside the scene folder"):
        World(_mjcf(tmp_path, asset="<mesh name='m' file='../../../etc/passwd'/>", body="<geom type='mesh' mesh='m'/>"))
    inc = tmp_path / "inc.xml"
    inc.write_text("<mujoco><include file='/etc/hosts'/></mujoco>")
    with pytest.raises(ValueError, match="outside the scene folder"):
        World(str(inc))
    import trimesh

    trimesh.creation.icosphere(subdivisions=3).export(tmp_path / "ball.stl")
    p = _mjcf(tmp_path, asset="<mesh name='m' file='ball.stl'/>", body="<geom type='mesh' mesh='m'/>", name="ball.xml")
    World(p).close()                                   # within the limits it loads
    import polar_sim.sim.scenes as scenes

    monkeypatch.setattr(scenes, "MAX_ASSET_BYTES", 1000)
    with pytest.raises(ValueError, match="MAX_ASSET_BYTES"):
        World(p)
    monkeypatch.setattr(scenes, "MAX_ASSET_BYTES", 2**30)
    monkeypatch.setattr(scenes, "MAX_MESH_FACES", 100)
    with pytest.raises(ValueError, match="MAX_MESH_FACES"):
        World(p)
    for path in ("/tmp/" + "x" * 5000 + ".xml", str(tmp_path / "ñandú √.xml"), str(tmp_path / "a\x00.xml")):
        with pytest.raises((ValueError, FileNotFoundError), match="scene"):
            World(path)
    monkeypatch.setattr(scenes, "MAX_MESH_FACES", 10**7)
    with World(p) as w, pytest.raises(ValueError, match="name: unknown camera"):
        w.camera("front")
