"""Online Platt calibration: recovers a known logistic law; GroundVO's calibrated map is better calibrated
than its raw posterior on the synthetic corridor (scored against the exact ground mask)."""

import numpy as np
from ground_helpers import run

from polar_sim.ground import CalibrationConfig, GroundVO
from polar_sim.ground.calibration import PlattCalibrator, sigmoid
from polar_sim.ground.classifier import GroundColourModel
from polar_sim.metrics.calibration import expected_calibration_error


# Labels drawn from P(y | z) = σ(a z + b): the fit recovers (a, b), and its output is then calibrated.
def test_platt_recovers_a_logistic_law():
    rng = np.random.default_rng(0)
    a, b = 2.0, -0.7
    cal = PlattCalibrator(decay=1.0, prior_weight=1.0, balance=False)
    for _ in range(20):
        z = rng.normal(0, 2, 2000)
        cal.update(z, rng.random(2000) < sigmoid(a * z + b))
    np.testing.assert_allclose(cal.coef_, [a, b], atol=0.08)
    z = rng.normal(0, 2, 50_000)
    y = rng.random(50_000) < sigmoid(a * z + b)
    assert expected_calibration_error(cal.transform(z), y) < 0.01


# With balanced classes the intercept corresponds to a 50/50 sample: a 10 % positive sample gives the
# same law as a 50 % one.
def test_balance_removes_the_sample_class_ratio():
    rng = np.random.default_rng(1)
    fits = []
    for share in (0.1, 0.5):
        cal = PlattCalibrator(decay=1.0, prior_weight=1.0, balance=True)
        for _ in range(20):
            y = rng.random(3000) < share
            z = np.where(y, rng.normal(1.0, 1.0, 3000), rng.normal(-1.0, 1.0, 3000))
            cal.update(z, y)
        fits.append(cal.coef_)
    np.testing.assert_allclose(fits[0], fits[1], atol=0.1)
    np.testing.assert_allclose(fits[1], [2.0, 0.0], atol=0.1)  # equal-variance Gaussians: a = 2, b = 0


# Adversarial self-labels (ground labelled where the classifier scores low, as paint the colour of the
# sky): the unconstrained fit's slope is negative, and the map in use falls back to the identity, so the
# calibrated probability still increases with the score; labels that rank with the score again bring the
# fit back.
def test_platt_never_inverts_the_score():
    rng = np.random.default_rng(2)
    cal = PlattCalibrator(decay=0.9, prior_weight=5.0)
    for _ in range(10):
        z = rng.normal(0, 3, 4000)
        cal.update(z, rng.random(4000) < sigmoid(-1.5 * z))
    assert cal.fit_[0] < 0 and cal.fallback_ == "slope_not_positive"
    z = np.linspace(-14, 14, 2001)
    p = cal.transform(z)
    assert np.all(np.diff(p.astype(np.float64)) >= 0) and p[-1] - p[0] > 0.99
    np.testing.assert_allclose(p, sigmoid(z), atol=1e-6)  # the identity: the classifier's own posterior
    for _ in range(40):
        z = rng.normal(0, 3, 4000)
        cal.update(z, rng.random(4000) < sigmoid(1.5 * z))
    assert cal.fallback_ is None and cal.coef_[0] > 1.0 and np.array_equal(cal.coef_, cal.fit_)


# Evidence-weighted decay: an update with few samples keeps most of the histogram.
def test_decay_samples_forgets_in_proportion_to_the_evidence():
    labels = np.zeros((20, 20), np.uint8)
    m = GroundColourModel(alpha=0.5, decay_samples=90)
    m.update(labels, np.array([[10.0, 10.0]] * 10), np.zeros((0, 2)))  # 90 samples: full decay next time
    h0 = m.hist_ground[0]
    m.update(labels, np.array([[10.0, 10.0]]), np.zeros((0, 2)))  # 9 samples: decay 0.5 ** 0.1
    assert np.isclose(m.hist_ground[0], h0 * 0.5 ** 0.1 + 9)
    spec = GroundColourModel(alpha=0.5)
    spec.update(labels, np.array([[10.0, 10.0]] * 10), np.zeros((0, 2)))
    spec.update(labels, np.array([[10.0, 10.0]]), np.zeros((0, 2)))
    assert np.isclose(spec.hist_ground[0], h0 * 0.5 + 9)


# The calibrated output beats the raw posterior in ECE on the corridor's later frames, and keeps the
# raw posterior's ranking within a frame (a monotone map of the smoothed log-odds).
def test_groundvo_calibrated_map_is_better_calibrated(corridor):
    kw = dict(seed=0)
    cal = run(GroundVO(corridor["K"], corridor["camera_height"], **kw), corridor)
    raw = run(GroundVO(corridor["K"], corridor["camera_height"], calibration=CalibrationConfig(method="none"), **kw),
              corridor)
    frames = range(10, len(cal))
    y = np.concatenate([corridor["ground_mask"][i].ravel() for i in frames])
    e_cal = expected_calibration_error(np.concatenate([cal[i].ground_prob.ravel() for i in frames]), y)
    e_raw = expected_calibration_error(np.concatenate([raw[i].ground_prob.ravel() for i in frames]), y)
    assert e_cal < e_raw
    assert e_cal < 0.05
    # RANSAC is untouched by the output calibration: the same inliers, speeds and poses.
    for a, b in zip(cal, raw):
        assert a.speed == b.speed and np.array_equal(a.inlier_mask, b.inlier_mask)
