"""Stage configs of GPISMap2D/3D (issue 34): one frozen dataclass per stage that checks its fields,
nested ``stage__field`` parameters, and ``published()`` as the one route to the published behaviour."""

import dataclasses
import inspect
import json

import numpy as np
import pytest

from polar_sim.gpis import GPISMap2D, GPISMap3D
from polar_sim.gpis.config import SWITCHES, LocalGPConfig2D, NoiseConfig2D, TreeConfig2D, TreeConfig3D

from .test_behaviour import _map2d

CLASSES = [GPISMap2D, GPISMap3D]


# at most 15 constructor arguments: the sensor's few, then one config per stage
@pytest.mark.parametrize("cls", CLASSES)
def test_constructor_takes_stage_configs(cls):
    names = cls._param_names()
    assert len(names) <= 15
    assert names[-5:] == ["observation", "noise", "tree", "local_gp", "distance"] == list(cls._STAGES)
    sig = inspect.signature(cls.__init__).parameters
    for stage, config in cls._STAGES.items():
        assert sig[stage].default == config() and dataclasses.is_dataclass(config)
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(config(), dataclasses.fields(config)[0].name, 1.0)


# every switch of every stage is in the one table, and published() sets each to its published
# value; the defaults are the table's first values
@pytest.mark.parametrize("cls", CLASSES)
def test_published_sets_every_switch(cls):
    default, pub = cls(), cls.published()
    seen = set()
    for stage, config in cls._STAGES.items():
        for f in dataclasses.fields(config):
            if f.name in SWITCHES:
                seen.add(f.name)
                assert getattr(getattr(default, stage), f.name) == SWITCHES[f.name][0]
                assert getattr(getattr(pub, stage), f.name) == SWITCHES[f.name][1]
                assert pub._pub(f.name) and not default._pub(f.name)
            else:   # the preset changes only the switches
                assert getattr(getattr(pub, stage), f.name) == getattr(getattr(default, stage), f.name)
    assert seen == set(SWITCHES) - ({"scan_model"} if cls is GPISMap3D else set())
    assert pub.get_params(deep=False).keys() == default.get_params(deep=False).keys()


@pytest.mark.parametrize("cls", CLASSES)
def test_published_overrides(cls):
    m = cls.published(local_gp__map_scale=0.5, tree__spacing_rule="strict")
    assert m.local_gp.map_scale == 0.5 and m.local_gp.retrain == "box"
    assert m.tree.spacing_rule == "strict"
    gp = cls._STAGES["local_gp"]()
    assert cls.published(local_gp=gp).local_gp is gp        # a whole config is used as given
    for bad, name in (({"nonsense": 1}, "nonsense"), ({"tree__nonsense": 1}, "tree__nonsense"),
                      ({"nonsense__x": 1}, "nonsense__x"), ({"local_gp__map_scale": -1.0}, "local_gp__map_scale")):
        with pytest.raises(ValueError, match=f"^{name}"):
            cls.published(**bad)


# each field is checked when the config is made; the error names it
@pytest.mark.parametrize("config,field,bad,exc", [
    (LocalGPConfig2D, "map_scale", 0.0, ValueError), (LocalGPConfig2D, "map_scale", np.inf, ValueError),
    (LocalGPConfig2D, "fbias", -0.1, ValueError), (LocalGPConfig2D, "retrain", "sometimes", ValueError),
    (LocalGPConfig2D, "map_scale", "1.2", TypeError), (NoiseConfig2D, "scan_model", "x", ValueError),
    (NoiseConfig2D, "min_grad_noise", np.nan, ValueError), (TreeConfig3D, "init_half", 0.3, ValueError),
    (TreeConfig3D, "max_half", -1.0, ValueError)])
def test_fields_are_checked(config, field, bad, exc):
    with pytest.raises(exc, match=field):
        config(**{field: bad})


# a map's stage must be its own dimension's config (the 2D defaults are no 3D map)
def test_stage_of_the_other_dimension_is_refused():
    with pytest.raises(TypeError, match="^tree: expected a TreeConfig3D"):
        GPISMap3D(tree=GPISMap2D().tree)
    m = GPISMap2D()
    with pytest.raises(TypeError, match="^local_gp"):
        m.set_params(local_gp=GPISMap3D().local_gp)
    assert m.local_gp == LocalGPConfig2D()


# set_params checks the new values and leaves the map unchanged on a bad one
def test_set_params_checked():
    m = GPISMap2D()
    with pytest.raises(ValueError, match="^local_gp__map_scale"):
        m.set_params(local_gp__map_scale=-1.0)
    assert m.local_gp.map_scale == 1.2
    assert m.set_params(local_gp__map_scale=1.0).local_gp.map_scale == 1.0
    with pytest.raises(ValueError, match="^local_gp__retrain"):
        m.set_params(local_gp__retrain="sometimes")
    assert m.local_gp.retrain == "changed"
    with pytest.raises(ValueError, match="^min_range/max_range"):
        m.set_params(min_range=40.0)
    assert m.min_range == 0.2


def test_set_params_on_a_fitted_map_refuses_a_new_geometry_and_the_file_still_loads(tmp_path):
    # a fitted map whose tree geometry changed could be saved but never loaded again (load checks
    # the tree against the parameters): the change is refused, the map unchanged; others round-trip
    ang = np.linspace(-np.pi / 2, np.pi / 2, 181)
    m = GPISMap2D()
    m.update(ang, 2.0 / np.maximum(np.cos(ang), 0.3), np.zeros(3))
    pts = np.array([[1.0, 0.2], [1.5, -0.3]])
    before = m.query(pts)
    for bad in (dict(tree__cluster_half=0.4), dict(tree__init_half=6.4), dict(tree__min_half=0.1)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            m.set_params(**bad)
        assert m.tree == TreeConfig2D()
    m.set_params(observation__obs_noise=0.02)
    m.save(tmp_path / "m.npz")
    back = GPISMap2D.load(tmp_path / "m.npz")
    assert back.observation.obs_noise == 0.02 and back.get_params() == m.get_params()
    for a, b in zip(before, back.query(pts)):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    m.reset().set_params(tree__cluster_half=0.4)          # after reset() it is allowed
    assert m.tree.cluster_half == 0.4


# the file stores each stage config as an object of its fields (format version 2 on); a version-1
# file (flat parameters, legacy=True for the published behaviour, no face runs) still loads, as the
# same map
def test_version1_file_loads(tmp_path):
    m = _map2d(3, published=True, local_gp__map_scale=1.1)
    m.save(tmp_path / "v3.npz")
    with np.load(tmp_path / "v3.npz", allow_pickle=False) as z:
        d = {k: z[k] for k in z.files if k != "tree/run"}
    params = json.loads(str(d["params"]))
    assert params["local_gp"]["map_scale"] == 1.1
    flat = {k: v for k, v in params.items() if not isinstance(v, dict)}
    for stage in GPISMap2D._STAGES:
        flat.update({k: v for k, v in params[stage].items() if k not in SWITCHES})
    flat["legacy"] = True
    np.savez(tmp_path / "v1.npz", **{**d, "version": np.array(1), "params": np.array(json.dumps(flat))})
    back = GPISMap2D.load(tmp_path / "v1.npz")
    assert back.get_params() == m.get_params()
    pts = m.samples()["points"][:50] + 0.02
    for a, b in zip(m.query(pts), back.query(pts)):
        np.testing.assert_array_equal(a, b)
    np.savez(tmp_path / "v1bad.npz", **{**d, "version": np.array(1),
                                        "params": np.array(json.dumps({**flat, "legacy": "yes"}))})
    with pytest.raises(ValueError, match="params"):
        GPISMap2D.load(tmp_path / "v1bad.npz")
