import numpy as np

from polar_sim.ground.depth import fuse, propagate


def test_propagation_is_exact_for_straight_motion():
    # Straight motion (ω = 0): z' = z - V dt exactly; the variance follows J² P + Q.
    d = np.array([0.1, 0.2, 0.5])
    u = np.array([0.1, -0.2, 0.3])
    d1, P1 = propagate(d, np.full(3, 0.5), u, 8.0, 0.0, 0.1, 0.02)
    np.testing.assert_allclose(d1, 1.0 / (1.0 / d - 0.8))
    np.testing.assert_allclose(P1, (d1 / d) ** 4 * 0.5 + 0.02)


def test_propagation_keeps_points_that_would_pass_behind():
    # A point closer than V dt keeps its value (spec §3.5).
    d1, P1 = propagate(np.array([2.0]), np.array([0.3]), np.array([0.0]), 8.0, 0.0, 0.1, 0.02)
    assert d1[0] == 2.0 and P1[0] == 0.3


def test_fusion_information_form():
    # Usable prior: precision-weighted mean; otherwise the measurement with the reset variance.
    d, P = fuse(np.array([0.2, 0.2]), np.array([0.6, 9.0]), np.array([0.3, 0.3]), np.array([True, False]), 0.6, 0.95)
    np.testing.assert_allclose(d, [0.25, 0.3])
    np.testing.assert_allclose(P, [0.3, 0.95])
