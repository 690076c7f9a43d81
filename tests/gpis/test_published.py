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
    assert m.legacy is True
    assert cls.published(map_scale=0.5).map_scale == 0.5
    with pytest.raises(ValueError, match="nonsense"):
        cls.published(nonsense=1)


# the preset builds the same map as the explicit parameters, bit for bit (2D and 3D)
def test_published_same_map():
    a = GPISMap2D.published(sensor_offset=(0.08, 0.0))
    b = GPISMap2D(legacy=True, sensor_offset=(0.08, 0.0))
    for pose in room_path(4):
        r = scan_2d(pose, ANG, offset=(0.08, 0.0))
        a.update(ANG, r, pose)
        b.update(ANG, r, pose)
    pts = b.samples()["points"][:30] + 0.02
    for x, y in zip(a.query(pts), b.query(pts)):
        np.testing.assert_array_equal(x, y)
    m3, p3 = _map3d(1, **GPISMap3D.PUBLISHED), _map3d(1, legacy=True)
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
