"""Randomised rover appearance: labels against the exact geometry for every family, determinism per
seed, geometry independent of the appearance, exact sky colours, and bad specs."""

import numpy as np
import pytest

from polar_sim.sim import LABELS, World
from polar_sim.sim.builders.appearance_textures import ground_family_texture
from polar_sim.sim.builders.rover_appearance import FAMILIES, RANDOM_FAMILIES, SKIES, resolve_appearance, sample_appearance
from polar_sim.sim.scenes import scene_options


def _backproject(f):
    H, W = f.depth.shape
    v, u = np.mgrid[0:H, 0:W]
    z = f.depth.astype(np.float64)
    ok = np.isfinite(z)
    pc = np.stack([(u - f.K[0, 2]) / f.K[0, 0] * z, (v - f.K[1, 2]) / f.K[1, 1] * z, z], -1)[ok]
    return pc @ f.T_world_cam[:3, :3].T + f.T_world_cam[:3, 3], ok


def _drive(w, n=12):
    for _ in range(n):
        w.step((6.0, 0.05))


# Every family (and "random"): the ground label of each pixel agrees with the exact geometry (the
# back-projected point's nearest surface is the terrain) on >= 99.9 % of pixels; sky pixels are "none".
@pytest.mark.parametrize("appearance", list(FAMILIES) + ["random"])
def test_ground_labels_agree_with_geometry(appearance):
    with World("rover_terrain", seed=10_001, appearance=appearance) as w:
        _drive(w)
        f = w.camera("front", width=320, height=240)
        P, ok = _backproject(f)
        on_ground = w.nearest_surface(P) == LABELS["ground"]
        labelled = f.labels[ok] == LABELS["ground"]
        assert labelled.mean() > 0.3  # the camera sees the ground
        assert np.mean(on_ground == labelled) >= 0.999
        assert np.all(f.labels[~ok] == LABELS["none"])


# The geometry, the route and the truth do not depend on the appearance: one seed, one world.
def test_geometry_is_independent_of_the_appearance():
    with World("rover_flat", seed=7) as a, World("rover_flat", seed=7, appearance="checker") as b:
        np.testing.assert_array_equal(a.meta.route, b.meta.route)
        np.testing.assert_array_equal(a.model.geom_pos, b.model.geom_pos)
        np.testing.assert_array_equal(a.model.geom_size, b.model.geom_size)
        _drive(a)
        _drive(b)
        np.testing.assert_array_equal(a.truth()["robot_pose"], b.truth()["robot_pose"])
        fa, fb = a.camera("front", width=160, height=120), b.camera("front", width=160, height=120)
        np.testing.assert_array_equal(fa.labels, fb.labels)
        np.testing.assert_array_equal(fa.depth, fb.depth)
        assert not np.array_equal(fa.rgb, fb.rgb)
        assert a.meta.appearance is None and b.meta.zones == ["checker"] * 4


# Same seed, same pixels; the resolved spec in meta rebuilds the same pixels under another world seed's
# geometry-free parts; another seed draws another appearance.
def test_determinism_and_round_trip_of_the_resolved_spec():
    def render(seed, appearance):
        with World("rover_flat", seed=seed, appearance=appearance) as w:
            return w.camera("front", width=160, height=120).rgb, w.meta.appearance

    a, spec = render(3, "random")
    b, spec_b = render(3, "random")
    np.testing.assert_array_equal(a, b)
    assert spec == spec_b
    c, _ = render(3, spec)  # the explicit spec (texture seed included) gives the same pixels
    np.testing.assert_array_equal(a, c)
    assert sample_appearance(4) != sample_appearance(3)
    # A family name fixes the ground; sky, light and texture seed come from the seed alone.
    s1, s2 = sample_appearance(5, "gravel"), sample_appearance(5, "stripes")
    assert s1["sky"] == s2["sky"] and s1["light"] == s2["light"] and s1["texture_seed"] == s2["texture_seed"]
    assert {z["family"] for z in s1["ground"]} == {"gravel"}


# "random" draws from the families it always drew from, in their order, so the random looks of the
# recorded routes (test_random_*) stay as they were when a family is added; pavers is never drawn.
def test_random_draws_only_the_random_families():
    assert list(RANDOM_FAMILIES) == [f for f in FAMILIES if f != "pavers"]
    drawn = {z["family"] for seed in range(200) for z in sample_appearance(seed)["ground"]}
    assert drawn == set(RANDOM_FAMILIES)


# Pavers: dark joints one course apart across the courses, and the bricks of a course are offset by
# half a brick from the next course's.
def test_pavers_joints_follow_the_courses():
    z = resolve_appearance({"ground": {"family": "pavers", "contrast": 0.0, "courses": 8, "ratio": 2}}, 0)["ground"][0]
    opts = {k: v for k, v in z.items() if k not in ("family", "scale_m")}
    img = ground_family_texture("pavers", np.random.default_rng(0), size=256, **opts).astype(float).mean(axis=2)
    row_mean = img.mean(axis=1)  # 8 courses of 32 px: the joints at 0, 32, ... are the dark rows
    dark = np.argsort(row_mean)[:8]
    assert set(dark % 32) <= {0, 31}
    # In course 0 the vertical joints are at x = 0, 64, ...; in course 1 at x = 32, 96, ...
    c0, c1 = img[8:24].mean(axis=0), img[40:56].mean(axis=0)
    assert c0[0] < c0[32] and c1[32] < c1[0]


# A plain sky is an unlit skybox: every sky pixel has exactly the sky colour.
@pytest.mark.parametrize("colour", [[0, 0, 0], [200, 30, 40]])
def test_plain_sky_pixels_have_the_sky_colour(colour):
    with World("rover_flat", seed=1, appearance={"sky": {"kind": "plain", "colour": colour}}) as w:
        f = w.camera("front", width=160, height=120)
        sky = f.labels == LABELS["none"]
        assert sky.sum() > 1000
        assert np.abs(f.rgb[sky].astype(int) - np.array(colour)).max() <= 1


# A brighter sun brightens the sunlit ground; the default light is that of the base scene.
def test_light_intensity_scales_the_ground_brightness():
    def ground_mean(intensity):
        spec = {"ground": {"family": "uniform", "contrast": 0.0}, "light": {"intensity": intensity, "ambient": 0.0}}
        with World("rover_flat", seed=1, appearance=spec) as w:
            f = w.camera("front", width=160, height=120)
            return f.rgb[f.labels == LABELS["ground"]].mean()

    assert ground_mean(0.5) < ground_mean(1.0) < ground_mean(1.5)


# Every family's texture tiles: the step across the wrap-around edge is no larger than inside.
@pytest.mark.parametrize("family", list(FAMILIES))
def test_family_textures_tile_seamlessly(family):
    z = resolve_appearance({"ground": {"family": family}}, 0)["ground"][0]
    opts = {k: v for k, v in z.items() if k not in ("family", "scale_m")}
    img = ground_family_texture(family, np.random.default_rng(0), size=128, **opts).astype(float)
    inner = np.abs(np.diff(img, axis=1)).mean(axis=(0, 2))
    wrap = np.abs(img[:, 0] - img[:, -1]).mean()
    assert wrap <= inner.max() + 1e-9
    inner_r = np.abs(np.diff(img, axis=0)).mean(axis=(1, 2))
    assert np.abs(img[0] - img[-1]).mean() <= inner_r.max() + 1e-9


# The option is listed; unknown families, kinds and fields raise ValueError naming them and the valid ones.
def test_bad_appearance_specs_raise():
    assert scene_options("rover_flat")["appearance"] is None
    assert scene_options("rover_terrain")["appearance"] is None
    with pytest.raises(ValueError, match=r"'marble'.*speckle.*blotches"):
        World("rover_flat", appearance="marble")
    cases = [
        ({"ground": {"family": "tartan"}}, r"appearance\.ground\[0\]\.family.*'tartan'.*checker"),
        ({"ground": [{"family": "checker", "colour": [1, 2]}]}, r"appearance\.ground\[0\]\.colour"),
        ({"ground": [{"family": "checker", "stripes": 3}]}, r"appearance\.ground\[0\].*unknown field.*'stripes'"),
        ({"ground": [{"family": "gravel", "contrast": -1}]}, r"appearance\.ground\[0\]\.contrast"),
        ({"ground": [{"colour": [1, 2, 3]}]}, r"appearance\.ground\[0\].*'family'"),
        ({"ground": []}, r"appearance\.ground"),
        ({"sky": {"kind": "aurora"}}, r"appearance\.sky\.kind.*'aurora'.*" + ".*".join(SKIES)),
        ({"sky": {"kind": "plain", "colour2": [0, 0, 0]}}, r"appearance\.sky.*'colour2'"),
        ({"light": {"intensity": float("nan")}}, r"appearance\.light\.intensity"),
        ({"light": {"colour": [2.0, 1.0, 1.0]}}, r"appearance\.light\.colour"),
        ({"lights": {}}, r"appearance.*unknown field.*'lights'"),
        ({"texture_seed": -3}, r"appearance\.texture_seed"),
        ({"ground": [{"family": "pavers", "courses": 9, "ratio": 2}]}, r"appearance\.ground\[0\]\.courses.*multiple"),
        ({"ground": [{"family": "pavers", "joint": 0.5}]}, r"appearance\.ground\[0\]\.joint"),
    ]
    for spec, match in cases:
        with pytest.raises(ValueError, match=match):
            World("rover_flat", appearance=spec)
    with pytest.raises(ValueError, match="appearance"):
        World("rover_flat", appearance=3)


# The gymnasium wrapper draws a new appearance per episode, repeatably under a seed, from the allowed
# families only; the camera image changes with it; a bad family raises.
def test_appearance_randomization_wrapper():
    import gymnasium as gym

    from polar_sim.envs.appearance import AppearanceRandomization

    env = AppearanceRandomization(gym.make("polar_sim/RoverDrive-v0", camera_size=(160, 48), supersample=False),
                                  families=["checker", "stripes"])
    try:
        o1, i1 = env.reset(seed=4)
        o2, i2 = env.reset()
        o1b, i1b = env.reset(seed=4)
        assert i1["appearance"] == i1b["appearance"] and np.array_equal(o1["rgb"], o1b["rgb"])
        assert i1["appearance"] != i2["appearance"]
        for info in (i1, i2):
            fams = {z["family"] for z in info["appearance"]["ground"]}
            assert len(fams) == 1 and fams <= {"checker", "stripes"}
        _, _, _, _, info = env.step(np.zeros(2, np.float32))
        assert info["appearance"] == i1["appearance"]
        # An explicit appearance in the reset options wins.
        o3, i3 = env.reset(seed=4, options={"appearance": "grass"})
        assert i3["appearance"] == "grass" and not np.array_equal(o3["rgb"], o1["rgb"])
    finally:
        env.close()
    with pytest.raises(ValueError, match="families"):
        AppearanceRandomization(gym.make("polar_sim/RoverDrive-v0"), families=["moss"])
