"""The map's parameters are checked when they are bound, not on every update (issue 35, item 5):
a rebinding (``set_params`` or an assignment) is seen by the next update, a bad one still raises
there, and the median of the beam spacing equals numpy's."""

import numpy as np
import pytest

from polar_sim.gpis import GPISMap2D
from polar_sim.gpis.config import DistanceConfig2D, NoiseConfig2D
from polar_sim.gpis.map2d import _median

from .scenes import room_path, scan_2d
from .test_behaviour import ANG


def _fit(m, n=4):
    for pose in room_path(n):
        m.update(ANG, scan_2d(pose, ANG), pose)
    return m


def _answers(m):
    P = np.array([[0.3, 0.2], [1.0, -0.5], [2.0, 1.0]])
    return np.concatenate([np.ravel(a) for a in m.query(P)] + [m.samples()["points"].ravel()])


def test_set_params_before_the_first_update_is_the_same_as_the_constructor():
    noise = NoiseConfig2D(range_noise=0.03)
    a = GPISMap2D()
    a._checked_params()                     # the defaults checked and kept
    a.set_params(noise=noise, max_range=8.0)
    b = GPISMap2D(noise=noise, max_range=8.0)
    np.testing.assert_array_equal(_answers(_fit(a)), _answers(_fit(b)))


def test_an_assignment_is_seen_by_the_next_update():
    a = _fit(GPISMap2D(), 2)
    a.max_range = 1.5                       # beams beyond 1.5 m are no returns from now on
    b = _fit(GPISMap2D(), 2)
    b.set_params(max_range=1.5)
    for m in (a, b):
        for pose in room_path(4)[2:]:
            m.update(ANG, scan_2d(pose, ANG), pose)
    np.testing.assert_array_equal(_answers(a), _answers(b))
    assert a._checked_params()["max_range"] == 1.5


def test_a_bad_assignment_raises_at_the_next_update_and_changes_nothing():
    m = _fit(GPISMap2D(), 2)
    before = _answers(m)
    m.min_range = -1.0
    pose = room_path(3)[2]
    with pytest.raises(ValueError, match="^min_range"):
        m.update(ANG, scan_2d(pose, ANG), pose)
    m.min_range = 0.2
    np.testing.assert_array_equal(_answers(m), before)


def test_switches_follow_set_params():
    m = GPISMap2D()
    assert not m._pub("query_mode")
    m.set_params(distance=DistanceConfig2D.published())
    assert m._pub("query_mode")
    m.set_params(distance__query_mode="faithful")
    assert not m._pub("query_mode")


@pytest.mark.parametrize("n", [1, 2, 3, 4, 269, 270, 1081])
def test_median_is_numpys(n):
    rng = np.random.default_rng(n)
    for scale in (1e-4, 1.0, 1e3):
        x = rng.normal(size=n) * scale
        assert _median(x) == float(np.median(x))
        x = np.full(n, 0.0043633)           # evenly spaced beams: all differences equal
        assert _median(x) == float(np.median(x))
