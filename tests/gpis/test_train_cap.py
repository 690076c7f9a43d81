"""``train_cap``: each local GP trains on the ``cap`` samples nearest its cluster's centre.

The invariant is checked against a brute-force derivation from the map's own samples after every
update: with ``retrain_tol=0`` (every change counts) each trained GP's inputs must be exactly the
cap nearest samples within the training radius, so both the capped gathering and the narrowed
choice of clusters to retrain (``dirty_slots``) are exercised against truth.
"""

import numpy as np
import pytest

from polar_sim.gpis import GPISMap2D
from polar_sim.gpis.config import LocalGPConfig2D

from .scenes import room_path, scan_2d

ANGLES = np.linspace(-np.pi * 0.75, np.pi * 0.75, 271)


def _capped(cap):
    return GPISMap2D(local_gp=LocalGPConfig2D(train_cap=cap))


def _scans(n):
    rng = np.random.default_rng(3)
    for pose in room_path(n):
        yield ANGLES, scan_2d(pose, ANGLES, noise=0.01, rng=rng), pose


def _gp_inputs(m, s):
    """Positions of the value observations (one per training sample) of slot s's GP."""
    g = m.gps_
    o, k = g.gp_obs[s], g.gp_m[s]
    kinds = g.kinds[o:o + k]
    nv = int(np.argmax((kinds >> 32) != 0)) if ((kinds >> 32) != 0).any() else k
    return g.X[o:o + nv]


def _expected(m, s, cap):
    """Brute force: the samples within R of slot s's centre, or the cap nearest of them. (How ties
    in distance are broken would matter only at exact equality, which noisy scans do not give.)"""
    tr = m.tree_
    R = m._TRAIN_R * m._hc()
    pts = tr.pos[tr.alive()]
    c = tr.slot_centres(np.array([s]))[0]
    d2 = ((pts - c) ** 2).sum(1)
    inside = pts[d2 < R * R]
    d2 = d2[d2 < R * R]
    if cap is not None and len(inside) > cap:
        inside = inside[np.argsort(d2, kind="stable")[:cap]]
    return inside


def _as_set(p):
    return {tuple(np.round(r, 12)) for r in p}


@pytest.mark.parametrize("cap", [None, 12])
def test_every_gp_holds_the_nearest_samples(cap):
    m = GPISMap2D(local_gp=LocalGPConfig2D(train_cap=cap, retrain_tol=0.0))
    checked = 0
    for a, r, pose in _scans(30):
        m.update(a, r, pose)
        for s in m.tree_.cluster_slots():
            want = _expected(m, s, cap)
            if len(want) == 0:
                continue
            got = _as_set(_gp_inputs(m, s))
            assert got == _as_set(want), (s, len(got), len(want))
            checked += 1
    assert checked > 100
    if cap is not None:   # the cap was binding somewhere, or the test proves nothing
        sizes = [len(_expected(m, s, None)) for s in m.tree_.cluster_slots()]
        assert max(sizes) > cap


# The 2D bounds (tests/gpis/test_accuracy2d.py) hold with GPs of a tenth of the samples.
def test_cap_bounds_the_gp_size_and_keeps_accuracy():
    from .scenes import eval_sets_2d, sdf_2d

    full, capped = _capped(None), _capped(12)
    path = []
    for a, r, pose in _scans(60):
        full.update(a, r, pose)
        capped.update(a, r, pose)
        path.append(pose)
    assert capped.gps_.gp_m.max() <= 12 * 3        # one value and two gradient rows per sample
    assert full.gps_.gp_m.max() > 12 * 3
    rng = np.random.default_rng(0)
    P = np.column_stack([rng.uniform(-0.5, 8.5, 30000), rng.uniform(-0.5, 6.5, 30000)])
    near, far = eval_sets_2d(P, np.array(path))
    e = capped.query(P)[0] - sdf_2d(P)
    assert near.sum() > 5000 and far.sum() > 5000
    assert np.sqrt(np.mean(e[near] ** 2)) <= 0.02
    assert np.abs(e[far]).mean() <= 0.05


def test_published_retraining_ignores_the_cap():
    a_map, b_map = GPISMap2D.published(), GPISMap2D.published(local_gp__train_cap=4)
    for a, r, pose in _scans(8):
        a_map.update(a, r, pose)
        b_map.update(a, r, pose)
    assert np.array_equal(a_map.gps_.X[: a_map.gps_.n_obs], b_map.gps_.X[: b_map.gps_.n_obs])
    c, d = GPISMap2D.published(), GPISMap2D.published(local_gp__train_cap=None)
    for a, r, pose in _scans(8):
        c.update(a, r, pose)
        d.update(a, r, pose)
    assert np.array_equal(c.gps_.X[: c.gps_.n_obs], d.gps_.X[: d.gps_.n_obs])


def test_save_load_keeps_the_capped_retraining(tmp_path):
    scans = list(_scans(16))
    ref = _capped(10)
    for a, r, pose in scans:
        ref.update(a, r, pose)
    m = _capped(10)
    for a, r, pose in scans[:8]:
        m.update(a, r, pose)
    m.save(tmp_path / "m.npz")
    m = GPISMap2D.load(tmp_path / "m.npz")
    assert m.local_gp.train_cap == 10
    for a, r, pose in scans[8:]:
        m.update(a, r, pose)
    pts = np.random.default_rng(1).uniform([0, 0], [8, 6], (500, 2))
    assert np.array_equal(m.query(pts)[0], ref.query(pts)[0])


@pytest.mark.parametrize("bad", [0, -3, 2.5, True, "8", np.nan])
def test_bad_cap_is_refused_and_the_map_kept(bad):
    m = _capped(16)
    a, r, pose = next(_scans(2))
    m.update(a, r, pose)
    before = m.query(np.array([[1.0, 1.0]]))[0]
    with pytest.raises(ValueError, match="^local_gp__train_cap"):
        m.set_params(local_gp__train_cap=bad)
    assert m.local_gp.train_cap == 16
    assert np.array_equal(m.query(np.array([[1.0, 1.0]]))[0], before)
    with pytest.raises(ValueError, match="^train_cap"):
        LocalGPConfig2D(train_cap=bad)
