"""The per-class and per-family statistics the ground experiments report (polar_sim.metrics.ground)."""

import numpy as np
import pytest

from polar_sim.metrics.calibration import pooled_reliability, reliability_counts
from polar_sim.metrics.ground import (class_mean_prob_bounds, class_prob_sums, classifier_iou, kitti_scores,
                                      kitti_scores_pooled, pool_by_family)


def _maps(seed, n=(40, 60)):
    rng = np.random.default_rng(seed)
    y = rng.random(n) < 0.4
    p = np.clip(np.where(y, 0.7, 0.2) + 0.2 * rng.standard_normal(n), 0, 1).astype(np.float32)
    return p, y


def test_class_prob_sums_are_the_exact_class_means():
    p, y = _maps(0)
    s = class_prob_sums(p, y)
    assert s[1] == y.sum() and s[3] == (~y).sum()
    assert s[0] / s[1] == pytest.approx(p[y].astype(np.float64).mean(), rel=1e-12)
    assert s[2] / s[3] == pytest.approx(p[~y].astype(np.float64).mean(), rel=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_bin_estimate_of_the_class_means_is_bounded_by_the_bin_edges(seed):
    p, y = _maps(seed)
    b = class_mean_prob_bounds(*reliability_counts(p, y))
    for name, m in (("ground", y), ("nonground", ~y)):
        exact = float(p[m].astype(np.float64).mean())
        est, lo, hi = b[name]
        assert lo <= exact <= hi and lo <= est <= hi
        assert hi - lo == pytest.approx(1 / 15) and abs(est - exact) <= 1 / 15


def test_an_empty_class_is_nan():
    p = np.full((4, 4), 0.3, np.float32)
    b = class_mean_prob_bounds(*reliability_counts(p, np.zeros((4, 4), bool)))
    assert np.isnan(b["ground"][0]) and b["nonground"][0] == pytest.approx(0.3, abs=1e-6)


def test_pool_by_family_pools_settled_frames_of_each_zone_across_routes():
    frames = [_maps(s) for s in range(6)]
    iou = np.array([classifier_iou(p, y) for p, y in frames])
    bins = np.stack([np.stack(reliability_counts(p, y)) for p, y in frames])
    ps = np.stack([class_prob_sums(p, y) for p, y in frames])
    a = dict(families=np.array(["grass", "checker"]), settled=np.array([1, 1, 0, 1, 1, 1], bool),
             zone=np.array([0, 0, 0, 1, 1, 1]), iou=iou[:6], bins=bins, psums=ps)
    b = dict(families=np.array(["checker"]), settled=np.array([1, 0, 1, 1, 1, 1], bool), zone=np.zeros(6, int),
             iou=iou, bins=bins, psums=ps)
    out = pool_by_family([a, b])
    assert list(out) == ["checker", "grass"]
    chk = [3, 4, 5, 0, 2, 3, 4, 5]  # frames of route a's zone 1 and route b's settled frames
    assert out["checker"]["frames"] == len(chk) and out["checker"]["iou_mean"] == pytest.approx(iou[chk].mean())
    np.testing.assert_allclose(out["checker"]["bins"], bins[chk].sum(axis=0))
    np.testing.assert_allclose(out["checker"]["psums"], ps[chk].sum(axis=0))
    assert out["grass"]["frames"] == 2
    assert pooled_reliability(*out["grass"]["bins"]).n == 2 * 40 * 60
    s = ps[chk].sum(axis=0)
    assert out["checker"]["p_ground"] == pytest.approx(s[0] / s[1]) and out["checker"]["p_nonground"] == pytest.approx(s[2] / s[3])
    del b["psums"]
    est = pool_by_family([a, b])["checker"]
    assert est["psums"] is None  # a route without the sums: no exact means, the bins' estimate
    bounds = class_mean_prob_bounds(*est["bins"])
    assert (est["p_ground"], est["p_nonground"]) == (bounds["ground"][0], bounds["nonground"][0])
    assert bounds["ground"][1] <= s[0] / s[1] <= bounds["ground"][2]


def test_kitti_scores_of_a_perfect_estimate_are_zero():
    n = 200
    gt = np.tile(np.eye(4), (n, 1, 1))
    gt[:, 2, 3] = np.arange(n) * 1.0  # 199 m straight ahead
    s = kitti_scores(gt, gt.copy(), prefix="x_")
    assert s["x_t_pct"] == pytest.approx(0, abs=1e-9) and s["x_ate_m"] == pytest.approx(0, abs=1e-9)
    assert s["x_n_segments"] > 0
    est = gt.copy()
    est[:, 2, 3] *= 1.02  # 2 % scale error
    p = kitti_scores_pooled([(gt, est), (gt, est)])
    # 2 % of each segment's true length over its nominal length L: a segment ends at the first frame
    # past L (1 m frame spacing), so 2 % <= error <= 2 % (L + 1) / L; L >= 100 m, or 199/8 m scaled.
    assert p["routes"] == 2 and 2.0 - 1e-6 <= p["t_pct"] <= 2.0 * 101 / 100 + 1e-6
    assert 2.0 - 1e-6 <= p["t_pct_scaled"] <= 2.0 * (1 + 8 / 199) + 1e-6
