"""polar_sim.geometry: the shared algorithms defined once (diameter, pinhole intrinsics)."""

import numpy as np
import pytest


# The diameter is the largest pairwise distance (brute force is the truth), on hulls, flat sets,
# collinear sets and sets too small for a hull; and the intrinsics are MuJoCo's pinhole.
@pytest.mark.parametrize("kind", ["cloud", "flat", "line", "three", "one", "planar2d"])
def test_diameter_is_the_largest_pairwise_distance(kind):
    from scipy.spatial.distance import pdist

    from polar_sim.geometry import diameter

    rng = np.random.default_rng(3)
    P = {"cloud": rng.normal(size=(2500, 3)), "flat": np.c_[rng.normal(size=(300, 2)), np.zeros(300)],
         "line": np.outer(rng.uniform(-1, 1, 40), [1.0, 2.0, -0.5]), "three": rng.normal(size=(3, 3)),
         "one": np.zeros((1, 3)), "planar2d": rng.normal(size=(500, 2))}[kind]
    truth = float(pdist(P).max()) if len(P) > 1 else 0.0
    assert diameter(P) == pytest.approx(truth, rel=1e-12, abs=0.0)


def test_pinhole_intrinsics():
    from polar_sim.geometry import pinhole_intrinsics

    K = pinhole_intrinsics(640, 480, 90.0)  # fovy 90 deg: f = H/2
    np.testing.assert_allclose(K, [[240.0, 0, 319.5], [0, 240.0, 239.5], [0, 0, 1]], rtol=1e-14)
