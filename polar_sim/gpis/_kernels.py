"""Numba batch operations on the tree: ordered inserts/removals of one update, re-evaluation
candidates (spec §6.1), training sets (§8.1) and the per-point cluster choice and GP blend (§9)."""

from __future__ import annotations

import numba as nb
import numpy as np

from polar_sim.gpis._localgp import _dot4
from polar_sim.gpis._tree import _insert, _lin, _node_of, _remove

__all__ = ["apply_new", "apply_reeval", "candidates", "dirty_slots", "gather_training", "query_gp",
           "maybe_new"]


@nb.njit(cache=True)
def apply_new(P, ok, bad, nrm, sp, sg, geo, root, level_off, L, cgrid, gshape, goff,
              node_sample, node_internal, slot_coord, slot_free, pos, s_slot, s_node, s_free,
              counts, strict, s_nrm, s_sp, s_sg, slot_gen):
    """Stage 3 in scan order: insert each ok point; undo it when its finite differences failed.

    Returns the sample index of each kept new point (-1 otherwise).
    """
    n = P.shape[0]
    out = np.full(n, -1, np.int64)
    dim = P.shape[1]
    for j in range(n):
        if not ok[j]:
            continue
        hw = counts[2]
        i, s = _insert(P[j], geo, root, level_off, L, cgrid, gshape, goff, node_sample,
                       node_internal, slot_coord, slot_free, pos, s_slot, s_node, s_free, counts,
                       strict, nrm[j], s_nrm, sg[j], s_sg)
        if i < 0:
            continue
        if counts[2] != hw or node_sample[s, 0] == i:
            slot_gen[s] += 1
        if bad[j]:
            _remove(i, dim, level_off, cgrid, gshape, goff, node_sample, node_internal,
                    slot_coord, slot_free, s_slot, s_node, s_free, counts)
            continue
        for k in range(dim):
            s_nrm[i, k] = nrm[j, k]
        s_sp[i] = sp[j]
        s_sg[i] = sg[j]
        out[j] = i
    return out


@nb.njit(cache=True)
def apply_reeval(cand, action, P, nrm, sp, sg, geo, root, level_off, L, cgrid, gshape, goff,
                 node_sample, node_internal, slot_coord, slot_free, pos, s_slot, s_node, s_free,
                 counts, strict, s_nrm, s_sp, s_sg, slot_gen):
    """Stage 2 tree updates in candidate order.

    action: 0 leave, 1 double the noises in place, 2 remove and re-insert at P (fused),
    3 remove for good. Returns the new sample index of each candidate (-1 if gone or untouched).
    """
    n = cand.shape[0]
    out = np.full(n, -1, np.int64)
    dim = P.shape[1]
    for j in range(n):
        i = cand[j]
        a = action[j]
        if a == 1:
            s_sp[i] *= 2.0
            s_sg[i] *= 2.0
            continue
        if a < 2:
            continue
        _remove(i, dim, level_off, cgrid, gshape, goff, node_sample, node_internal, slot_coord,
                slot_free, s_slot, s_node, s_free, counts)
        if a == 3:
            continue
        hw = counts[2]
        ni, s = _insert(P[j], geo, root, level_off, L, cgrid, gshape, goff, node_sample,
                        node_internal, slot_coord, slot_free, pos, s_slot, s_node, s_free, counts,
                        strict, nrm[j], s_nrm, sg[j], s_sg)
        if ni < 0:
            continue
        if counts[2] != hw or node_sample[s, 0] == ni:
            slot_gen[s] += 1
        for k in range(dim):
            s_nrm[ni, k] = nrm[j, k]
        s_sp[ni] = sp[j]
        s_sg[ni] = sg[j]
        out[j] = ni
    return out


@nb.njit(cache=True)
def candidates(t, rmax, geo, cgrid, gshape, goff, node_sample, node_internal, level_off, hc):
    """Children of the non-empty, non-leaf clusters near t (spec §6.1).

    Returns (child centres (k, d), CSR pointer (k + 1,), sample indices) in grid order.
    """
    dim = t.shape[0]
    w = geo[dim]
    lo = np.empty(dim, np.int64)
    hi = np.empty(dim, np.int64)
    for k in range(dim):
        lo[k] = max(int(np.floor((t[k] - rmax - geo[k]) / w)), goff[k])
        hi[k] = min(int(np.floor((t[k] + rmax - geo[k]) / w)), goff[k] + gshape[k] - 1)
    nch = 1 << dim
    cap = 64
    cent = np.empty((cap, dim))
    ptr = np.zeros(cap + 1, np.int64)
    samp = np.empty(1024, np.int64)
    nc = 0
    ns = 0
    total = 1
    for k in range(dim):
        if hi[k] < lo[k]:
            return cent[:0], ptr[:1], samp[:0]
        total *= hi[k] - lo[k] + 1
    cc = np.empty(dim, np.int64)
    lim = rmax * rmax + 2.0 * hc * hc
    for flat in range(total):
        r = flat
        for k in range(dim):
            span = hi[k] - lo[k] + 1
            cc[k] = lo[k] + r % span
            r //= span
        g = _lin(cc, gshape, goff)
        s = cgrid[g]
        if s < 0 or not node_internal[s, 0]:
            continue
        d2 = 0.0
        for k in range(dim):
            e = geo[k] + (cc[k] + 0.5) * w - t[k]
            d2 += e * e
        if d2 > lim:
            continue
        for b in range(nch):
            if nc + 1 >= cap:
                cap *= 2
                c2 = np.empty((cap, dim))
                c2[:nc] = cent[:nc]
                cent = c2
                p2 = np.zeros(cap + 1, np.int64)
                p2[: nc + 1] = ptr[: nc + 1]
                ptr = p2
            for k in range(dim):
                cent[nc, k] = geo[k] + cc[k] * w + (((b >> k) & 1) + 0.5) * (w / 2)
            # samples whose level-1 ancestor is child b
            for node in range(1, node_sample.shape[1]):
                i = node_sample[s, node]
                if i < 0:
                    continue
                lvl = 0
                while node >= level_off[lvl + 1]:
                    lvl += 1
                n = 1 << lvl
                rr = node - level_off[lvl]
                bb = 0
                for k in range(dim):
                    c = rr % n
                    rr //= n
                    bb |= (c >> (lvl - 1)) << k
                if bb != b:
                    continue
                if ns >= samp.shape[0]:
                    s2 = np.empty(2 * samp.shape[0], np.int64)
                    s2[:ns] = samp[:ns]
                    samp = s2
                samp[ns] = i
                ns += 1
            nc += 1
            ptr[nc] = ns
    return cent[:nc], ptr[: nc + 1], samp[:ns]


@nb.njit(cache=True)
def _kept_radius2(s, cap, gp_obs, gp_m, X, kinds, c0):
    """Squared distance from centre c0 to the farthest training sample of slot s's GP when the
    GP holds exactly ``cap`` samples (its training set was capped, or just full); else inf."""
    m = gp_m[s] if s < gp_m.shape[0] else 0
    o = gp_obs[s] if s < gp_obs.shape[0] else 0
    nv = 0
    far = 0.0
    while nv < m and (kinds[o + nv] >> 32) == 0:   # value observations come first, one per sample
        d2 = 0.0
        for k in range(c0.shape[0]):
            e = X[o + nv, k] - c0[k]
            d2 += e * e
        far = max(far, d2)
        nv += 1
    return far if (cap > 0 and nv == cap) else np.inf


@nb.njit(cache=True)
def dirty_slots(pts, R, cap, geo, cgrid, gshape, goff, slot_coord, nslots, gp_obs, gp_m, X, kinds):
    """Sorted slots of the non-empty clusters whose training set may hold one of pts (n, d).

    A cluster's training set is its samples within R of its centre (spec §8.1), or with a cap
    the ``cap`` nearest of them: a position counts when it lies within R of the centre and, for
    a GP trained on a full set of ``cap`` samples, no farther than its farthest sample (a point
    beyond it neither was nor would be kept). Ties count, so the test never misses a change."""
    n, dim = pts.shape
    w = geo[dim]
    reach = int(np.ceil(R / w - 0.5))
    mark = np.zeros(nslots, np.bool_)
    kept = np.full(nslots, -1.0)          # the kept radius^2 of each slot, computed once
    span = 2 * reach + 1
    total = 1
    for _ in range(dim):
        total *= span
    cc = np.empty(dim, np.int64)
    c0 = np.empty(dim, np.int64)
    cen = np.empty(dim)
    for j in range(n):
        for k in range(dim):
            c0[k] = np.int64(np.floor((pts[j, k] - geo[k]) / w))
        for flat in range(total):
            r = flat
            for k in range(dim):
                cc[k] = c0[k] + r % span - reach
                r //= span
            g = _lin(cc, gshape, goff)
            if g < 0:
                continue
            s = cgrid[g]
            if s < 0 or mark[s]:
                continue
            d2 = 0.0
            for k in range(dim):
                cen[k] = geo[k] + (slot_coord[s, k] + 0.5) * w
                e = pts[j, k] - cen[k]
                d2 += e * e
            if not d2 < R * R:
                continue
            if kept[s] < 0.0:
                kept[s] = _kept_radius2(s, cap, gp_obs, gp_m, X, kinds, cen)
            if d2 <= kept[s]:
                mark[s] = True
    return np.nonzero(mark)[0].astype(np.int64)


@nb.njit(cache=True)
def gather_training(slots, R, geo, cgrid, gshape, goff, node_sample, slot_coord, pos, cap=0):
    """CSR of the samples within R of each cluster centre (spec §8.1, Q_R).

    ``cap`` > 0 keeps only the ``cap`` samples nearest the centre (ties to the one gathered
    first), in gathering order; 0 keeps them all."""
    dim = pos.shape[1]
    w = geo[dim]
    reach = int(np.ceil(R / w - 0.5))
    span = 2 * reach + 1
    total = 1
    for _ in range(dim):
        total *= span
    ptr = np.zeros(slots.shape[0] + 1, np.int64)
    out = np.empty(1024, np.int64)
    n = 0
    cc = np.empty(dim, np.int64)
    c0 = np.empty(dim)
    for a in range(slots.shape[0]):
        s0 = slots[a]
        for k in range(dim):
            c0[k] = geo[k] + (slot_coord[s0, k] + 0.5) * w
        for flat in range(total):
            r = flat
            for k in range(dim):
                cc[k] = slot_coord[s0, k] + r % span - reach
                r //= span
            g = _lin(cc, gshape, goff)
            if g < 0:
                continue
            s = cgrid[g]
            if s < 0:
                continue
            for node in range(node_sample.shape[1]):
                i = node_sample[s, node]
                if i < 0:
                    continue
                d2 = 0.0
                for k in range(dim):
                    e = pos[i, k] - c0[k]
                    d2 += e * e
                if d2 < R * R:
                    if n >= out.shape[0]:
                        o2 = np.empty(2 * out.shape[0], np.int64)
                        o2[:n] = out[:n]
                        out = o2
                    out[n] = i
                    n += 1
        start = ptr[a]
        if cap > 0 and n - start > cap:
            d2s = np.empty(n - start)
            for u in range(n - start):
                d2 = 0.0
                for k in range(dim):
                    e = pos[out[start + u], k] - c0[k]
                    d2 += e * e
                d2s[u] = d2
            keep = np.sort(np.argsort(d2s, kind="mergesort")[:cap])
            chosen = out[start + keep]
            out[start:start + cap] = chosen
            n = start + cap
        ptr[a + 1] = n
    return ptr, out[:n]


@nb.njit(cache=True)
def _nearest3(x, W, geo, cgrid, gshape, goff, node_sample, node_internal, best_s, best_d,
              best_k, iw):
    """Up to 3 nearest non-empty clusters (by centre) whose box meets the box of half W at x.

    Ties in distance go to the cluster that comes first in grid order (last axis slowest), as
    in a plain scan of the box. The cells are visited in rings around x's own cell, and the
    search stops once no further ring can hold a nearer centre. ``best_k`` (3,) and ``iw``
    (6 * dim,) are int64 work arrays (no allocation per point).
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
        # the cells at Chebyshev distance r from c0, inside the box
        total = 1
        empty = False
        for k in range(1, dim):
            a0[k] = max(c0[k] - r, lo[k])
            a1[k] = min(c0[k] + r, hi[k])
            if a1[k] < a0[k]:
                empty = True
            total *= a1[k] - a0[k] + 1
        if empty:
            continue
        for flat in range(total):
            f = flat
            edge = False
            for k in range(1, dim):
                span = a1[k] - a0[k] + 1
                cc[k] = a0[k] + f % span
                f //= span
                if abs(cc[k] - c0[k]) == r:
                    edge = True
            xs = c0[0] - r
            step = 1 if (edge or r == 0) else 2 * r
            while xs <= c0[0] + r:
                cx = xs
                xs += step
                if cx < lo[0] or cx > hi[0]:
                    continue
                cc[0] = cx
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


def query_gp(pts, *args):
    """GP query; large batches run on all cores (numba threads), small ones serially."""
    if pts.shape[0] >= 20000:
        return _query_gp_par(pts, *args)
    return _query_gp_ser(pts, *args)


_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01     # ln 2 in two parts (Cody-Waite): k * _LN2_HI is exact
_LN2_LO = 1.90821492927058770002e-10


@nb.njit(cache=True, fastmath=False)
def _exp_neg(x, n, work):
    """x[:n] = exp(x[:n]) in place for x <= 0, within 1 ulp of ``np.exp`` (0 below -708).

    A loop that vectorises (numba's scalar ``exp`` is a libm call per element, and the query
    takes one per training sample and point): exp(x) = 2^k exp(f), x = k ln 2 + f, |f| <= ln 2 / 2,
    exp(f) by its Taylor polynomial of degree 13 (truncation < 1e-17 relative); 2^k is built
    from its bits in ``work`` (float64, >= n, viewed as int64).
    """
    bits = work.view(np.int64)
    for p in range(n):
        v = max(x[p], -708.0)
        k = np.floor(v * _LOG2E + 0.5)
        f = (v - k * _LN2_HI) - k * _LN2_LO
        y = 1.0 / 6227020800.0
        y = y * f + 1.0 / 479001600.0
        y = y * f + 1.0 / 39916800.0
        y = y * f + 1.0 / 3628800.0
        y = y * f + 1.0 / 362880.0
        y = y * f + 1.0 / 40320.0
        y = y * f + 1.0 / 5040.0
        y = y * f + 1.0 / 720.0
        y = y * f + 1.0 / 120.0
        y = y * f + 1.0 / 24.0
        y = y * f + 1.0 / 6.0
        y = y * f + 0.5
        y = y * f + 1.0
        y = y * f + 1.0
        x[p] = y if x[p] >= -708.0 else 0.0
        bits[p] = (np.int64(k) + 1023) << 52
    for p in range(n):
        x[p] *= work[p]


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
    for p in range(nv, m):
        c = (kinds[p] >> 32) - 1
        u = kinds[p] & 0xFFFFFFFF
        e = ex[u]
        dc = eb[1 + c, u]
        k0 = a2 * dc * e
        z[p] = k0
        ap = alpha[p]
        s0 += k0 * ap
        inv_r = ir[u]
        v = (1.0 if c == 0 else 0.0) - a * d0[u] * dc * inv_r
        s1 += (a2 * v * e) * ap
        v = (1.0 if c == 1 else 0.0) - a * d1[u] * dc * inv_r
        s2 += (a2 * v * e) * ap
        if dim == 3:
            v = (1.0 if c == 2 else 0.0) - a * d2[u] * dc * inv_r
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
    iw = np.empty(6 * dim, np.int64)
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


@nb.njit(cache=True)
def _slot_samples(node_sample, nslots):
    """CSR (ptr, idx) of the samples of each cluster slot, in node order."""
    ptr = np.zeros(nslots + 1, np.int64)
    for s in range(nslots):
        c = 0
        row = node_sample[s]
        for j in range(row.shape[0]):
            if row[j] >= 0:
                c += 1
        ptr[s + 1] = ptr[s] + c
    idx = np.empty(ptr[nslots], np.int64)
    for s in range(nslots):
        o = ptr[s]
        row = node_sample[s]
        for j in range(row.shape[0]):
            if row[j] >= 0:
                idx[o] = row[j]
                o += 1
    return ptr, idx


@nb.njit(cache=True)
def _too_close_csr(p, cc, hmin, dim, cgrid, gshape, goff, sptr, sidx, pos, q):
    """``_tree._too_close_neighbours`` over a CSR of the clusters' samples (same answer)."""
    nb_ = 1
    for _ in range(dim):
        nb_ *= 3
    h2 = hmin * hmin
    for t in range(nb_):
        r = t
        for k in range(dim):
            q[k] = cc[k] + (r % 3) - 1
            r //= 3
        g = _lin(q, gshape, goff)
        if g < 0:
            continue
        s = cgrid[g]
        if s < 0:
            continue
        for j in range(sptr[s], sptr[s + 1]):
            i = sidx[j]
            d2 = 0.0
            for k in range(dim):
                e = pos[i, k] - p[k]
                d2 += e * e
            if d2 < h2:
                return True
    return False


@nb.njit(cache=True)
def maybe_new(P, geo, root, level_off, cgrid, gshape, goff, node_sample, node_internal, pos,
              strict):
    """False where an insert of P would be rejected by a sample already in the tree.

    In strict mode this is exact for the whole update (existing samples only move in stage 2);
    in chain-only mode it is the test against the tree as it stands before stage 3.
    """
    n, dim = P.shape
    out = np.ones(n, np.bool_)
    w = geo[dim]
    hmin = geo[dim + 1]
    lo = np.empty(dim)
    cc = np.empty(dim, np.int64)
    qw = np.empty(dim, np.int64)
    if strict:
        sptr, sidx = _slot_samples(node_sample, node_sample.shape[0])
    else:
        sptr, sidx = np.zeros(1, np.int64), np.zeros(0, np.int64)
    for j in range(n):
        p = P[j]
        for k in range(dim):
            cc[k] = int(np.floor((p[k] - geo[k]) / w))
        if strict:
            if _too_close_csr(p, cc, geo[dim + 3], dim, cgrid, gshape, goff, sptr, sidx, pos, qw):
                out[j] = False
            continue
        g = _lin(cc, gshape, goff)
        if g < 0:
            continue
        s = cgrid[g]
        if s < 0:
            continue
        for k in range(dim):
            lo[k] = geo[k] + cc[k] * w
        node = 0
        lvl = 0
        while node_internal[s, node]:
            lvl += 1
            node = _node_of(p, lo, w, lvl, dim, level_off)
        q = node_sample[s, node]
        if q >= 0:
            d2 = 0.0
            for k in range(dim):
                e = pos[q, k] - p[k]
                d2 += e * e
            if d2 < hmin * hmin:
                out[j] = False
    return out
