"""The batched query kernels against plain per-point references.

``query_gp`` evaluates the points grouped by cluster, with the cross-covariances built in loops
over the training samples and the variance solves done several points at a time. Here each
point is recomputed on its own with dense numpy: the cross-covariances from the kernel formulas
of ``_localgp``, the packed factor unpacked, one triangular solve per point.
"""

import numpy as np
import pytest
from scipy.linalg import solve_triangular

from polar_sim.gpis import GPISMap2D, GPISMap3D
from polar_sim.gpis._numeric import _exp_neg
from polar_sim.gpis._query import _nearest3
from polar_sim.gpis._shells import SHELL_STATE, shell_next, shell_start
from polar_sim.gpis._localgp import _var_consts

from .scenes import intrinsics, orbit_poses, render_sphere, room_path, scan_2d

ANG = np.deg2rad(np.arange(-135.0, 135.0, 1.0))


def _map(dim, legacy):
    if dim == 2:
        m = GPISMap2D.published() if legacy else GPISMap2D()
        for pose in room_path(8):
            m.update(ANG, scan_2d(pose, ANG), pose)
        return m
    m = GPISMap3D.published() if legacy else GPISMap3D()
    K = intrinsics(160, 120, 130.0)
    for T in orbit_poses(3):
        m.update(render_sphere(T, K, 160, 120), K, T)
    return m


def _near_points(m, n, spread, seed=0):
    rng = np.random.default_rng(seed)
    s = m.samples()["points"]
    return s[rng.integers(0, len(s), n)] + rng.normal(scale=spread, size=(n, m.dim))


def _nearest_gp(m, x):
    """Slot of the nearest cluster with a current GP (the kernel's first choice), or -1."""
    tr, g = m.tree_, m.gps_
    W = m._QUERY_W if m._QUERY_W is not None else 4.0 * m.local_gp.map_scale
    best_s, best_d = np.zeros(3, np.int64), np.zeros(3)
    n = _nearest3(x, float(W), tr.geo, tr.cgrid, tr.gshape, tr.goff, tr.node_sample,
                  tr.node_internal, best_s, best_d, np.zeros(3, np.int64),
                  np.zeros(6 * m.dim + SHELL_STATE, np.int64))
    for j in range(n):
        s = best_s[j]
        if g.gp_m[s] > 0 and m.gp_gen_[s] == m.slot_gen_[s]:
            return s
        if m._pub("query_mode"):
            return -1
    return -1


def _reference(m, s, x):
    """[f, grad, var_f] of cluster s's GP at x, dense and per point."""
    g, dim = m.gps_, m.dim
    n, ob, tri = g.gp_m[s], g.gp_obs[s], g.gp_tri[s]
    X, kinds, alpha = g.X[ob:ob + n], g.kinds[ob:ob + n], g.alpha[ob:ob + n]
    L = np.zeros((n, n))
    L[np.tril_indices(n)] = g.Lbuf[tri:tri + n * (n + 1) // 2]      # packed by rows
    a = np.sqrt(3.0) / m.local_gp.map_scale
    d = x - X                                   # (n, dim)
    r = np.linalg.norm(d, axis=1)
    e = np.exp(-a * r)
    inv_r = np.where(r > 0, 1.0 / np.where(r > 0, r, 1.0), 0.0)
    c = (kinds >> 32) - 1                       # -1 value, else gradient component
    grad_obs = c >= 0
    cc = np.where(grad_obs, c, 0)
    dc = d[np.arange(n), cc]
    kf = np.where(grad_obs, a * a * dc * e, (1 + a * r) * e)          # cov(f(x), obs)
    kg = np.empty((dim, n))                                          # cov(d_i f(x), obs)
    for i in range(dim):
        kg[i] = np.where(grad_obs,
                         a * a * ((cc == i) - a * d[:, i] * dc * inv_r) * e,
                         -a * a * d[:, i] * e)
    v = solve_triangular(L, kf, lower=True)
    var_f0, _ = _var_consts(dim, float(m.local_gp.map_scale))
    return np.concatenate([[kf @ alpha], kg @ alpha, [var_f0 - v @ v]])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("legacy", [False, True])
def test_query_gp_matches_dense_reference(dim, legacy):
    m = _map(dim, legacy)
    pts = _near_points(m, 400, 0.2 if dim == 2 else 0.01)
    m._T_BLEND = np.inf                # the nearest GP only, no blend: one reference per point
    out = m._gp_query(pts)
    d = dim
    done = 0
    for x, o in zip(pts, out):
        s = _nearest_gp(m, x)
        if s < 0:
            continue
        np.testing.assert_allclose(o[:d + 2], _reference(m, s, x), rtol=0, atol=1e-9)
        assert np.isnan(o[d + 2:]).all()          # the query does not compute var_grad
        done += 1
    assert done > 300
    # several points per cluster, so the blocks of points and their short ends are exercised
    slots = [_nearest_gp(m, x) for x in pts]
    assert np.bincount(np.array(slots)[np.array(slots) >= 0]).max() >= 9


@pytest.mark.parametrize("dim", [2, 3])
def test_query_gp_point_independent_of_batch(dim):
    """A point's answer is bitwise the same whatever other points share its batch."""
    m = _map(dim, False)
    pts = _near_points(m, 200, 0.2 if dim == 2 else 0.01, seed=1)
    full = m._gp_query(pts)
    for k in (1, 2, 3, 5, 7, 13):
        part = np.concatenate([m._gp_query(pts[i:i + k]) for i in range(0, len(pts), k)])
        np.testing.assert_array_equal(part, full)
    np.testing.assert_array_equal(m._gp_query(pts[::-1])[::-1], full)


def test_exp_neg_matches_numpy():
    x = np.concatenate([-np.geomspace(1e-300, 800.0, 20001), [0.0, -708.0, -708.5, -1e4]])
    ref = np.exp(x)
    y = x.copy()
    _exp_neg(y, len(y), np.empty(len(y)))
    ok = x >= -708.0
    np.testing.assert_allclose(y[ok], ref[ok], rtol=2.3e-16, atol=0)
    assert (y[~ok] == 0.0).all() and np.abs(ref[~ok]).max() < 3.4e-308
    assert y[x == 0.0][0] == 1.0


@pytest.mark.parametrize("dim", [2, 3])
def test_faithful_query_point_independent_of_batch(dim):
    """The default query (nearest samples, surfel distance, GP blend in one kernel) gives a
    point bitwise the same answer whatever other points share its batch."""
    m = _map(dim, False)
    pts = _near_points(m, 200, 0.3 if dim == 2 else 0.02, seed=2)
    full = m.query(pts)
    for k in (1, 3, 7):
        part = [np.concatenate(x) for x in zip(*(m.query(pts[i:i + k]) for i in range(0, len(pts), k)))]
        for a, b in zip(part, full):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("dim", [2, 3])
def test_knn_matches_brute_force(dim):
    """The ring search over cluster cells finds the k nearest samples, also for points far
    outside the map (distances compared: ties may come in either order)."""
    from polar_sim.gpis._distance import knn
    from polar_sim.gpis._kernels import _slot_samples

    m = _map(dim, False)
    tr = m.tree_
    sptr, sidx = _slot_samples(tr.node_sample, int(tr.counts[2]))
    alive = tr.alive()
    P = tr.pos[alive]
    rng = np.random.default_rng(3)
    lo, hi = P.min(0), P.max(0)
    span = hi - lo
    pts = np.concatenate([rng.uniform(lo - s * span, hi + s * span, (300, dim)) for s in (0.1, 1.0, 30.0)])
    out = np.empty((len(pts), 4), np.int64)
    knn(pts, 4, tr.geo, tr.cgrid, tr.gshape, tr.goff, sptr, sidx, tr.pos, out)
    d_ref = np.sort(np.linalg.norm(pts[:, None, :] - P[None], axis=2), axis=1)[:, :4]
    d_got = np.linalg.norm(pts[:, None, :] - tr.pos[out], axis=2)
    np.testing.assert_allclose(d_got, d_ref, rtol=1e-12, atol=0)
    assert np.isin(out, alive).all()


def test_planar_line_search_kernel_matches_general_form():
    """The planar scan's line-search kernel and the general vectorised line search (spec §6.2
    step 3) move every sample to the same place, with the same flags."""
    from polar_sim.gpis._linesearch import TOL, line_search
    from polar_sim.gpis import _scan2d as planar
    from polar_sim.gpis._obsgp import ObsGP1D

    ang = np.deg2rad(np.arange(-135.0, 135.0, 0.5))
    pose = room_path(4)[1]
    r = scan_2d(pose, ang)
    ok = np.isfinite(r)
    gp = ObsGP1D(ang[ok], r[ok] ** -0.5)
    rng = np.random.default_rng(4)
    k = 400
    phi = rng.uniform(-2.4, 2.4, k)
    rr = np.interp(phi, ang[ok], r[ok]) + rng.normal(scale=0.05, size=k)
    p = np.stack([rr * np.cos(phi), rr * np.sin(phi)], 1)
    t = rng.normal(size=(k, 2))
    n = -p / np.linalg.norm(p, axis=1)[:, None] + 0.5 * t
    n /= np.linalg.norm(n, axis=1)[:, None]
    got = planar.line_search(gp, p, n, 0.1, 0.01, TOL, -0.1)
    ref = line_search(p, n, lambda q: planar.occupancy(gp, q, 0.1), 0.01, -0.1)
    for a, b in zip(got, ref):
        if a.dtype == bool:
            np.testing.assert_array_equal(a, b)
        else:
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    live, _, _, _, found = got
    assert 0.3 * k < live.sum() and 0 < found.sum() < live.sum()   # both outcomes exercised


# the shell walk (knn's and the query's one enumeration) visits every cell of the box exactly once,
# each in the shell of its Chebyshev distance from the centre, rows of axes 1.. in order with axis 1
# fastest and axis 0 increasing within a row: checked against a brute-force listing of the box
@pytest.mark.parametrize("dim", [2, 3])
def test_shell_walk_visits_each_cell_once_in_order(dim):
    rng = np.random.default_rng(dim)
    for _ in range(20):
        lo = rng.integers(-4, 2, dim)
        hi = lo + rng.integers(0, 6, dim)
        c0 = rng.integers(lo - 2, hi + 3)         # the centre may lie outside the box
        a0, a1, cc = (np.zeros(dim, np.int64) for _ in range(3))
        st = np.zeros(SHELL_STATE, np.int64)
        rmax = int(np.max(np.maximum(np.abs(c0 - lo), np.abs(hi - c0))))
        for r in range(rmax + 1):
            got = []
            if shell_start(r, c0, lo, hi, a0, a1, st):
                while shell_next(r, c0, lo, hi, a0, a1, cc, st):
                    got.append(tuple(int(v) for v in cc))
            box = np.stack(np.meshgrid(*[np.arange(a, b + 1) for a, b in zip(lo, hi)], indexing="ij"), -1)
            box = box.reshape(-1, dim)
            on = box[np.abs(box - c0).max(1) == r]
            want = sorted(map(tuple, on.tolist()), key=lambda c: (c[:0:-1], c[0]))
            assert got == want, (lo, hi, c0, r)
