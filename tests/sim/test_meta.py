"""World.meta is its scene's frozen dataclass (polar_sim.sim.meta): every shipped scene declares one,
the fields a scene fills only with an option take their documented default otherwise, and a builder
that breaks the declaration (a wrong type, a wrong shape, a missing or undeclared key) is refused,
naming the field."""

import dataclasses

import numpy as np
import pytest

from polar_sim.sim.meta import SCENE_META, NavWorldMeta, SceneMeta, check_meta
from polar_sim.sim.scenes import list_scenes, load_scene


def test_every_shipped_scene_declares_its_meta():
    assert set(SCENE_META) == set(list_scenes())


# The option-dependent fields: their documented default without the option, the option's value with it.
@pytest.mark.parametrize("scene, options, expect", [(s, {}, {}) for s in list_scenes()] + [
    ("navworld", {}, {"pooled": False, "max_round_radius": 0.0}),
    ("navworld", {"pooled": True}, {"pooled": True, "max_round_radius": 0.35}),
    ("office2d", {}, {"tiles": 1}), ("office2d", {"tiles": 2}, {"tiles": 2}),
    ("tabletop", {}, {"appearance": None}), ("rover_flat", {}, {"appearance": None})])
def test_meta_is_the_declared_dataclass(scene, options, expect):
    _, meta = load_scene(scene, 1, **options)
    assert type(meta) is SCENE_META[scene]
    assert {k: getattr(meta, k) for k in expect} == expect
    with pytest.raises(dataclasses.FrozenInstanceError):
        meta.bounds = (0, 1, 0, 1)
    # to_dict / from_dict round trip: the same values, the very same objects
    back = type(meta).from_dict(meta.to_dict())
    assert all(getattr(back, f.name) is getattr(meta, f.name) for f in dataclasses.fields(meta))


@pytest.mark.parametrize("scene, family", [("tabletop", "random"), ("tabletop", "studio"), ("rover_flat", "random")])
def test_appearance_option_fills_the_field(scene, family):
    _, meta = load_scene(scene, 1, appearance=family)
    assert isinstance(meta.appearance, dict)
    assert family == "random" or meta.appearance["family"] == family


def test_mjcf_world_has_empty_meta(tmp_path):
    p = tmp_path / "box.xml"
    p.write_text("<mujoco><worldbody><geom type='box' size='1 1 1'/></worldbody></mujoco>")
    _, meta = load_scene(str(p))
    assert type(meta) is SceneMeta and meta.to_dict() == {}


def test_check_meta_names_the_broken_field():
    _, meta = load_scene("navworld", 1)
    d = meta.to_dict()
    with pytest.raises(TypeError, match=r"NavWorldMeta\.goal: expected ndarray, got list"):
        check_meta("navworld", {**d, "goal": [0.0, 1.0]})
    with pytest.raises(ValueError, match=r"NavWorldMeta\.goal: expected shape \(2,\), got \(3,\)"):
        check_meta("navworld", {**d, "goal": np.zeros(3)})
    with pytest.raises(ValueError, match=r"NavWorldMeta\.occupancy: expected shape \(n, n\), got \(5,\)"):
        check_meta("navworld", {**d, "occupancy": np.zeros(5, bool)})
    with pytest.raises(TypeError, match=r"missing \['goal'\], undeclared \['gaol'\]"):
        check_meta("navworld", {**{k: v for k, v in d.items() if k != "goal"}, "gaol": np.zeros(2)})
    with pytest.raises(TypeError, match="occupancy_res"):
        check_meta("navworld", {**d, "occupancy_res": "0.05"})
    with pytest.raises(TypeError, match="values: expected a dict"):
        NavWorldMeta.from_dict([("goal", np.zeros(2))])


# The old dict reading fails with a message that says how to read the field now.
def test_subscript_says_use_attributes():
    _, meta = load_scene("navworld", 1)
    with pytest.raises(TypeError, match=r"read w\.meta\.goal"):
        meta["goal"]
    with pytest.raises(TypeError, match=r"hasattr\(w\.meta, 'pooled'\)"):
        "pooled" in meta
