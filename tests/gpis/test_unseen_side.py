"""An object seen from one side: the map's variance says that its far side was never observed.

Drawn by value alone, the distance behind such an object is an extrapolation (the wedges and
teardrops of "inside" in a map picture); the variance there is the prior ``1 + map_noise``, which
is how pictures and users can tell (the demo greys such cells out)."""

import numpy as np
import pytest

from polar_sim.gpis import GPISMap2D

DISC, R = np.array([2.0, 0.0]), 0.3              # a round table 0.6 m across, 2 m ahead, nothing behind it
ANG = np.deg2rad(np.arange(-135.0, 135.0, 0.25))


def _ranges(origin):
    d = np.stack([np.cos(ANG), np.sin(ANG)], 1)
    oc = origin - DISC
    b = d @ oc
    disc = b**2 - (oc @ oc - R**2)
    with np.errstate(invalid="ignore"):
        t = -b - np.sqrt(disc)
    return np.where((disc >= 0) & (t > 0), t, np.inf)


@pytest.fixture(scope="module")
def one_sided():
    m = GPISMap2D()
    for y in np.linspace(-0.2, 0.2, 20):          # a short sideways drive, facing the disc
        o = np.array([0.0, y])
        m.update(ANG, _ranges(o), np.array([o[0], o[1], 0.0]))
    return m


def test_far_side_has_the_prior_variance(one_sided):
    m = one_sided
    x, y = np.meshgrid(np.linspace(2.9, 3.6, 8), np.linspace(-0.15, 0.15, 7))
    shadow = np.stack([x.ravel(), y.ravel()], 1)   # behind the disc, in its shadow from every pose
    assert np.all(np.linalg.norm(shadow - DISC, axis=1) - R > 0.55)   # truly free space, never seen
    _, _, v = m.query(shadow)
    np.testing.assert_array_equal(v, np.full(len(v), 1.0 + m.noise.map_noise))
    front = np.stack([np.linspace(0.6, 1.4, 9), np.zeros(9)], 1)   # seen free space between robot and disc
    d, _, vf = m.query(front)
    assert np.all(vf < 0.1)
    np.testing.assert_allclose(d, np.linalg.norm(front - DISC, axis=1) - R, atol=0.03)
