"""Numba batch operations on the tree: ordered inserts/removals of one update, re-evaluation
candidates (spec §6.1), training sets (§8.1) and the per-point cluster choice and GP blend (§9)."""

from __future__ import annotations

import numba as nb
import numpy as np

from polar_sim.gpis._localgp import _predict_one
from polar_sim.gpis._tree import _insert, _lin, _node_of, _remove, _too_close_neighbours

__all__ = ["apply_new", "apply_reeval", "candidates", "gather_training", "query_gp", "maybe_new"]


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
                       strict)
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
                        strict)
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
def gather_training(slots, R, geo, cgrid, gshape, goff, node_sample, slot_coord, pos):
    """CSR of the samples within R of each cluster centre (spec §8.1, Q_R)."""
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
        ptr[a + 1] = n
    return ptr, out[:n]


@nb.njit(cache=True)
def _nearest3(x, W, geo, cgrid, gshape, goff, node_sample, node_internal, best_s, best_d):
    """Up to 3 nearest non-empty clusters (by centre) whose box meets the box of half W at x."""
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
        # insertion into the sorted top 3 (stable: earlier scan order wins ties)
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


@nb.njit(cache=True)
def _query_rows(i0, i1, pts, W, T, legacy, scale, var_f0, var_g0, default_var, geo, cgrid, gshape, goff,
             node_sample, node_internal, slot_gen, gp_gen, gp_m, gp_obs, gp_tri, X, kinds, alpha,
             Lbuf, mmax, out):
    """GP query of spec §9.1 for points i0..i1-1; out rows [f, grad(d), var_f, var_grad(d)]."""
    dim = pts.shape[1]
    a = np.sqrt(3.0) / scale
    if True:
        kb = np.empty((mmax, dim + 2))
        zb = np.empty(mmax)
        best_s = np.empty(3, np.int64)
        best_d = np.empty(3)
        cand = np.empty((3, 2 * dim + 2))
        cvar = np.empty(3)
        for i in range(i0, i1):
            o = out[i]
            o[:] = 0.0
            o[dim + 1] = default_var
            for k in range(dim):
                o[dim + 2 + k] = np.nan
            nc = _nearest3(pts[i], W, geo, cgrid, gshape, goff, node_sample, node_internal,
                           best_s, best_d)
            if not legacy:
                # keep only clusters that have a current GP
                m = 0
                for j in range(nc):
                    s = best_s[j]
                    if gp_m[s] > 0 and gp_gen[s] == slot_gen[s]:
                        best_s[m] = s
                        m += 1
                nc = m
            if nc == 0:
                continue
            s = best_s[0]
            if gp_m[s] == 0 or gp_gen[s] != slot_gen[s]:
                continue
            m0 = gp_m[s]
            ob = gp_obs[s]
            _predict_one(pts[i], Lbuf[gp_tri[s]:], alpha[ob:ob + m0], X[ob:ob + m0],
                         kinds[ob:ob + m0], a, dim, var_f0, var_g0, False, cand[0], kb, zb)
            if nc == 1 or cand[0, dim + 1] <= T:
                o[:] = cand[0]
                continue
            nn = 1
            for j in range(1, nc):
                s = best_s[j]
                if gp_m[s] == 0 or gp_gen[s] != slot_gen[s]:
                    continue
                m0 = gp_m[s]
                ob = gp_obs[s]
                _predict_one(pts[i], Lbuf[gp_tri[s]:], alpha[ob:ob + m0], X[ob:ob + m0],
                             kinds[ob:ob + m0], a, dim, var_f0, var_g0, False, cand[nn], kb, zb)
                nn += 1
            for j in range(nn):
                cvar[j] = cand[j, dim + 1]
            # order the candidates by var_f (stable)
            order = np.argsort(cvar[:nn], kind="mergesort")
            ia = order[0]
            if cvar[ia] < T or nn == 1:
                o[:] = cand[ia]
                continue
            ib = order[1]
            wa = cvar[ib] - T
            wb = cvar[ia] - T
            for k in range(2 * dim + 2):
                o[k] = (wa * cand[ia, k] + wb * cand[ib, k]) / (wa + wb)


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
    nblk = 64
    for blk in nb.prange((n + nblk - 1) // nblk):
        _query_rows(blk * nblk, min(n, (blk + 1) * nblk), pts, W, T, legacy, scale, var_f0,
                    var_g0, default_var, geo, cgrid, gshape, goff, node_sample, node_internal,
                    slot_gen, gp_gen, gp_m, gp_obs, gp_tri, X, kinds, alpha, Lbuf, mmax, out)


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
    for j in range(n):
        p = P[j]
        for k in range(dim):
            cc[k] = int(np.floor((p[k] - geo[k]) / w))
        if strict:
            if _too_close_neighbours(p, cc, geo[dim + 3], dim, cgrid, gshape, goff, node_sample,
                                     pos):
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
