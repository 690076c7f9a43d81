"""The Kümmerle et al. (2009) relation metric against analytic cases."""

import numpy as np
import pytest

from polar_sim.geometry import between2d, compose2d
from polar_sim.metrics import relation_errors, relation_scores


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
                                         ((np.zeros((3, 3)), [[0, 1]], [[0, 0]]), "reference"),
                                         ((np.zeros((3, 3)), [[0, 1]], [[np.nan, 0, 0]]), "reference")])
def test_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        relation_errors(*args)


# Indices that are not integers are the wrong kind of input: TypeError naming them.
def test_float_pairs_are_refused():
    with pytest.raises(TypeError, match="pairs"):
        relation_errors(np.zeros((3, 3)), [[0.5, 1]], [[0, 0, 0]])


def _loop_log():
    t = np.arange(20, dtype=float)
    truth = np.column_stack([np.cos(t / 3), np.sin(t / 3), t / 3])
    pairs = [(0, 1), (5, 6), (10, 12), (0, 18), (2, 19)]
    ref = np.array([between2d(truth[i], truth[j]) for i, j in pairs])
    rel = np.column_stack([t[[i for i, _ in pairs]], t[[j for _, j in pairs]], ref])
    return t, truth, np.vstack([rel, [100.0, 101.0, 0, 0, 0]])      # times not in the log: not scored


# The reference relations of the true trajectory score zero; a trajectory that jumps 0.5 m between
# scans 14 and 15 scores zero on local relations and 0.5 m on the two loop relations that span it
# (2 of 5 relations: 0.2 m over all).
def test_relation_scores_local_and_loop():
    t, truth, rel = _loop_log()
    drift = truth.copy()
    drift[15:, 0] += 0.5
    out = relation_scores({"truth": truth, "drift": drift}, t, rel)
    assert out["n_relations"] == 5 and out["n_loop_relations"] == 2
    for k in ("trans_mean_m", "trans_max_m", "rot_mean_deg", "rot_max_deg"):
        assert out[f"truth_{k}"] == pytest.approx(0.0, abs=1e-9) and out[f"truth_local_{k}"] == pytest.approx(0.0, abs=1e-9)
    assert out["drift_local_trans_max_m"] == pytest.approx(0.0, abs=1e-12)
    assert out["drift_loop_trans_mean_m"] == pytest.approx(0.5) and out["drift_trans_mean_m"] == pytest.approx(0.2)


# A log whose timestamps step back (as the Intel Lab log's do four times) is matched time by time:
# shuffling the scans and their times together changes no relation's error (only which relations
# are local, a matter of log order).
def test_relation_scores_unsorted_times():
    t, truth, rel = _loop_log()
    drift = truth.copy()
    drift[15:, 0] += 0.5
    perm = np.random.default_rng(0).permutation(len(t))
    a = relation_scores({"drift": drift}, t, rel)
    b = relation_scores({"drift": drift[perm]}, t[perm], rel)
    keys = ["n_relations"] + [f"drift_{k}" for k in ("trans_mean_m", "trans_max_m", "rot_mean_deg", "rot_max_deg")]
    assert {k: b[k] for k in keys} == pytest.approx({k: a[k] for k in keys}, abs=1e-12)


@pytest.mark.parametrize("kw, exc, match", [
    ({"t_abs": np.full(20, "a")}, TypeError, "t_abs"),
    ({"t_abs": np.zeros(20)}, ValueError, "t_abs"),                     # every time the same
    ({"relations": np.zeros((3, 4))}, ValueError, "relations"),
    ({"relations": np.zeros((3, 5), complex)}, TypeError, "relations"),
    ({"trajectories": [np.zeros((20, 3))]}, TypeError, "trajectories"),
    ({"trajectories": {"a": np.zeros((19, 3))}}, ValueError, "trajectories\\['a'\\]"),
    ({"local_gap": 1.5}, TypeError, "local_gap"),
])
def test_relation_scores_bad_input(kw, exc, match):
    t, truth, rel = _loop_log()
    args = {"trajectories": {"truth": truth}, "t_abs": t, "relations": rel, **kw}
    with pytest.raises(exc, match=f"^{match}"):
        relation_scores(args.pop("trajectories"), args.pop("t_abs"), args.pop("relations"), **args)
