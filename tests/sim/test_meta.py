"""World.meta follows its scene's declaration (polar_sim.sim.meta), and the check finds a builder
that breaks it."""

import numpy as np
import pytest

from polar_sim.sim.meta import SCENE_META, check_meta
from polar_sim.sim.scenes import list_scenes, load_scene


def test_every_shipped_scene_declares_its_meta():
    assert set(SCENE_META) == set(list_scenes())


# load_scene runs check_meta; the keys a scene declares optional appear only with their option.
@pytest.mark.parametrize("scene, options, optional", [(s, {}, set()) for s in list_scenes()] + [
    ("navworld", {"pooled": True}, {"pooled", "max_round_radius"}), ("office2d", {"tiles": 2}, {"tiles"}),
    ("tabletop", {"appearance": "random"}, {"appearance"}), ("rover_flat", {"appearance": "random"}, set())])
def test_meta_follows_the_declaration(scene, options, optional):
    _, meta = load_scene(scene, 1, **options)
    decl = SCENE_META[scene]
    assert decl.__required_keys__ <= set(meta) <= decl.__required_keys__ | decl.__optional_keys__
    assert set(meta) - decl.__required_keys__ == optional


def test_check_meta_names_the_broken_key():
    _, meta = load_scene("navworld", 1)
    with pytest.raises(TypeError, match=r"meta\['goal'\] is a list, declared ndarray"):
        check_meta("navworld", {**meta, "goal": [0.0, 1.0]})
    with pytest.raises(TypeError, match=r"missing \['goal'\], undeclared \['gaol'\]"):
        check_meta("navworld", {**{k: v for k, v in meta.items() if k != "goal"}, "gaol": np.zeros(2)})
    with pytest.raises(TypeError, match="occupancy_res"):
        check_meta("navworld", {**meta, "occupancy_res": "0.05"})
