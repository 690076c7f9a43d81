"""Numba batch operations on the tree: ordered inserts/removals of one update, re-evaluation
candidates (spec §6.1), training sets (§8.1) and the per-cluster sample lists."""

from __future__ import annotations

import numba as nb
import numpy as np

from polar_sim.gpis._native import entry
from polar_sim.gpis._tree import _insert, _lin, _node_of, _remove, slot_members

__all__ = ["apply_new", "apply_reeval", "candidates", "dirty_slots", "gather_training",
           "maybe_new", "reeval_changes"]


@entry
@nb.njit(cache=True)
def apply_new(P, ok, bad, nrm, sp, sg, geo, root, level_off, L, cgrid, gshape, goff,
              node_sample, node_internal, slot_coord, slot_free, pos, s_slot, s_node, s_free,
              counts, strict, link, slot_head, s_nrm, s_sp, s_sg, slot_gen):
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
                       strict, link, slot_head, nrm[j], s_nrm, sg[j], s_sg)
        if i < 0:
            continue
        if counts[2] != hw or node_sample[s, 0] == i:
            slot_gen[s] += 1
        if bad[j]:
            _remove(i, dim, level_off, cgrid, gshape, goff, node_sample, node_internal,
                    slot_coord, slot_free, s_slot, s_node, s_free, counts, link, slot_head)
            continue
        for k in range(dim):
            s_nrm[i, k] = nrm[j, k]
        s_sp[i] = sp[j]
        s_sg[i] = sg[j]
        out[j] = i
    return out


@entry
@nb.njit(cache=True)
def apply_reeval(cand, action, P, nrm, sp, sg, geo, root, level_off, L, cgrid, gshape, goff,
                 node_sample, node_internal, slot_coord, slot_free, pos, s_slot, s_node, s_free,
                 counts, strict, link, slot_head, s_nrm, s_sp, s_sg, slot_gen):
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
                slot_free, s_slot, s_node, s_free, counts, link, slot_head)
        if a == 3:
            continue
        hw = counts[2]
        ni, s = _insert(P[j], geo, root, level_off, L, cgrid, gshape, goff, node_sample,
                        node_internal, slot_coord, slot_free, pos, s_slot, s_node, s_free, counts,
                        strict, link, slot_head, nrm[j], s_nrm, sg[j], s_sg)
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


@entry
@nb.njit(cache=True)
def candidates(t, rmax, geo, cgrid, gshape, goff, node_internal, level_off, hc, slot_head, link,
               s_node, node_sample, singletons):
    """Children of the non-empty, non-leaf clusters near t (spec §6.1).

    Returns (child centres (k, d), CSR pointer (k + 1,), sample indices) in grid order. With
    ``singletons`` a cluster that is itself a leaf contributes its one sample (``node_sample``,
    the tree's), under the cluster's centre; without, it contributes nothing: the spec's [quirk]
    by which a sample alone in its cluster is never re-evaluated.
    """
    dim = t.shape[0]
    w = geo[dim]
    lo = np.empty(dim, np.int64)
    hi = np.empty(dim, np.int64)
    for k in range(dim):
        lo[k] = max(int(np.floor((t[k] - rmax - geo[k]) / w)), goff[k])
        hi[k] = min(int(np.floor((t[k] + rmax - geo[k]) / w)), goff[k] + gshape[k] - 1)
    nch = 1 << dim
    cent = np.empty((64, dim))
    ptr = np.zeros(65, np.int64)
    samp = np.empty(1024, np.int64)
    buf = np.empty(64, np.int64)
    cnt = 0
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
        if s < 0 or not (node_internal[s, 0] or (singletons and node_sample[s, 0] >= 0)):
            continue
        d2 = 0.0
        for k in range(dim):
            e = geo[k] + (cc[k] + 0.5) * w - t[k]
            d2 += e * e
        if d2 > lim:
            continue
        if not node_internal[s, 0]:         # a leaf cluster: its one sample, under its centre
            cent, ptr, samp = _grown(cent, ptr, samp, nc, ns)
            for k in range(dim):
                cent[nc, k] = geo[k] + (cc[k] + 0.5) * w
            samp[ns] = node_sample[s, 0]
            ns += 1
            nc += 1
            ptr[nc] = ns
            continue
        for b in range(nch):
            cent, ptr, samp = _grown(cent, ptr, samp, nc, ns)
            for k in range(dim):
                cent[nc, k] = geo[k] + cc[k] * w + (((b >> k) & 1) + 0.5) * (w / 2)
            # samples whose level-1 ancestor is child b, in node order
            if b == 0:
                buf, cnt = slot_members(s, slot_head, link, s_node, buf)
            for u in range(cnt):
                i = buf[u]
                node = np.int64(s_node[i])
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
                    cent, ptr, samp = _grown(cent, ptr, samp, nc, ns)
                samp[ns] = i
                ns += 1
            nc += 1
            ptr[nc] = ns
    return cent[:nc], ptr[: nc + 1], samp[:ns]


@nb.njit(cache=True)
def _grown(cent, ptr, samp, nc, ns):
    """The output buffers of :func:`candidates` with room for one more child and one more
    sample (doubled when full; the first nc children and ns samples kept)."""
    cap = cent.shape[0]
    if nc + 1 >= cap:
        c2 = np.empty((2 * cap, cent.shape[1]))
        c2[:nc] = cent[:nc]
        cent = c2
        p2 = np.zeros(2 * cap + 1, np.int64)
        p2[: nc + 1] = ptr[: nc + 1]
        ptr = p2
    if ns >= samp.shape[0]:
        s2 = np.empty(2 * samp.shape[0], np.int64)
        s2[:ns] = samp[:ns]
        samp = s2
    return cent, ptr, samp


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


@entry
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


@entry
@nb.njit(cache=True)
def gather_training(slots, R, geo, cgrid, gshape, goff, slot_head, link, s_node, slot_coord, pos,
                    cap=0):
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
    buf = np.empty(64, np.int64)
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
            buf, cnt = slot_members(s, slot_head, link, s_node, buf)
            for u in range(cnt):             # node order
                i = buf[u]
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


@entry
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


@entry
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


@entry
@nb.njit(cache=True)
def reeval_changes(cand, action, new, pos, nrm, sp, sg, pos_t, nrm_t, sp_t, sg_t, tol, every):
    """After stage 2 (``apply_reeval`` gave each candidate's new index, -1 if gone): which
    changes the trained GPs must see, and the training snapshots (``*_t``) brought up to date.

    A candidate counts when it left the map, or when (re-measured, action >= 1) its position
    moved more than ``tol``, its normal turned more than 0.05 rad or a noise changed more than
    2x since the values its GPs were trained on (``every``: any re-measurement counts, as
    published). Counted samples get a fresh snapshot; the others carry theirs to their new
    index. Returns the world positions (old snapshot and new position) of the counted ones,
    and those of every kept sample (the published retraining's "touched").
    """
    k, d = cand.shape[0], pos.shape[1]
    dirty = np.zeros(k, np.bool_)
    ch = np.empty((2 * k, d))
    nch = 0
    for j in range(k):                        # read every snapshot before writing any
        i = cand[j]
        a = action[j]
        if every:
            dirty[j] = a >= 1
        elif a >= 2 and new[j] < 0:
            dirty[j] = True
        elif a >= 1:
            c = new[j] if new[j] >= 0 else i
            dp = 0.0
            dn = 0.0
            for q in range(d):
                dp += (pos[c, q] - pos_t[i, q]) ** 2
                dn += (nrm[c, q] - nrm_t[i, q]) ** 2
            dirty[j] = (np.sqrt(dp) > tol or np.sqrt(dn) > 0.05 or sp[c] > 2 * sp_t[i]
                        or 2 * sp[c] < sp_t[i] or sg[c] > 2 * sg_t[i] or 2 * sg[c] < sg_t[i])
        if dirty[j]:
            ch[nch] = pos_t[i]
            nch += 1
    carry_p = np.empty((k, d))
    carry_n = np.empty((k, d))
    carry_s = np.empty((k, 2))
    for j in range(k):
        i = cand[j]
        carry_p[j] = pos_t[i]
        carry_n[j] = nrm_t[i]
        carry_s[j, 0] = sp_t[i]
        carry_s[j, 1] = sg_t[i]
    nt = 0
    touched = np.empty((k, d))
    for j in range(k):
        c = new[j]
        if c >= 0:
            touched[nt] = pos[c]
            nt += 1
        if dirty[j] and (c >= 0 or action[j] == 1):
            c = c if c >= 0 else cand[j]      # fused or re-inserted: its new values; doubled: in place
            if new[j] >= 0:
                ch[nch] = pos[c]
                nch += 1
            pos_t[c] = pos[c]
            nrm_t[c] = nrm[c]
            sp_t[c] = sp[c]
            sg_t[c] = sg[c]
        elif c >= 0:
            pos_t[c] = carry_p[j]
            nrm_t[c] = carry_n[j]
            sp_t[c] = carry_s[j, 0]
            sg_t[c] = carry_s[j, 1]
    return ch[:nch], touched[:nt]
