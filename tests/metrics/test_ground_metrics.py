import numpy as np
import pytest

from polar_sim.metrics.ground import (classifier_auc, classifier_iou, fit_success_curve, ground_success,
                                      laplace_scale)


def test_ground_success_recall_precision_f1():
    # Two frames pooled: |I∩G| = 3, |G| = 4, |I| = 5 -> ps 0.75, precision 0.6, F1 2/3.
    g = [np.array([1, 1, 0, 0], bool), np.array([1, 1, 0], bool)]
    i = [np.array([1, 0, 1, 0], bool), np.array([1, 1, 1], bool)]
    s = ground_success(g, i)
    assert (s.ps, s.precision) == (0.75, 0.6) and s.f1 == pytest.approx(2 / 3)
    assert ground_success(np.array([1, 0], bool), np.array([1, 0], bool)).ps == 1.0
    with pytest.raises(ValueError):
        ground_success(g, i[:1])


def test_exponential_fit_recovers_parameters():
    # ps(N) = pmax - (pmax - p0) p^N sampled with noise over 30 repetitions: parameters recovered.
    rng = np.random.default_rng(0)
    N = np.repeat([5, 11, 25, 55, 125], 30)
    truth = 0.82 - (0.82 - 0.4) * 0.93**N
    fit = fit_success_curve(N, np.clip(truth + rng.normal(0, 0.01, N.size), 0, 1))
    assert fit.p_max == pytest.approx(0.82, abs=0.01) and fit.p_0 == pytest.approx(0.4, abs=0.05)
    assert fit.p == pytest.approx(0.93, abs=0.01)
    assert fit.n95 == pytest.approx(np.log(0.05 * 0.82 / 0.42) / np.log(0.93), rel=0.1)
    assert 0 <= fit.p_0 <= fit.p_max <= 1 and 0 < fit.p < 1
    np.testing.assert_allclose(fit([5, 125]), fit.p_max - (fit.p_max - fit.p_0) * fit.p ** np.array([5, 125]))


def test_exponential_fit_ideal_ransac():
    # Ideal RANSAC: pmax 1, p0 0, p = 1 - w^s.
    N = np.arange(1, 40)
    w, s = 0.5, 2
    fit = fit_success_curve(N, 1 - (1 - w**s) ** N)
    assert fit.p_max == pytest.approx(1.0, abs=1e-3) and fit.p_0 == pytest.approx(0.0, abs=1e-3)
    assert fit.p == pytest.approx(1 - w**s, abs=1e-3)


def test_laplace_scale_is_mean_absolute_error():
    # The Laplace MLE scale is mean |e|; on a large Laplace sample it recovers b.
    assert laplace_scale([1.0, -2.0, 3.0]) == 2.0
    e = np.random.default_rng(1).laplace(0, 1.7, 200000)
    assert laplace_scale(e) == pytest.approx(1.7, rel=0.01)
    with pytest.raises(ValueError):
        laplace_scale([1.0, np.nan])


def test_classifier_iou_and_auc_hand_cases():
    # IoU of the thresholded map; AUC 1 for a perfect ranking, 0.5 for a constant map, ties count half.
    gt = np.array([[1, 1, 0, 0]], bool)
    assert classifier_iou(np.array([[0.9, 0.4, 0.8, 0.1]]), gt) == pytest.approx(1 / 3)
    assert classifier_auc(np.array([[0.9, 0.8, 0.2, 0.1]]), gt) == 1.0
    assert classifier_auc(np.full((1, 4), 0.3), gt) == 0.5
    assert classifier_auc(np.array([[0.9, 0.5, 0.5, 0.1]]), gt) == pytest.approx(0.875)
    valid = np.array([[1, 0, 1, 0]], bool)
    assert classifier_iou(np.array([[0.9, 0.4, 0.8, 0.1]]), gt, valid=valid) == 0.5
    with pytest.raises(ValueError, match="gt_mask"):
        classifier_iou(np.zeros((2, 2)), np.zeros((2, 3), bool))


# labels_at reads the mask at rounded, clamped pixel positions (column, row).
def test_labels_at_hand_case():
    from polar_sim.metrics.ground import labels_at

    m = np.zeros((4, 5), bool)
    m[1, 3] = m[3, 0] = True
    np.testing.assert_array_equal(labels_at(m, [[3.2, 0.6], [-2.0, 9.0], [1.0, 1.0]]), [True, True, False])
    assert labels_at(m, np.zeros((0, 2))).shape == (0,)
    with pytest.raises(ValueError, match="mask"):
        labels_at(m.astype(int), [[0, 0]])


# Oracle speeds times the frame periods are the true step lengths.
def test_oracle_step_speeds():
    from polar_sim.metrics.ground import oracle_step_speeds

    t = np.array([0.0, 0.1, 0.3, 0.4])
    s = np.array([0.0, 0.5, 2.0, 0.1])
    v = oracle_step_speeds(t, s)
    np.testing.assert_allclose(v[1:] * np.diff(t), s[1:])
    with pytest.raises(ValueError, match="increase"):
        oracle_step_speeds([0.0, 0.0], [0.0, 1.0])



# ΔV of raw and filtered speeds: image k's values against the true speed of its middle frame k - 1;
# frames without a raw speed are left out; by hand on a 4-frame series.
def test_speed_error_scales_by_hand():
    from polar_sim.metrics.ground import speed_error_scales

    true = np.array([1.0, 2.0, 3.0, 4.0])
    raw = np.array([np.nan, 1.5, np.nan, 2.0])      # errors vs true[k-1]: 0.5 (k=1), -1.0 (k=3)
    filt = np.array([0.0, 1.0, 2.5, 3.0])           # errors vs true[k-1]: 0, 0.5, 0 (k=1..3)
    dv_raw, dv_f = speed_error_scales(raw, filt, true)
    assert dv_raw == pytest.approx(0.75) and dv_f == pytest.approx(0.5 / 3)
    assert np.isnan(speed_error_scales(np.full(4, np.nan), filt, true)[0])
    with pytest.raises(ValueError, match="speed_raw, speed, speed_true"):
        speed_error_scales(raw[:3], filt, true)


# Settled / transition / all-frame IoU statistics of a series, by hand; NaN IoUs are left out.
def test_iou_summary_by_hand():
    from polar_sim.metrics.ground import iou_summary

    iou = np.array([0.1, 0.9, 0.8, np.nan, 0.5, 0.95])
    settled = np.array([0, 1, 1, 1, 0, 1], bool)
    scored = np.array([0, 1, 1, 1, 1, 1], bool)
    s = iou_summary(iou, settled, scored, 0.85)
    assert s["n_settled"] == 3 and s["iou_settled_mean"] == pytest.approx((0.9 + 0.8 + 0.95) / 3)
    assert s["share_settled_ge_target"] == pytest.approx(2 / 3)
    assert s["iou_settled_p10"] == pytest.approx(np.percentile([0.9, 0.8, 0.95], 10))
    assert s["iou_transition_mean"] == 0.5 and s["iou_all_mean"] == pytest.approx((0.9 + 0.8 + 0.5 + 0.95) / 4)
    empty = iou_summary(iou, np.zeros(6, bool), np.zeros(6, bool), 0.85)
    assert empty["n_settled"] == 0 and np.isnan(empty["iou_settled_mean"]) and np.isnan(empty["iou_transition_mean"])
