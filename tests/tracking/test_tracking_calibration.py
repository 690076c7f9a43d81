"""Online calibration of P(target) (polar_sim.tracking.calibration) against known miscalibrations."""

import numpy as np

from polar_sim import metrics
from polar_sim.tracking.calibration import OnlineCalibration, isotonic


def test_isotonic_matches_brute_force_pooling():
    # PAV pools exactly the violating runs: [1, 3, 2, 4] with unit weights -> [1, 2.5, 2.5, 4]
    assert np.allclose(isotonic([1, 3, 2, 4], [1, 1, 1, 1]), [1, 2.5, 2.5, 4])
    # weighted pooling, and an already monotone input is unchanged
    assert np.allclose(isotonic([2.0, 0.0], [3.0, 1.0]), [1.5, 1.5])
    y = np.sort(np.random.default_rng(0).random(20))
    assert np.allclose(isotonic(y, np.ones(20)), y)


def test_untrained_map_is_the_identity():
    # with no labels the calibrated probability is sigmoid(z) up to the bin interpolation
    z = np.linspace(-7, 7, 101)
    assert np.abs(OnlineCalibration()(z) - 1 / (1 + np.exp(-z))).max() < 0.02


def test_learns_an_overconfident_map():
    # labels drawn with P(target) = sigmoid(z / 3): the raw sigmoid(z) is badly overconfident; after
    # 20 updates the calibrated map has ECE < 0.02 on fresh samples, and it stays monotone
    rng = np.random.default_rng(1)
    cal = OnlineCalibration()

    def draw(n):
        z = rng.uniform(-8, 8, n)
        return z, rng.random(n) < 1 / (1 + np.exp(-z / 3))

    for _ in range(20):
        cal.update(*draw(5000))
    z, y = draw(50000)
    raw = 1 / (1 + np.exp(-z))
    assert metrics.expected_calibration_error(raw, y) > 0.1
    assert metrics.expected_calibration_error(cal(z), y) < 0.02
    p = cal(np.linspace(-8, 8, 200))
    assert np.all(np.diff(p) >= 0)


def test_fading_follows_a_change():
    # counts fade (decay 0.9): after the labels change, the map follows within 30 updates
    rng = np.random.default_rng(2)
    cal = OnlineCalibration()
    z = rng.uniform(-8, 8, 5000)
    for _ in range(30):
        cal.update(z, np.ones(5000, bool))
    assert cal(np.array([-6.0]))[0] > 0.8
    for _ in range(30):
        cal.update(z, np.zeros(5000, bool))
    assert cal(np.array([6.0]))[0] < 0.2
