"""ECE and reliability statistics against analytic cases."""

import numpy as np
import pytest

from polar_sim import metrics


# labels drawn with exactly the predicted probability give ECE near 0 (sampling noise only)
def test_calibrated_probabilities_have_small_ece():
    rng = np.random.default_rng(0)
    p = rng.uniform(size=200_000)
    y = rng.uniform(size=p.size) < p
    assert metrics.expected_calibration_error(p, y) < 0.01


# a constant prediction 0.3 on a set that is 80 % positive: ECE = |0.8 - 0.3| exactly
def test_constant_prediction_ece_is_the_gap():
    y = np.zeros(1000, bool)
    y[:800] = True
    r = metrics.reliability(np.full(1000, 0.3), y)
    assert r.ece == pytest.approx(0.5, abs=1e-12) and r.mce == pytest.approx(0.5, abs=1e-12)
    assert r.count.sum() == 1000 and r.count[4] == 1000          # 0.3 falls in bin [4/15, 5/15)


# p = 1 falls in the last bin; the valid mask restricts the pixels; the bins follow the definition
def test_bins_and_valid_mask():
    p = np.array([[0.0, 1.0], [0.5, 0.99]])
    y = np.array([[False, True], [True, True]])
    r = metrics.reliability(p, y, n_bins=2, valid=np.array([[True, True], [False, True]]))
    assert r.n == 3 and list(r.count) == [1, 2]
    np.testing.assert_allclose(r.confidence, [0.0, 0.995])
    np.testing.assert_allclose(r.frequency, [0.0, 1.0])
    assert r.ece == pytest.approx(2 / 3 * 0.005)


# bad input names the argument
@pytest.mark.parametrize("prob, labels, kw, match", [
    (np.array([0.2, 1.2]), np.array([True, False]), {}, "prob"),
    (np.array([0.2, np.nan]), np.array([True, False]), {}, "prob"),
    (np.array([0.2, 0.4]), np.array([True]), {}, "labels"),
    (np.array([0.2, 0.4]), np.array([2, 0]), {}, "labels"),
    (np.array([0.2, 0.4]), np.array([True, False]), {"n_bins": 0}, "n_bins"),
    (np.array([0.2, 0.4]), np.array([True, False]), {"valid": np.array([1, 0])}, "valid"),
    (np.array([]), np.array([], bool), {}, "prob"),
])
def test_bad_input(prob, labels, kw, match):
    with pytest.raises(ValueError, match=match):
        metrics.reliability(prob, labels, **kw)
    with pytest.raises(TypeError, match="prob"):
        metrics.reliability(np.array(["a"]), np.array([True]))


# Summed per-frame reliability counts give exactly the reliability of the pooled samples.
def test_pooled_reliability_equals_reliability_of_the_pool():
    rng = np.random.default_rng(0)
    ps = [rng.random((6, 7)) for _ in range(4)]
    ys = [rng.random((6, 7)) < p for p in ps]
    summed = [sum(x) for x in zip(*[metrics.reliability_counts(p, y) for p, y in zip(ps, ys)])]
    a, b = metrics.pooled_reliability(*summed), metrics.reliability(np.stack(ps), np.stack(ys))
    assert a.n == b.n and np.isclose(a.ece, b.ece) and np.isclose(a.mce, b.mce)
    np.testing.assert_array_equal(a.count, b.count)
    with pytest.raises(ValueError, match="no samples"):
        metrics.pooled_reliability(np.zeros(15, int), np.zeros(15), np.zeros(15))


# Scoring never draws: the metrics package does not import matplotlib (plots are the experiments').
def test_metrics_import_no_matplotlib():
    import subprocess
    import sys

    code = "import sys, polar_sim.metrics; print('matplotlib' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == "False"
