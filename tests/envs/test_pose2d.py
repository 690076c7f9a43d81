"""The per-step planar pose helpers equal polar_sim.geometry's array forms bit for bit."""

import numpy as np

from polar_sim.envs import _pose2d
from polar_sim.geometry import between2d, compose2d, inv2d


# Random poses, angles far outside [-pi, pi) and exact multiples of pi included: every result is
# identical to the array form's, bit for bit (the environments' episodes depend on it).
def test_scalar_forms_equal_the_array_forms_bit_for_bit():
    rng = np.random.default_rng(0)
    a = rng.uniform(-50, 50, (3000, 3))
    b = rng.uniform(-50, 50, (3000, 3))
    a[:100, 2] = np.pi * rng.integers(-6, 7, 100)
    b[100:200, 2] = -a[100:200, 2]
    for x, y in zip(a, b):
        np.testing.assert_array_equal(_pose2d.compose(x, y), compose2d(x, y))
        np.testing.assert_array_equal(_pose2d.inverse(x), inv2d(x))
        np.testing.assert_array_equal(_pose2d.between(x, y), between2d(x, y))
