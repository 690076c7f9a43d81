"""Segmentation metrics against hand-computed cases: IoU, success, precision/recall, occluder fraction, ROC AUC."""

import numpy as np
import pytest

from polar_sim import metrics


def _rect(y0, y1, x0, x1, shape=(10, 10)):
    m = np.zeros(shape, bool)
    m[y0:y1, x0:x1] = True
    return m


def test_iou_hand_computed():
    # two 4x4 squares overlapping in 2x4: IoU = 8 / 24
    a, b = _rect(0, 4, 0, 4), _rect(2, 6, 0, 4)
    assert metrics.iou(a, b) == pytest.approx(8 / 24)
    assert metrics.iou(a, a) == 1.0
    assert metrics.iou(a, ~a) == 0.0


def test_iou_stack_and_empty():
    # stacks give per-frame values; two empty masks agree perfectly
    a = np.stack([_rect(0, 4, 0, 4), np.zeros((10, 10), bool)])
    b = np.stack([_rect(0, 4, 0, 2), np.zeros((10, 10), bool)])
    assert np.allclose(metrics.iou(a, b), [0.5, 1.0])


def test_iou_success_and_curve():
    # success counts IoU strictly above the threshold; the curve's mean is its AUC
    ious = np.array([0.2, 0.5, 0.7, 0.9])
    assert metrics.iou_success(ious, 0.5) == 0.5
    th, rates, auc = metrics.iou_success_curve(ious)
    assert rates[0] == 1.0 and rates[-1] == 0.0 and auc == pytest.approx(rates.mean())


def test_precision_recall():
    # predicted 4x4, truth 4x2 inside it: precision 0.5, recall 1
    p, r = metrics.precision_recall(_rect(0, 4, 0, 4), _rect(0, 4, 0, 2))
    assert (p, r) == (0.5, 1.0)


def test_occluder_as_target():
    # 3 of 12 hand pixels labelled target: 0.25; no hand at all: NaN
    hand = _rect(0, 3, 0, 4)
    pred = _rect(0, 1, 0, 3)
    assert metrics.occluder_as_target(pred, hand) == pytest.approx(0.25)
    assert np.isnan(metrics.occluder_as_target(pred, np.zeros_like(hand)))
    # restricted to the first hand row (4 pixels, 3 labelled target)
    assert metrics.occluder_as_target(pred, hand, within=_rect(0, 1, 0, 10)) == pytest.approx(0.75)


def test_roc_auc_matches_pair_counting():
    # the rank formula equals the fraction of (positive, negative) pairs ordered right (ties 1/2)
    rng = np.random.default_rng(0)
    s = np.round(rng.normal(size=200), 1)
    y = rng.random(200) < 0.3
    pos, neg = s[y], s[~y]
    brute = ((pos[:, None] > neg[None]).sum() + 0.5 * (pos[:, None] == neg[None]).sum()) / (len(pos) * len(neg))
    assert metrics.roc_auc(s, y) == pytest.approx(brute)


@pytest.mark.parametrize("call", [
    lambda: metrics.iou(np.zeros((4, 4), bool), np.zeros((4, 5), bool)),
    lambda: metrics.iou(np.zeros((4, 4)) + 0.5, np.zeros((4, 4), bool)),
    lambda: metrics.iou_success([]),
    lambda: metrics.roc_auc([0.1, 0.2], [True, True]),
])
def test_bad_input_raises(call):
    # mismatched shapes, non-boolean masks, empty inputs, one-class labels raise ValueError
    with pytest.raises(ValueError):
        call()


# issue 34: roc_auc took string and complex arrays (converting or dropping the imaginary part); they
# are the wrong kind of input. Shapes that disagree name both arguments (either may be wrong).
@pytest.mark.parametrize("scores, labels, name", [
    (np.array(["0.1", "0.9"]), [False, True], "scores"),
    (np.array([0.1, 0.9]) + 1j, [False, True], "scores"),
    ([0.1, 0.9], np.array(["no", "yes"]), "labels"),
    ([0.1, 0.9], np.array([0, 1]) + 0j, "labels"),
])
def test_roc_auc_refuses_strings_and_complex(scores, labels, name):
    with pytest.raises(TypeError, match=f"^{name}:"):
        metrics.roc_auc(scores, labels)


def test_mask_shape_errors_name_both_masks():
    with pytest.raises(ValueError, match=r"^mask_a, mask_b: expected one shape, got \(2, 4, 5\) and \(4, 5\)"):
        metrics.iou(np.zeros((2, 4, 5), bool), np.zeros((4, 5), bool))


def test_near_mask_is_a_disc_dilation():
    # one pixel dilated by r = 3: exactly the pixels within Euclidean distance 3
    m = np.zeros((20, 20), bool)
    m[10, 10] = True
    n = metrics.near_mask(m, 3)
    yy, xx = np.mgrid[0:20, 0:20]
    assert np.array_equal(n, (yy - 10) ** 2 + (xx - 10) ** 2 <= 9)
    assert not metrics.near_mask(np.zeros((5, 5), bool), 2).any()


def test_mask_frame_scores_counts():
    # hand-computed counts for a 4x4 prediction, a 4x6 truth and a hand overlapping both
    pred, gt = _rect(0, 4, 0, 4), _rect(0, 4, 2, 8)
    hand = _rect(2, 6, 0, 2)
    s = metrics.mask_frame_scores(pred, gt, hand, within=_rect(0, 3, 0, 10))
    assert s["n_pred"] == 16 and s["n_gt"] == 24 and s["n_tp"] == 8
    assert s["iou"] == pytest.approx(8 / 32)
    assert s["hand_all"] == 8 and s["hand_all_tgt"] == 4 and s["hand_near"] == 2 and s["hand_near_tgt"] == 2
