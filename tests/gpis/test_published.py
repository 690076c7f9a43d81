"""The published behaviour as a named preset built from parameters (issue 17, item 1)."""

import numpy as np
import pytest

from polar_sim.gpis import GPISMap2D, GPISMap3D

from .scenes import room_path, scan_2d
from .test_behaviour import ANG, _map3d


# published() is the constructor with PUBLISHED's parameters; overrides win; unknown names raise
@pytest.mark.parametrize("cls", [GPISMap2D, GPISMap3D])
def test_published_preset(cls):
    m = cls.published()
    assert m.get_params() == cls(**cls.PUBLISHED).get_params()
    assert m.legacy is False
    for k, v in cls.PUBLISHED.items():
        assert getattr(m, k) == v and v == cls._PUBLISHED_CHOICE[k]
    # every behaviour parameter of the class is in the preset (nothing is left to legacy)
    assert {k for k in cls.CHOICES if k in cls._PARAMS} == set(cls.PUBLISHED)
    assert cls.published(map_scale=0.5).map_scale == 0.5
    with pytest.raises(ValueError, match="nonsense"):
        cls.published(nonsense=1)


# the preset, built from parameters, builds the same map as legacy=True, bit for bit (2D, 3D):
# samples, normals, noises and query answers
def test_published_same_map():
    a = GPISMap2D.published(sensor_offset=(0.08, 0.0))
    b = GPISMap2D(legacy=True, sensor_offset=(0.08, 0.0))
    for pose in room_path(4):
        r = scan_2d(pose, ANG, offset=(0.08, 0.0))
        a.update(ANG, r, pose)
        b.update(ANG, r, pose)
    for k, v in b.samples().items():
        np.testing.assert_array_equal(a.samples()[k], v)
    pts = np.random.default_rng(0).uniform(-1.0, 9.0, (500, 2))
    for x, y in zip(a.query(pts), b.query(pts)):
        np.testing.assert_array_equal(x, y)
    m3, p3 = _map3d(2, **GPISMap3D.PUBLISHED), _map3d(2, legacy=True)
    for k, v in p3.samples().items():
        np.testing.assert_array_equal(m3.samples()[k], v)
    q = p3.samples()["points"][:30] + 0.002
    for x, y in zip(m3.query(q), p3.query(q)):
        np.testing.assert_array_equal(x, y)


# set_params checks the new values and leaves the map unchanged on a bad one
def test_set_params_checked():
    m = GPISMap2D()
    with pytest.raises(ValueError, match="map_scale"):
        m.set_params(map_scale=-1.0)
    assert m.map_scale == 1.2
    assert m.set_params(map_scale=1.0).map_scale == 1.0
    with pytest.raises(ValueError, match="retrain"):
        m.set_params(retrain="sometimes")
    assert m.retrain == "changed"


# on the published demo's gazebo1 scans the preset equals legacy=True (the parity tests' map)
def test_published_on_gazebo1_demo():
    from polar_sim.datasets import load_gazebo1

    g = load_gazebo1()
    a = GPISMap2D.published(sensor_offset=g["sensor_offset"])
    b = GPISMap2D(legacy=True, sensor_offset=g["sensor_offset"])
    for k in g["demo_frames"][:40]:
        a.update(g["thetas"], g["ranges"][k], g["poses"][k])
        b.update(g["thetas"], g["ranges"][k], g["poses"][k])
    for k, v in b.samples().items():
        np.testing.assert_array_equal(a.samples()[k], v)


def test_set_params_on_a_fitted_map_refuses_a_new_geometry_and_the_file_still_loads(tmp_path):
    # a fitted map whose tree geometry changed could be saved but never loaded again (load checks
    # the tree against the parameters): the change is refused, the map unchanged; others round-trip
    from polar_sim.gpis import GPISMap2D

    ang = np.linspace(-np.pi / 2, np.pi / 2, 181)
    m = GPISMap2D()
    m.update(ang, 2.0 / np.maximum(np.cos(ang), 0.3), np.zeros(3))
    before = m.query(np.array([[1.0, 0.2], [1.5, -0.3]]))
    for bad in (dict(cluster_half=0.4), dict(init_half=6.4), dict(min_half=0.1)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            m.set_params(**bad)
        assert m.get_params()[next(iter(bad))] == GPISMap2D().get_params()[next(iter(bad))]
    m.set_params(obs_noise=0.02)
    m.save(tmp_path / "m.npz")
    back = GPISMap2D.load(tmp_path / "m.npz")
    assert back.obs_noise == 0.02
    for a, b in zip(before, back.query(np.array([[1.0, 0.2], [1.5, -0.3]]))):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    m.reset().set_params(cluster_half=0.4)          # after reset() it is allowed
    assert m.cluster_half == 0.4
