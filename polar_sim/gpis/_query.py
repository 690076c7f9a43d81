"""The query (spec §9): the per-point cluster choice and GP blend, and the default mode's
faithful distance (the GPIS near surfaces blended into the surfel distance) in one kernel."""

from __future__ import annotations

import numba as nb
import numpy as np

from polar_sim.gpis._distance import _far_weights, blend_gp, knn
from polar_sim.gpis._localgp import _dot4
from polar_sim.gpis._native import K, entry
from polar_sim.gpis._numeric import _exp_neg
from polar_sim.gpis._shells import SHELL_STATE, shell_next, shell_start
from polar_sim.gpis._tree import _lin

__all__ = ["PARALLEL_POINTS", "query_gp", "faithful"]


@nb.njit(cache=True)
def _nearest3(x, W, geo, cgrid, gshape, goff, node_sample, node_internal, best_s, best_d,
              best_k, iw):
    """Up to 3 nearest non-empty clusters (by centre) whose box meets the box of half W at x.

    Ties in distance go to the cluster that comes first in grid order (last axis slowest), as
    in a plain scan of the box. The cells are visited in shells around x's own cell
    (:mod:`._shells`), and the search stops once no further shell can hold a nearer centre. ``best_k`` (3,) and ``iw``
    (6 * dim + SHELL_STATE,) are int64 work arrays (no allocation per point).
    """
    dim = x.shape[0]
    w = geo[dim]
    hc = w / 2
    lo = iw[0:dim]
    hi = iw[dim:2 * dim]
    c0 = iw[2 * dim:3 * dim]
    cc = iw[3 * dim:4 * dim]
    a0 = iw[4 * dim:5 * dim]
    a1 = iw[5 * dim:6 * dim]
    st = iw[6 * dim:6 * dim + SHELL_STATE]
    rmax = 0
    for k in range(dim):
        lo[k] = max(int(np.ceil((x[k] - W - hc - geo[k]) / w - 0.5)), goff[k])
        hi[k] = min(int(np.floor((x[k] + W + hc - geo[k]) / w - 0.5)), goff[k] + gshape[k] - 1)
        if hi[k] < lo[k]:
            return 0
        c0[k] = int(np.floor((x[k] - geo[k]) / w))
        rmax = max(rmax, abs(c0[k] - lo[k]), abs(hi[k] - c0[k]))
    n = 0
    for r in range(rmax + 1):
        if n == 3 and r >= 1:
            lb = (r - 0.5) * w
            if lb * lb > best_d[2] * (1.0 + 1e-9):
                break
        if not shell_start(r, c0, lo, hi, a0, a1, st):
            continue
        while shell_next(r, c0, lo, hi, a0, a1, cc, st):
            s = cgrid[_lin(cc, gshape, goff)]
            if s < 0 or (node_sample[s, 0] < 0 and not node_internal[s, 0]):
                continue
            d2 = 0.0
            for k in range(dim):
                e = geo[k] + (cc[k] + 0.5) * w - x[k]
                d2 += e * e
            # position in a scan of the box (first axis fastest): the tie-break
            key = 0
            stride = 1
            for k in range(dim):
                key += (cc[k] - lo[k]) * stride
                stride *= hi[k] - lo[k] + 1
            if n < 3:
                j = n
                n += 1
            elif d2 < best_d[2] or (d2 == best_d[2] and key < best_k[2]):
                j = 2
            else:
                continue
            while j > 0 and (best_d[j - 1] > d2 or (best_d[j - 1] == d2
                                                     and best_k[j - 1] > key)):
                best_d[j] = best_d[j - 1]
                best_s[j] = best_s[j - 1]
                best_k[j] = best_k[j - 1]
                j -= 1
            best_d[j] = d2
            best_s[j] = s
            best_k[j] = key
    return n


@nb.njit(cache=True)
def _nearest3_scan(x, W, geo, cgrid, gshape, goff, node_sample, node_internal, best_s, best_d,
                   best_k, iw):
    """Reference for ``_nearest3``: a plain scan of the whole box (tests)."""
    dim = x.shape[0]
    w = geo[dim]
    hc = w / 2
    lo = np.empty(dim, np.int64)
    hi = np.empty(dim, np.int64)
    total = 1
    for k in range(dim):
        lo[k] = max(int(np.ceil((x[k] - W - hc - geo[k]) / w - 0.5)), goff[k])
        hi[k] = min(int(np.floor((x[k] + W + hc - geo[k]) / w - 0.5)), goff[k] + gshape[k] - 1)
        if hi[k] < lo[k]:
            return 0
        total *= hi[k] - lo[k] + 1
    n = 0
    cc = np.empty(dim, np.int64)
    for flat in range(total):
        r = flat
        for k in range(dim):
            span = hi[k] - lo[k] + 1
            cc[k] = lo[k] + r % span
            r //= span
        s = cgrid[_lin(cc, gshape, goff)]
        if s < 0 or (node_sample[s, 0] < 0 and not node_internal[s, 0]):
            continue
        d2 = 0.0
        for k in range(dim):
            e = geo[k] + (cc[k] + 0.5) * w - x[k]
            d2 += e * e
        if n < 3:
            j = n
            n += 1
        elif d2 < best_d[2]:
            j = 2
        else:
            continue
        while j > 0 and best_d[j - 1] > d2:
            best_d[j] = best_d[j - 1]
            best_s[j] = best_s[j - 1]
            j -= 1
        best_d[j] = d2
        best_s[j] = s
    return n


#: Batches of at least this many points query the GPs on all cores (numba threads).
PARALLEL_POINTS = 20000


def query_gp(pts, *args):
    """GP query; large batches run on all cores (numba threads), small ones serially."""
    if pts.shape[0] >= PARALLEL_POINTS:
        return _query_gp_par(pts, *args)
    return K._query_gp_ser(pts, *args)


# reassociation lets the sums over the observations vectorise (no other fast-math licence)
@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _ks_mean(x, alpha, X, kinds, a, dim, z, eb, out):
    """One GP at x: the value cross-covariances k(x, obs) into z (m,), the mean [f, grad]
    into out.

    The arithmetic of ``_localgp._predict_one``, summed in another order. The per-sample
    quantities (x - X, r, exp, then 1/r) are computed once per sample, in loops over the
    samples that vectorise, and reused by its gradient observations, whose cross-covariances go
    straight into their sums. ``eb`` (dim + 3, >= m): rows r then 1/r, x - X (dim),
    exp(-a r), and ``_exp_neg``'s work row.
    """
    m = X.shape[0]
    a2 = a * a
    nv = 0
    while nv < m and (kinds[nv] >> 32) == 0:
        nv += 1
    ir = eb[0]
    d0 = eb[1]
    d1 = eb[2]
    d2 = eb[dim]                    # (dim == 3 only)
    ex = eb[dim + 1]
    x0 = x[0]
    x1 = x[1]
    x2 = x[dim - 1]
    for p in range(nv):
        e0 = x0 - X[p, 0]
        e1 = x1 - X[p, 1]
        r2 = e0 * e0 + e1 * e1
        if dim == 3:
            e2 = x2 - X[p, 2]
            r2 += e2 * e2
            d2[p] = e2
        d0[p] = e0
        d1[p] = e1
        ir[p] = np.sqrt(r2)
    for p in range(nv):
        ex[p] = -a * ir[p]
    _exp_neg(ex, nv, eb[dim + 2])
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    for p in range(nv):
        r = ir[p]
        e = ex[p]
        k0 = (1.0 + a * r) * e
        z[p] = k0
        ir[p] = 1.0 / r if r > 0.0 else 0.0
        ap = alpha[p]
        s0 += k0 * ap
        s1 += (-a2 * d0[p] * e) * ap
        s2 += (-a2 * d1[p] * e) * ap
        if dim == 3:
            s3 += (-a2 * d2[p] * e) * ap
    # gradient observations: one block per component c, each the samples with a gradient in
    # sample order (``_localgp._train_one``'s layout); when every sample has one, sample j of
    # block c is value observation j and the loop reads contiguous rows (it vectorises)
    ng = (m - nv) // dim
    dense = ng == 0 or (kinds[nv + ng - 1] & 0xFFFFFFFF) == ng - 1
    if not dense:                   # gather the gradient samples' rows into contiguous ones
        for j in range(ng):
            u = kinds[nv + j] & 0xFFFFFFFF
            for r in range(dim + 2):
                eb[r, nv + j] = eb[r, u]
        base = nv
    else:
        base = 0
    for c in range(dim):
        dc_row = eb[1 + c, base:base + ng]
        ir_g = ir[base:base + ng]
        d0_g = d0[base:base + ng]
        d1_g = d1[base:base + ng]
        d2_g = d2[base:base + ng]
        ex_g = ex[base:base + ng]
        al = alpha[nv + c * ng:nv + (c + 1) * ng]
        zc = z[nv + c * ng:nv + (c + 1) * ng]
        e0 = 1.0 if c == 0 else 0.0
        e1 = 1.0 if c == 1 else 0.0
        e2 = 1.0 if c == 2 else 0.0
        for j in range(ng):
            e = ex_g[j]
            dc = dc_row[j]
            k0 = a2 * dc * e
            zc[j] = k0
            ap = al[j]
            s0 += k0 * ap
            inv_r = ir_g[j]
            v = e0 - a * d0_g[j] * dc * inv_r
            s1 += (a2 * v * e) * ap
            v = e1 - a * d1_g[j] * dc * inv_r
            s2 += (a2 * v * e) * ap
            if dim == 3:
                v = e2 - a * d2_g[j] * dc * inv_r
                s3 += (a2 * v * e) * ap
    out[0] = s0
    out[1] = s1
    out[2] = s2
    if dim == 3:
        out[3] = s3


@nb.njit(cache=True)
def _tri_sq4(Lp, Z, m, acc):
    """acc[b] = |L^-1 z_b|^2 for the four rows z_b of Z (4, >= m), overwritten.

    Forward substitution on the packed lower factor, four right-hand sides at once: each factor
    row is read once for the four dot products. Every lane goes through the same operations,
    so a point's result does not depend on the other three (nor on the batch it came in).
    """
    z0 = Z[0]
    z1 = Z[1]
    z2 = Z[2]
    z3 = Z[3]
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    o = 0
    for p in range(m):
        t0, t1, t2, t3 = _dot4(z0, z1, z2, z3, Lp[o:o + p], p)
        d = Lp[o + p]
        v0 = (z0[p] - t0) / d
        v1 = (z1[p] - t1) / d
        v2 = (z2[p] - t2) / d
        v3 = (z3[p] - t3) / d
        z0[p] = v0
        z1[p] = v1
        z2[p] = v2
        z3[p] = v3
        a0 += v0 * v0
        a1 += v1 * v1
        a2 += v2 * v2
        a3 += v3 * v3
        o += p + 1
    acc[0] = a0
    acc[1] = a1
    acc[2] = a2
    acc[3] = a3


@nb.njit(cache=True)
def _eval_group(ev_pt, ev_out, order, g0, g1, s, pts, a, dim, var_f0, gp_m, gp_obs, gp_tri, X,
                kinds, alpha, Lbuf, rbuf, Z, acc, cand):
    """Predict [f, grad, var_f] of cluster s at the points of evaluations order[g0:g1].

    Means one point at a time; variances four points at a time (``_tri_sq4``; a short last
    quad repeats its last point).
    """
    m0 = gp_m[s]
    ob = gp_obs[s]
    Lp = Lbuf[gp_tri[s]:]
    Xs = X[ob:ob + m0]
    ks_ = kinds[ob:ob + m0]
    al = alpha[ob:ob + m0]
    for c0 in range(g0, g1, 4):
        c1 = min(g1, c0 + 4)
        for t in range(c0, c0 + 4):
            b = t - c0
            if t < c1:
                e = order[t]
                _ks_mean(pts[ev_pt[e]], al, Xs, ks_, a, dim, Z[b], rbuf,
                         cand[ev_pt[e], ev_out[e]])
            else:
                Z[b, :m0] = Z[c1 - 1 - c0, :m0]
        _tri_sq4(Lp, Z, m0, acc)
        for t in range(c0, c1):
            e = order[t]
            cand[ev_pt[e], ev_out[e], dim + 1] = var_f0 - acc[t - c0]


@nb.njit(cache=True)
def _run_evals(ne, ev_pt, ev_out, ev_s, pts, a, dim, var_f0, gp_m, gp_obs, gp_tri, X, kinds,
               alpha, Lbuf, rbuf, Z, acc, cand):
    """Evaluate the ne (point, cluster) pairs, grouped by cluster (stable, so deterministic)."""
    if ne == 0:
        return
    order = np.argsort(ev_s[:ne], kind="mergesort")
    g0 = np.int64(0)  # not a literal 0: numba would type (and compile) _eval_group for Literal[int](0) too
    while g0 < ne:
        s = ev_s[order[g0]]
        g1 = g0 + 1
        while g1 < ne and ev_s[order[g1]] == s:
            g1 += 1
        _eval_group(ev_pt, ev_out, order, g0, g1, s, pts, a, dim, var_f0, gp_m, gp_obs, gp_tri,
                    X, kinds, alpha, Lbuf, rbuf, Z, acc, cand)
        g0 = g1


@nb.njit(cache=True)
def _lt(x, y):
    """x < y with NaN last (numpy's sort order)."""
    if np.isnan(x):
        return False
    return np.isnan(y) or x < y


@nb.njit(cache=True)
def _query_rows(i0, i1, pts, W, T, legacy, scale, var_f0, var_g0, default_var, geo, cgrid,
                gshape, goff, node_sample, node_internal, slot_gen, gp_gen, gp_m, gp_obs, gp_tri,
                X, kinds, alpha, Lbuf, mmax, out):
    """GP query of spec §9.1 for points i0..i1-1; out rows [f, grad(d), var_f, var_grad(d)].

    Per point: the nearest cluster's GP; when its var_f exceeds T, also the other (up to two)
    nearest clusters', then the lowest-variance one or a variance-weighted blend of the best
    two. The evaluations are grouped by cluster (factor reused from cache, variance solves four
    points at a time).
    """
    dim = pts.shape[1]
    n = i1 - i0
    a = np.sqrt(3.0) / scale
    ncol = 2 * dim + 2
    cs = np.empty((n, 3), np.int64)          # clusters with a usable GP, nearest first
    nv = np.zeros(n, np.int64)
    cand = np.empty((n, 3, ncol))
    ev_pt = np.empty(3 * n, np.int64)
    ev_out = np.empty(3 * n, np.int64)
    ev_s = np.empty(3 * n, np.int64)
    best_s = np.empty(3, np.int64)
    best_d = np.empty(3)
    best_k = np.empty(3, np.int64)
    iw = np.empty(6 * dim + SHELL_STATE, np.int64)
    rbuf = np.empty((dim + 3, mmax))
    Z = np.empty((4, mmax))
    acc = np.empty(4)
    ne = np.int64(0)  # not a literal 0 (see _run_evals)
    for t in range(n):
        i = i0 + t
        o = out[i]
        o[:] = 0.0
        o[dim + 1] = default_var
        for k in range(dim):
            o[dim + 2 + k] = np.nan
        nc = _nearest3(pts[i], W, geo, cgrid, gshape, goff, node_sample, node_internal,
                       best_s, best_d, best_k, iw)
        k = 0
        for j in range(nc):
            s = best_s[j]
            if gp_m[s] > 0 and gp_gen[s] == slot_gen[s]:
                cs[t, k] = s
                k += 1
            elif j == 0 and legacy:
                k = 0                         # nearest cluster without a current GP: no answer
                break
        nv[t] = k
        for j in range(3):
            for c in range(dim + 2, ncol):
                cand[t, j, c] = np.nan
        if k > 0:
            ev_pt[ne] = t
            ev_out[ne] = 0
            ev_s[ne] = cs[t, 0]
            ne += 1
    sub = pts[i0:i1]
    _run_evals(ne, ev_pt, ev_out, ev_s, sub, a, dim, var_f0, gp_m, gp_obs, gp_tri, X, kinds,
               alpha, Lbuf, rbuf, Z, acc, cand)
    # second round: the other clusters of points whose nearest GP is not confident enough
    ne = np.int64(0)  # not a literal 0 (see _run_evals)
    for t in range(n):
        if nv[t] > 1 and cand[t, 0, dim + 1] > T:
            for j in range(1, nv[t]):
                ev_pt[ne] = t
                ev_out[ne] = j
                ev_s[ne] = cs[t, j]
                ne += 1
    _run_evals(ne, ev_pt, ev_out, ev_s, sub, a, dim, var_f0, gp_m, gp_obs, gp_tri, X, kinds,
               alpha, Lbuf, rbuf, Z, acc, cand)
    for t in range(n):
        k = nv[t]
        if k == 0:
            continue
        o = out[i0 + t]
        c0 = cand[t, 0]
        if k == 1 or c0[dim + 1] <= T:
            o[:] = c0
            continue
        # order the candidates by var_f (stable, NaN last, as numpy's mergesort)
        ia, ib = 0, 1
        v = cand[t, :, dim + 1]
        if _lt(v[1], v[0]):
            ia, ib = 1, 0
        if k == 3 and _lt(v[2], v[ib]):
            ib = 2
            if _lt(v[2], v[ia]):
                ib = ia
                ia = 2
        if v[ia] < T:
            o[:] = cand[t, ia]
            continue
        wa = v[ib] - T
        wb = v[ia] - T
        for c in range(ncol):
            o[c] = (wa * cand[t, ia, c] + wb * cand[t, ib, c]) / (wa + wb)


# Two entry points with distinct names: numba's cache index does not key on the ``parallel``
# flag, so one Python function jitted twice with cache=True shares one cache entry, and the
# "serial" dispatcher could load the threaded build (which stalls on a loaded machine).
@entry
@nb.njit(cache=True)
def _query_gp_ser(pts, W, T, legacy, scale, var_f0, var_g0, default_var, geo, cgrid, gshape,
                  goff, node_sample, node_internal, slot_gen, gp_gen, gp_m, gp_obs, gp_tri, X,
                  kinds, alpha, Lbuf, mmax, out):
    _query_rows(0, pts.shape[0], pts, W, T, legacy, scale, var_f0, var_g0, default_var, geo,
                cgrid, gshape, goff, node_sample, node_internal, slot_gen, gp_gen, gp_m, gp_obs,
                gp_tri, X, kinds, alpha, Lbuf, mmax, out)


@nb.njit(cache=True, parallel=True)
def _query_gp_par(pts, W, T, legacy, scale, var_f0, var_g0, default_var, geo, cgrid, gshape,
                  goff, node_sample, node_internal, slot_gen, gp_gen, gp_m, gp_obs, gp_tri, X,
                  kinds, alpha, Lbuf, mmax, out):
    n = pts.shape[0]
    nblk = 4096
    for blk in nb.prange((n + nblk - 1) // nblk):
        _query_rows(blk * nblk, min(n, (blk + 1) * nblk), pts, W, T, legacy, scale, var_f0,
                    var_g0, default_var, geo, cgrid, gshape, goff, node_sample, node_internal,
                    slot_gen, gp_gen, gp_m, gp_obs, gp_tri, X, kinds, alpha, Lbuf, mmax, out)




@entry
@nb.njit(cache=True)
def faithful(pts, k, sptr, sidx, pos, nrm, sp, sg, gate, use_trust, r_s, fgrid, fshape, foff, fres,
             var_unobs, near, far, sign_h, behind, W, T, legacy, scale, var_f0, var_g0, fbias,
             t_info, geo, cgrid, gshape, goff, node_sample, node_internal, slot_gen, gp_gen, gp_m,
             gp_obs, gp_tri, X, kinds, alpha, Lbuf, mmax, dist, grad, var):
    """The default query at pts (n, d) into dist (n,), grad (n, d), var (n,).

    The surfel distance of the k nearest samples (``_distance``), then, where its blend weight
    is positive, the GPIS of the nearest clusters (``_query_rows``) blended in (``blend_gp``).
    ``sptr``/``sidx`` list each cluster slot's samples; ``var_unobs`` is the prior variance.
    """
    n, dim = pts.shape
    gi = np.empty((n, k), np.int64)
    knn(pts, k, geo, cgrid, gshape, goff, sptr, sidx, pos, gi)
    w = np.empty(n)
    _far_weights(pts, gi, pos, nrm, sp, sg, gate, use_trust, r_s, fgrid, fshape, foff, fres,
                 fres * np.sqrt(dim), var_unobs, near, far, dist, grad, var, w, sign_h, behind)
    ns = 0
    for i in range(n):
        if w[i] > 0:
            ns += 1
    if ns == 0:
        return
    sel = np.empty(ns, np.int64)
    sub = np.empty((ns, dim))
    j = 0
    for i in range(n):
        if w[i] > 0:
            sel[j] = i
            for c in range(dim):
                sub[j, c] = pts[i, c]
            j += 1
    out = np.empty((ns, 2 * dim + 2))
    _query_rows(0, ns, sub, W, T, legacy, scale, var_f0, var_g0, var_unobs, geo, cgrid, gshape,
                goff, node_sample, node_internal, slot_gen, gp_gen, gp_m, gp_obs, gp_tri, X, kinds,
                alpha, Lbuf, mmax, out)
    blend_gp(sel, out, w, fbias, var_unobs - 1e-12, dist, grad, var, t_info)
