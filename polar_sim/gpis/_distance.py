"""Faithful Euclidean distance far from surfaces (default mode).

Far from the surface the GPIS value drifts back to its bias, so the default query blends it with
the distance to the fused surface samples, each treated as a small disc ("surfel") of radius
``r_s`` centred on the sample and orthogonal to its normal: for a sample p with unit normal n and
``v = x - p``, ``a = v.n``, tangential part ``t = v - a n``,
``d = sqrt(a^2 + max(|t| - r_s, 0)^2)``. The distance is the minimum over the k nearest samples.

Sign: positive where the point lies in *observed free space* (a coarse grid of cells that some ray
crossed before its return, :class:`FreeSpace`) and is more than one cell diagonal from the nearest
surfel; elsewhere the sign of ``a`` of the closest surfel, i.e. negative behind (on the occluded
side of) the surface. With a sign width ``h`` > 0 (both maps' default mode), the sign there is
instead that of the implicit moving-least-squares surface of the k nearest surfels with a trusted
normal (Kolluri 2005), ``sum_j w_j a_j`` with ``w_j = exp(-|x - p_j|^2 / h^2)`` (the closest
surfel's side where none is near): next to an edge or a corner, the closest *disc* often belongs
to the adjacent face, whose plane the point lies behind although it is outside the object; the
centre-distance weights let the face the point actually faces decide.

Variance: in observed free space, the fused position variance of the closest sample (how well the
surface that sets the distance is known); elsewhere, never-observed space, the GP prior variance
``1 + map_noise``: the distance there is only the distance to the nearest *observed* surface.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from polar_sim.gpis._native import K, entry
from polar_sim.gpis._shells import SHELL_STATE, shell_next, shell_start
from polar_sim.gpis._tree import _lin

__all__ = ["FreeSpace", "far_field", "far_weights", "blend_gp"]


@entry
@nb.njit(cache=True)
def _mark(grid, gshape, goff, res, origin, hits, margin):
    dim = origin.shape[0]
    step = 0.5 * res
    c = np.empty(dim, np.int64)
    for h in range(hits.shape[0]):
        L2 = 0.0
        for k in range(dim):
            e = hits[h, k] - origin[k]
            L2 += e * e
        L = np.sqrt(L2)
        Lr = L - margin * res
        if not Lr > 0 or not np.isfinite(L):
            continue
        # only the part of the ray inside the grid's box is walked (slab clipping), so the work
        # per ray is bounded by the grid, whatever the ray's length or position
        t0, t1 = 0.0, Lr / L
        for k in range(dim):
            dk = hits[h, k] - origin[k]
            blo = goff[k] * res
            bhi = (goff[k] + gshape[k]) * res
            if dk == 0.0:
                if origin[k] < blo or origin[k] >= bhi:
                    t1 = -1.0
            else:
                ta = (blo - origin[k]) / dk
                tb = (bhi - origin[k]) / dk
                if ta > tb:
                    ta, tb = tb, ta
                t0 = max(t0, ta)
                t1 = min(t1, tb)
        if not t0 <= t1:
            continue
        n = int(Lr / step) + 1
        s0 = max(int(t0 * L / step) - 1, 0)
        s1 = min(int(t1 * L / step) + 2, n)
        for s in range(s0, s1):
            t = min(s * step, Lr) / L
            idx = 0
            stride = 1
            ok = True
            for k in range(dim):
                x = origin[k] + t * (hits[h, k] - origin[k])
                xf = np.floor(x / res) - goff[k]      # compared as a float: no overflowing cast
                if not (xf >= 0 and xf < gshape[k]):
                    ok = False
                    break
                c[k] = int(xf)
                idx += c[k] * stride
                stride *= gshape[k]
            if ok:
                grid[idx] = 1


class FreeSpace:
    """Cells (edge ``res`` metres) that a sensor ray crossed at least ``margin`` cells before its return."""

    def __init__(self, dim, res, margin=1.5, reach=np.inf):
        # ``reach``: the grid never extends beyond [-reach, reach]^dim (metres), the region the
        # map's tree can ever hold samples in; rays outside it are not recorded
        self.dim, self.res, self.margin = dim, float(res), float(margin)
        self.reach = float(reach)
        self.grid = np.zeros(0, np.uint8)
        self.gshape = np.zeros(dim, np.int64)
        self.goff = np.zeros(dim, np.int64)

    def _cover(self, lo, hi):
        glo, ghi = self.goff, self.goff + self.gshape
        if self.grid.size and (lo >= glo).all() and (hi <= ghi).all():
            return
        if self.grid.size:
            pad = (ghi - glo) // 4
            lo = np.minimum(lo, glo - np.where(lo < glo, pad, 0))
            hi = np.maximum(hi, ghi + np.where(hi > ghi, pad, 0))
        shape = hi - lo
        new = np.zeros(tuple(shape[::-1]), np.uint8)
        if self.grid.size:
            sl = tuple(slice(int(a), int(a + s)) for a, s in zip((glo - lo)[::-1], self.gshape[::-1]))
            new[sl] = self.grid.reshape(tuple(self.gshape[::-1]))
        self.grid = new.ravel()
        self.gshape, self.goff = shape.astype(np.int64), lo.astype(np.int64)

    def mark(self, origin, hits):
        """Mark the cells along the rays from ``origin`` (d,) to ``hits`` (n, d)."""
        if len(hits) == 0:
            return
        pts = np.vstack([hits, origin[None]])
        # the cover is clipped to the reachable box before any integer conversion: a scan far
        # away (1e12 m) grows nothing
        lim = np.floor(self.reach / self.res) + 2.0
        lo = np.clip(np.floor(pts.min(0) / self.res) - 1, -lim, lim)
        hi = np.clip(np.floor(pts.max(0) / self.res) + 2, -lim, lim)
        if not (hi > lo).all():
            return
        self._cover(lo.astype(np.int64), hi.astype(np.int64))
        K._mark(self.grid, self.gshape, self.goff, self.res, np.ascontiguousarray(origin, np.float64),
              np.ascontiguousarray(hits, np.float64), self.margin)

    def observed(self, pts):
        """True where the point lies in a cell marked free."""
        if self.grid.size == 0:
            return np.zeros(len(pts), bool)
        c = np.floor(pts / self.res).astype(np.int64) - self.goff
        inside = ((c >= 0) & (c < self.gshape)).all(1)
        strides = np.cumprod(np.concatenate([[1], self.gshape[:-1]]))
        flat = (np.where(inside[:, None], c, 0) * strides).sum(1)
        return inside & (self.grid[flat] > 0)

    def nbytes(self):
        return self.grid.nbytes

    def state(self):
        return {"grid": self.grid, "gshape": self.gshape, "goff": self.goff}

    def set_state(self, st):
        self.grid = np.ascontiguousarray(st["grid"], np.uint8).copy()
        self.gshape = np.asarray(st["gshape"], np.int64).copy()
        self.goff = np.asarray(st["goff"], np.int64).copy()


@nb.njit(cache=True)
def _imls(pts, i, gi, pos, nrm, sg, gate, h, fallback):
    """Implicit MLS value ``sum_j w_j a_j / sum_j w_j`` at point i over its surfels gi[i] (m),
    ``w_j = exp(-(|x - p_j|^2 - min_j |x - p_j|^2) / h^2)`` (shifted by the nearest centre so
    that it cannot underflow), over the surfels with a trusted normal (gradient noise <= gate);
    ``fallback`` if their weights sum below exp(-9), none lying within about 3 h of the nearest
    centre's distance (a surface seen only with untrusted normals must not take its side from a
    trusted one farther away)."""
    d = pts.shape[1]
    k = gi.shape[1]
    r2min = np.inf
    for j in range(k):
        s = gi[i, j]
        r2 = 0.0
        for c in range(d):
            e = pts[i, c] - pos[s, c]
            r2 += e * e
        r2min = min(r2min, r2)
    num = 0.0
    den = 0.0
    for j in range(k):
        s = gi[i, j]
        nl = 0.0
        r2 = 0.0
        a = 0.0
        for c in range(d):
            e = pts[i, c] - pos[s, c]
            r2 += e * e
            a += e * nrm[s, c]
            nl += nrm[s, c] * nrm[s, c]
        if nl <= 0.25 or sg[s] > gate:
            continue
        wj = np.exp(-(r2 - r2min) / (h * h))
        num += wj * a / np.sqrt(nl)
        den += wj
    return num / den if den > np.exp(-9.0) else fallback


@entry
@nb.njit(cache=True)
def _surfels(pts, gi, pos, nrm, sp, sg, gate, r_s, seen, cell_diag, var_unobs, dist, grad, var,
             dtrust, sign_h=0.0):
    n, d = pts.shape
    k = gi.shape[1]
    v = np.empty(d)
    t = np.empty(d)
    for i in range(n):
        best = np.inf
        bt = np.inf                  # nearest surfel whose normal is trusted
        bj = -1
        ba = 0.0
        for j in range(k):
            s = gi[i, j]
            nl = 0.0
            for c in range(d):
                v[c] = pts[i, c] - pos[s, c]
                nl += nrm[s, c] * nrm[s, c]
            nl = np.sqrt(nl)
            if nl > 0.5:
                a = 0.0
                for c in range(d):
                    a += v[c] * nrm[s, c] / nl
                tl = 0.0
                for c in range(d):
                    e = v[c] - a * nrm[s, c] / nl
                    tl += e * e
                tl = np.sqrt(tl)
                ex = max(tl - r_s, 0.0)
                dk = np.sqrt(a * a + ex * ex)
            else:
                a = 0.0
                dk = 0.0
                for c in range(d):
                    dk += v[c] * v[c]
                dk = np.sqrt(dk)
            if dk < best:
                best, bj, ba = dk, j, a
            if sg[s] <= gate and dk < bt:
                bt = dk
        s = gi[i, bj]
        nl = 0.0
        for c in range(d):
            nl += nrm[s, c] * nrm[s, c]
        nl = np.sqrt(nl)
        rs = r_s if nl > 0.5 else 0.0
        # closest point on the chosen surfel, and the unit direction from it
        tl = 0.0
        for c in range(d):
            v[c] = pts[i, c] - pos[s, c]
            t[c] = v[c] - (ba * nrm[s, c] / nl if nl > 0.5 else v[c])
            tl += t[c] * t[c]
        tl = np.sqrt(tl)
        sc = min(tl, rs) / tl if tl > 0 else 0.0
        gl = 0.0
        for c in range(d):
            v[c] = v[c] - sc * t[c]
            gl += v[c] * v[c]
        gl = np.sqrt(gl)
        # observed free space decides the sign beyond one cell diagonal of the surfel, and also
        # within it when the surfel's normal is not trusted (gradient noise above ``gate``)
        ok = seen[i] and (best > cell_diag or sg[s] > gate)
        if ok:
            sign = 1.0
        else:
            side = ba if sign_h <= 0.0 else _imls(pts, i, gi, pos, nrm, sg, gate, sign_h, ba)
            sign = 1.0 if side >= 0 else -1.0
        dist[i] = sign * best
        for c in range(d):
            if gl > 0:
                grad[i, c] = sign * v[c] / gl
            else:
                grad[i, c] = sign * (nrm[s, c] / nl if nl > 0.5 else 0.0)
        var[i] = min(sp[s], var_unobs) if ok else var_unobs
        dtrust[i] = bt


@entry
@nb.njit(cache=True)
def knn(pts, k, geo, cgrid, gshape, goff, sptr, sidx, pos, out):
    """Indices (n, k) into ``out`` of the k samples nearest each point (nearest first; ties to
    the one met first), by a search in shells of cluster cells around the point's cell
    (:mod:`._shells`).

    ``sptr``/``sidx`` list each cluster slot's samples (CSR); ``cgrid`` maps the grid cells
    (origin ``geo[:d]``, edge ``geo[d]``, shape ``gshape`` from ``goff``) to slots. The search
    stops once no unsearched cell can hold a nearer sample than the k-th found. A point outside
    the grid starts from the nearest edge cell. Needs k <= the number of samples.
    """
    n, dim = pts.shape
    w = geo[dim]
    lo = np.empty(dim, np.int64)
    hi = np.empty(dim, np.int64)
    for j in range(dim):
        lo[j] = goff[j]
        hi[j] = goff[j] + gshape[j] - 1
    c0 = np.empty(dim, np.int64)
    cc = np.empty(dim, np.int64)
    a0 = np.empty(dim, np.int64)
    a1 = np.empty(dim, np.int64)
    bd = np.empty(k)
    st = np.empty(SHELL_STATE, np.int64)
    for i in range(n):
        x = pts[i]
        rmax = 0
        for j in range(dim):
            cf = np.floor((x[j] - geo[j]) / w)
            c = lo[j] if not cf >= lo[j] else (hi[j] if cf > hi[j] else np.int64(cf))
            c0[j] = c
            rmax = max(rmax, c - lo[j], hi[j] - c)
        found = 0
        for r in range(rmax + 1):
            if found == k and r >= 1:
                lb = np.inf
                for j in range(dim):
                    if c0[j] - r >= lo[j]:
                        lb = min(lb, max(x[j] - (geo[j] + (c0[j] - r + 1) * w), 0.0))
                    if c0[j] + r <= hi[j]:
                        lb = min(lb, max(geo[j] + (c0[j] + r) * w - x[j], 0.0))
                if lb * lb > bd[k - 1]:
                    break
            if not shell_start(r, c0, lo, hi, a0, a1, st):
                continue
            while shell_next(r, c0, lo, hi, a0, a1, cc, st):
                s = cgrid[_lin(cc, gshape, goff)]
                if s < 0:
                    continue
                for u in range(sptr[s], sptr[s + 1]):
                    q = sidx[u]
                    d2 = 0.0
                    for j in range(dim):
                        e = pos[q, j] - x[j]
                        d2 += e * e
                    if found < k:
                        m = found
                        found += 1
                    elif d2 < bd[k - 1]:
                        m = k - 1
                    else:
                        continue
                    while m > 0 and bd[m - 1] > d2:
                        bd[m] = bd[m - 1]
                        out[i, m] = out[i, m - 1]
                        m -= 1
                    bd[m] = d2
                    out[i, m] = q


def far_field(pts, gi, pos, nrm, sp, sg, r_s, free, var_unobs, gate=np.inf, sign_h=0.0):
    """Surfel distance with sign, its gradient and variance at pts (n, d) from each point's
    nearest samples gi (n, k) (None: the map has none); see the module docs (``sign_h``: width of
    the implicit-MLS sign, m; 0 = the closest surfel's side)."""
    n, d = pts.shape
    if gi is None:
        return np.full(n, np.inf), np.zeros((n, d)), np.full(n, var_unobs)
    dist, grad, var = np.empty(n), np.empty((n, d)), np.empty(n)
    # a free cell may straddle the surface: trust it only beyond one cell diagonal
    K._surfels(pts, np.ascontiguousarray(gi, np.int64), pos, nrm, sp, sg, float(gate), float(r_s),
             free.observed(pts), free.res * np.sqrt(d), float(var_unobs), dist, grad, var,
             np.empty(n), float(sign_h))
    return dist, grad, var


@nb.njit(cache=True)
def _observed(pts, grid, gshape, goff, res, seen):
    """``FreeSpace.observed`` in one pass (same cells, same answer)."""
    n, d = pts.shape
    for i in range(n):
        seen[i] = False
        if grid.shape[0] == 0:
            continue
        flat = 0
        stride = 1
        inside = True
        for k in range(d):
            c = np.int64(np.floor(pts[i, k] / res)) - goff[k]
            if c < 0 or c >= gshape[k]:
                inside = False
            flat += c * stride
            stride *= gshape[k]
        seen[i] = inside and grid[flat] > 0


@entry
@nb.njit(cache=True)
def _far_weights(pts, gi, pos, nrm, sp, sg, gate, use_trust, r_s, grid, gshape, goff, res,
                 cell_diag, var_unobs,
                 near, far, dist, grad, var, w, sign_h=0.0, behind=0.5):
    """Surfel distance, gradient, variance (``far_field``) and the GPIS blend weight (0..1)."""
    n = pts.shape[0]
    seen = np.empty(n, np.bool_)
    _observed(pts, grid, gshape, goff, res, seen)
    dtrust = np.empty(n)
    _surfels(pts, gi, pos, nrm, sp, sg, gate, r_s, seen, cell_diag, var_unobs, dist, grad, var,
             dtrust, sign_h)
    nsel = 0
    for i in range(n):
        # the GPIS learned its shape from trusted normals only: its weight follows the distance
        # to the nearest trusted surfel (with gate = inf, every surfel: the nearest one)
        a = max(abs(dist[i]), dtrust[i]) if use_trust else abs(dist[i])
        # behind surfaces the GP has no data: with ``behind`` < 1 the surfel distance takes over
        # that much earlier there
        sc = behind if dist[i] < 0 else 1.0
        x = (far * sc - a) / ((far - near) * sc)
        x = min(max(x, 0.0), 1.0)
        x = x * x * (3.0 - 2.0 * x)               # smoothstep: C1 at both ends
        w[i] = x
        if x > 0:
            nsel += 1
    return nsel


def far_weights(pts, gi, pos, nrm, sp, sg, r_s, free, var_unobs, near, far, gate=np.inf,
                sign_h=0.0, behind=0.5):
    """(dist, grad, var, w): ``far_field`` and the smoothstep weight of the GPIS (``behind``
    scales the blend band on the negative side)."""
    n, d = pts.shape
    dist, grad, var, w = np.empty(n), np.empty((n, d)), np.empty(n), np.empty(n)
    K._far_weights(pts, gi, pos, nrm, sp, sg, float(gate), bool(np.isfinite(gate)), float(r_s),
                 free.grid, free.gshape, free.goff, float(free.res), free.res * np.sqrt(d),
                 float(var_unobs), float(near), float(far), dist, grad, var, w, float(sign_h),
                 float(behind))
    return dist, grad, var, w


@entry
@nb.njit(cache=True)
def blend_gp(sel, out, w, fbias, has_thr, dist, grad, var, t_info=0.0):
    """Blend the GPIS rows ``out`` (one per selected point) into the surfel answer in place.

    With ``t_info`` > 0 the GPIS weight is also scaled by how much the GP knows there,
    ``clip(1 - var_f / t_info, 0, 1)``: a GP whose samples carry no gradient observation (poorly
    seen surfaces, whose samples fail the gradient gate) has a value but no zero level, and
    near var_f >= t_info (the spec's query threshold for "uninformative") the surfel distance is
    used instead."""
    d = grad.shape[1]
    for j in range(sel.shape[0]):
        i = sel[j]
        o = out[j]
        ws = w[i] if o[d + 1] < has_thr else 0.0     # a cluster answered
        if t_info > 0.0:
            ws *= min(max(1.0 - o[d + 1] / t_info, 0.0), 1.0)
        dist[i] = ws * (o[0] + fbias) + (1 - ws) * dist[i]
        for k in range(d):
            grad[i, k] = ws * o[1 + k] + (1 - ws) * grad[i, k]
        var[i] = ws * o[d + 1] + (1 - ws) * var[i]
