"""The Kümmerle et al. (2009) relation metric against analytic cases."""

import numpy as np
import pytest

from polar_sim.geometry import between2d, compose2d
from polar_sim.metrics import relation_errors


def _traj(n=30, seed=0):
    rng = np.random.default_rng(seed)
    out = [np.zeros(3)]
    for _ in range(n - 1):
        out.append(compose2d(out[-1], [rng.uniform(0.1, 0.5), rng.normal(0, 0.05), rng.normal(0, 0.2)]))
    return np.array(out)


# The true trajectory has zero error, and so has any rigid motion of it (no common frame needed).
def test_zero_for_the_truth_and_its_rigid_motions():
    gt = _traj()
    pairs = np.array([(i, j) for i in range(0, 30, 3) for j in range(i + 1, 30, 7)])
    ref = between2d(gt[pairs[:, 0]], gt[pairs[:, 1]])
    e = relation_errors(gt, pairs, ref)
    assert e.trans_max < 1e-12 and e.rot_max_deg < 1e-9 and e.n == len(pairs)
    moved = compose2d(np.array([5.0, -3.0, 1.2]), gt)
    assert relation_errors(moved, pairs, ref).trans_max < 1e-9


# Moving pose j by d metres in its own frame makes each relation (i, j) off by d; turning it by
# 3 deg makes the rotation error 3 deg; the squared means follow.
def test_known_errors():
    gt = _traj()
    pairs = np.array([[0, 5], [2, 5], [5, 9]])
    ref = between2d(gt[pairs[:, 0]], gt[pairs[:, 1]])
    est = gt.copy()
    est[5] = compose2d(gt[5], [0.3, 0.4, np.radians(3.0)])
    e = relation_errors(est, pairs, ref)
    # relation (5, 9): pose 5 is the reference frame, so the error is the inverse displacement seen from 9
    np.testing.assert_allclose(e.trans[:2], 0.5, atol=1e-12)
    np.testing.assert_allclose(e.rot_deg, 3.0, atol=1e-9)
    assert e.trans_mean == pytest.approx(np.mean(e.trans)) and e.trans_sq_mean == pytest.approx(np.mean(e.trans ** 2))
    assert e.rot_sq_mean_deg2 == pytest.approx(9.0)


# Bad input raises ValueError naming the argument.
@pytest.mark.parametrize("args, match", [((np.zeros((3, 2)), [[0, 1]], [[0, 0, 0]]), "poses"),
                                         ((np.zeros((3, 3)), [[0, 3]], [[0, 0, 0]]), "pairs"),
                                         ((np.zeros((3, 3)), [[0.5, 1]], [[0, 0, 0]]), "pairs"),
                                         ((np.zeros((3, 3)), [[0, 1]], [[0, 0]]), "reference"),
                                         ((np.zeros((3, 3)), [[0, 1]], [[np.nan, 0, 0]]), "reference")])
def test_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        relation_errors(*args)
