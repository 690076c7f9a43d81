"""Rates of a tracking run from per-frame scores, their pooling over runs, the rank correlation, and
the pooled ECE of per-frame reliability counts, against hand-computed cases (numpy only)."""

import numpy as np
import pytest

from polar_sim import metrics


def test_add_success_rate_is_strict_and_selects_frames():
    # threshold k d = 0.5 x 0.2 m = 0.1 m: 0.1 itself fails (strictly below), inf fails
    e = np.array([0.0, 0.099, 0.1, np.inf])
    assert metrics.add_success_rate(e, 0.2, k=0.5) == 0.5
    assert metrics.add_success_rate(e, 0.2, k=0.5) == metrics.add_success(e, 0.2, k=0.5)
    assert metrics.add_success_rate(e, 0.2, k=0.5, where=np.array([False, True, True, True])) == pytest.approx(1 / 3)
    assert np.isnan(metrics.add_success_rate(e, 0.2, where=np.zeros(4, bool)))   # no frame selected
    with pytest.raises(ValueError, match="errors"):
        metrics.add_success_rate([0.1, np.nan], 0.2)
    with pytest.raises(ValueError, match="where"):
        metrics.add_success_rate(e, 0.2, where=np.ones(3, bool))


def test_success_5cm5deg_rate_from_errors():
    # 4 deg / 4 cm succeeds, 6 deg fails, 6 cm fails; exactly 5 cm fails (strict)
    rot = np.deg2rad([4.0, 6.0, 0.0, 0.0])
    trans = np.array([0.04, 0.0, 0.06, 0.05])
    assert metrics.success_5cm5deg_rate(rot, trans) == 0.25
    assert metrics.success_5cm5deg_rate(rot, trans, where=np.array([True, True, False, False])) == 0.5
    assert np.isnan(metrics.success_5cm5deg_rate(rot, trans, where=np.zeros(4, bool)))
    with pytest.raises(ValueError, match="rotation, translation"):
        metrics.success_5cm5deg_rate(rot, trans[:3])


def test_pooled_rate_is_the_rate_over_all_frames():
    # run A: 10 frames, 10 ok; run B: 30 frames, 15 ok -> 25 / 40 over the pooled frames
    a, b = np.ones(10, bool), np.r_[np.ones(15, bool), np.zeros(15, bool)]
    rates, frames = [a.mean(), b.mean()], [10, 30]
    assert metrics.pooled_rate(rates, frames) == 0.625 == np.r_[a, b].mean()
    # a run with a NaN rate (no frame of the kind) or no weight is left out
    assert metrics.pooled_rate([1.0, 0.5, np.nan, 0.0], [10, 30, 5, 0]) == 0.625
    assert np.isnan(metrics.pooled_rate([np.nan], [3]))
    with pytest.raises(ValueError, match="weights"):
        metrics.pooled_rate([0.5], [-1])


def test_spearman_ranks_with_ties():
    # monotone but non-linear: +1 and -1
    x = np.arange(1.0, 7.0)
    assert metrics.spearman(x, x ** 3) == pytest.approx(1.0)
    assert metrics.spearman(x, -np.exp(x)) == pytest.approx(-1.0)
    # y ranks (1, 2, 3.5, 5, 3.5) against (1, ..., 5): 8 / sqrt(10 x 9.5)
    assert metrics.spearman([1, 2, 3, 4, 5], [5, 6, 7, 8, 7]) == pytest.approx(8 / np.sqrt(95), abs=1e-12)
    # undefined: fewer than 3 pairs, or a constant input
    assert np.isnan(metrics.spearman([1.0, 2.0], [2.0, 1.0]))
    assert np.isnan(metrics.spearman([1.0, 2.0, 3.0], [0.5, 0.5, 0.5]))
    assert np.isnan(metrics.spearman([7.0, 7.0, 7.0], [1.0, 2.0, 3.0]))


def test_iou_success_rate_is_strict_and_selects_frames():
    ious = np.array([0.5, 0.51, 0.9, 0.0])
    assert metrics.iou_success_rate(ious) == 0.5 == metrics.iou_success(ious)
    assert metrics.iou_success_rate(ious, 0.8, where=np.array([False, True, True, False])) == 0.5
    assert np.isnan(metrics.iou_success_rate(ious, where=np.zeros(4, bool)))


def test_pooled_precision_recall_from_frame_counts():
    # two frames of 1 x 10 pixels: pred {0..3} vs truth {1..6}; pred {} vs truth {8, 9}
    pred = np.zeros((2, 1, 10), bool)
    gt = np.zeros((2, 1, 10), bool)
    pred[0, 0, :4], gt[0, 0, 1:7], gt[1, 0, 8:] = True, True, True
    f = [metrics.mask_frame_scores(p, g) for p, g in zip(pred, gt)]
    counts = [[x[k] for x in f] for k in ("n_tp", "n_pred", "n_gt")]
    assert counts == [[3, 0], [4, 0], [6, 2]]
    assert metrics.pooled_precision_recall(*counts) == (0.75, 0.375) == metrics.precision_recall(pred, gt)
    assert metrics.pooled_precision_recall([0], [0], [5]) == (1.0, 0.0)   # nothing predicted
    assert metrics.pooled_precision_recall([0], [2], [0]) == (0.0, 1.0)   # nothing true
    with pytest.raises(ValueError, match="n_tp"):
        metrics.pooled_precision_recall([3], [2], [5])


def test_pooled_occluder_as_target_from_frame_counts():
    # 10 hand pixels with 1 labelled target, a frame without hand, 30 with 3 (not selected)
    n, nt = np.array([10, 0, 30]), np.array([1, 0, 3])
    assert metrics.pooled_occluder_as_target(n, nt) == 0.1
    assert metrics.pooled_occluder_as_target(n, nt, where=np.array([True, True, False])) == 0.1
    assert np.isnan(metrics.pooled_occluder_as_target(n, nt, where=np.array([False, True, False])))
    # the same as occluder_as_target on the masks
    pred, hand = np.zeros((2, 1, 10), bool), np.zeros((2, 1, 10), bool)
    hand[0, 0, :], pred[0, 0, 0], hand[1, 0, :4], pred[1, 0, 3] = True, True, True, True
    f = [metrics.mask_frame_scores(p, p, occluder=h) for p, h in zip(pred, hand)]
    assert metrics.pooled_occluder_as_target([x["hand_near"] for x in f], [x["hand_near_tgt"] for x in f]) == \
        metrics.occluder_as_target(pred, hand) == 2 / 14
    with pytest.raises(ValueError, match="n_occluder_target"):
        metrics.pooled_occluder_as_target([1], [2])


def test_pooled_ece_of_frame_counts_by_hand():
    # 15 bins: 0.1 -> bin 1, 0.9 -> bin 13, 0.95 and 1.0 -> bin 14 (p = 1 in the last bin)
    frames = [(np.array([0.1, 0.1]), np.array([False, False])),
              (np.array([0.9, 0.9, 0.9, 0.95, 1.0]), np.array([True, True, True, False, True]))]
    c, p, y = (sum(x) for x in zip(*[metrics.reliability_counts(pr, lab) for pr, lab in frames]))
    assert c[1] == 2 and c[13] == 3 and c[14] == 2 and c.sum() == 7
    # |sum y - sum p| per bin: 0.2 (bin 1), 0.3 (bin 13), |1 - 1.95| = 0.95 (bin 14), over 7 pixels
    r = metrics.pooled_reliability(c, p, y)
    assert r.ece == pytest.approx((0.2 + 0.3 + 0.95) / 7, abs=1e-15)
    assert r.ece == pytest.approx(metrics.reliability(np.r_[frames[0][0], frames[1][0]],
                                                      np.r_[frames[0][1], frames[1][1]]).ece, abs=1e-15)


def test_pooled_ece_of_stacked_frame_counts():
    # pooled_ece adds stacked per-frame counts (frames, 3, bins) over the leading axes: the same frames
    # as above give (0.2 + 0.3 + 0.95) / 7, stacked by frame or by run; no pixel gives NaN
    frames = [(np.array([0.1, 0.1]), np.array([False, False])),
              (np.array([0.9, 0.9, 0.9, 0.95, 1.0]), np.array([True, True, True, False, True]))]
    stack = np.stack([np.stack(metrics.reliability_counts(pr, lab)) for pr, lab in frames]).astype(float)
    assert stack.shape == (2, 3, 15)
    assert metrics.pooled_ece(stack) == pytest.approx((0.2 + 0.3 + 0.95) / 7, abs=1e-15)
    assert metrics.pooled_ece(stack[None]) == metrics.pooled_ece(stack)
    assert np.isnan(metrics.pooled_ece(np.zeros((4, 3, 15))))
    for bad, err in ((np.zeros((3,)), ValueError), (np.zeros((2, 4, 15)), ValueError),
                     (np.full((1, 3, 15), "x"), TypeError), (-np.ones((1, 3, 15)), ValueError)):
        with pytest.raises(err, match="counts"):
            metrics.pooled_ece(bad)
