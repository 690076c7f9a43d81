"""Quadtree / octree of surface samples (spec §7), stored as flat arrays for numba.

The tree above cluster level is a regular grid: cluster cells (half-length ``h_c``) have borders
at ``origin + k * 2 h_c`` whatever the root's growth, so the cells above cluster level carry no
information beyond the root box (kept for the root-limit test). Each cluster cell owns a complete
``2^d``-ary subtree of fixed depth ``L`` (levels 0 = cluster ... L = max-depth, ``h < h_min``),
stored as two rows of ``node_sample`` / ``node_internal``; nodes are numbered level by level.
A dense grid ``cgrid`` (grown on demand over the bounding box of the clusters) maps cluster
coordinates to a slot. Samples live in flat arrays with a free list, so slots are reused.

Each cluster's samples are also chained in a doubly linked list (``link[i] = (next, prev)``,
``slot_head[s]``), kept by insert and remove, so that the kernels visit a cluster's few samples
without scanning its subtree's nodes; where the order matters they sort them by node. The lists
are derived state: not saved, rebuilt on load.

Semantics follow the spec: a leaf at or below cluster level holds at most one sample; inserting
next to a sample closer than ``h_min`` in the same leaf is rejected (the chain-only "IsNotNew"
test); a max-depth cell never splits; removal collapses parents whose children are all empty
leaves. With ``spacing`` given (default mode) an insert is also rejected when closer than
``spacing`` to *any* sample in the 3^d neighbouring clusters (the spacing the spec intends).

Each sample also carries ``run`` (2,): how far (m) the scans' returns were seen to run on along
its face past it, on the side of its tangent (-n_y, n_x) and of the opposite one (2D default mode,
:func:`polar_sim.gpis._scan2d.face_runs`; zeros elsewhere, +inf in a file written before them). A
re-inserted sample keeps its runs (``GPISMapBase._run_update``).

With ``face_cos`` given (2D default mode), spacing applies only between samples of the same
surface side: a sample whose normal makes a dot product below ``face_cos`` with the new one's
(the other face of a wall thinner than the spacing) neither blocks it nor shares its leaf, and
the tree has leaves of half-length ``leaf_half`` (< ``min_half``) so that both faces fit.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from polar_sim.gpis._native import K, entry

__all__ = ["Tree"]

_I32 = np.int32
_FACE_SG = 0.1001       # gradient-noise gate of the local GPs (spec §8.2)


@nb.njit(cache=True)
def _lin(coords, gshape, goff):
    """Flat index into the cluster grid of integer cluster coordinates, or -1 if outside."""
    idx = 0
    stride = 1
    for k in range(coords.shape[0]):
        c = coords[k] - goff[k]
        if c < 0 or c >= gshape[k]:
            return -1
        idx += c * stride
        stride *= gshape[k]
    return idx


@nb.njit(cache=True)
def _node_of(p, lo, w, level, dim, level_off):
    """Index of the node at ``level`` containing point p in a cluster with low corner lo, width w."""
    n = 1 << level
    cw = w / n
    idx = 0
    stride = 1
    for k in range(dim):
        c = int(np.floor((p[k] - lo[k]) / cw))
        if c < 0:
            c = 0
        elif c >= n:
            c = n - 1
        idx += c * stride
        stride *= n
    return level_off[level] + idx


@nb.njit(cache=True)
def _level_of(node, level_off):
    lvl = 0
    while node >= level_off[lvl + 1]:
        lvl += 1
    return lvl


@nb.njit(cache=True)
def _parent(node, lvl, dim, level_off):
    """Parent index of a node at level ``lvl`` >= 1."""
    n = 1 << lvl
    r = node - level_off[lvl]
    idx = 0
    stride = 1
    for _ in range(dim):
        c = r % n
        r //= n
        idx += (c >> 1) * stride
        stride *= n >> 1
    return level_off[lvl - 1] + idx


@nb.njit(cache=True)
def _first_child(node, lvl, dim, level_off):
    """Coordinates-based iteration helper: returns (level offset, n, coords of node)."""
    n = 1 << lvl
    r = node - level_off[lvl]
    coords = np.empty(dim, np.int64)
    for k in range(dim):
        coords[k] = r % n
        r //= n
    return coords


@nb.njit(cache=True)
def _child_index(coords, bits, lvl, dim, level_off):
    n = 1 << (lvl + 1)
    idx = 0
    stride = 1
    for k in range(dim):
        c = 2 * coords[k] + ((bits >> k) & 1)
        idx += c * stride
        stride *= n
    return level_off[lvl + 1] + idx


@nb.njit(cache=True)
def _cluster_coords(p, origin, w, dim):
    c = np.empty(dim, np.int64)
    for k in range(dim):
        c[k] = int(np.floor((p[k] - origin[k]) / w))
    return c


@nb.njit(cache=True)
def _in_root_or_grow(p, root, hmax, dim):
    """Grow the root toward p until it contains p or reaches its limit; True if p is inside."""
    while True:
        inside = True
        for k in range(dim):
            if not (abs(p[k] - root[k]) < root[dim]):
                inside = False
        if inside:
            return True
        if root[dim + 1] > 0.5:
            return False
        h = root[dim]
        for k in range(dim):
            root[k] += h if p[k] >= root[k] else -h
        root[dim] = 2.0 * h
        if root[dim] > hmax:
            root[dim + 1] = 1.0


@nb.njit(cache=True)
def _too_close_neighbours(p, cc, hmin, dim, cgrid, gshape, goff, slot_head, link, pos, n_p, nrm,
                          face_cos, g_p, sg):
    """True if any sample in the 3^d clusters around cluster cc is closer than hmin to p
    (samples facing away from ``n_p``, normal dot < face_cos, do not count)."""
    nb_ = 1
    for _ in range(dim):
        nb_ *= 3
    q = np.empty(dim, np.int64)
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
        i = slot_head[s]
        while i >= 0:
            d2 = 0.0
            for k in range(dim):
                e = pos[i, k] - p[k]
                d2 += e * e
            if d2 < h2 and not _other_face(n_p, nrm, i, face_cos, dim, g_p, sg):
                return True
            i = link[i, 0]
    return False


@nb.njit(cache=True)
def _link(i, s, link, slot_head):
    """Put sample i at the head of cluster slot s's list."""
    h = slot_head[s]
    link[i, 0] = h
    link[i, 1] = -1
    if h >= 0:
        link[h, 1] = i
    slot_head[s] = i


@nb.njit(cache=True)
def _unlink(i, s, link, slot_head):
    """Take sample i out of cluster slot s's list."""
    nx, pv = link[i, 0], link[i, 1]
    if pv >= 0:
        link[pv, 0] = nx
    else:
        slot_head[s] = nx
    if nx >= 0:
        link[nx, 1] = pv
    link[i, 0] = -1
    link[i, 1] = -1


@entry
@nb.njit(cache=True)
def rebuild_links(node_sample, nslots, link, slot_head):
    """The cluster lists from the node arrays (each in node order)."""
    link[:] = -1
    slot_head[:] = -1
    for s in range(nslots):
        for node in range(node_sample.shape[1] - 1, -1, -1):
            i = node_sample[s, node]
            if i >= 0:
                _link(i, s, link, slot_head)


@nb.njit(cache=True)
def slot_members(s, slot_head, link, s_node, buf):
    """Cluster slot s's samples in node order, into ``buf`` (grown if needed); returns
    (buf, count)."""
    n = 0
    i = slot_head[s]
    while i >= 0:
        if n >= buf.shape[0]:
            b2 = np.empty(2 * buf.shape[0], np.int64)
            b2[:n] = buf[:n]
            buf = b2
        j = n                            # insertion sort by node (the lists are short)
        while j > 0 and s_node[buf[j - 1]] > s_node[i]:
            buf[j] = buf[j - 1]
            j -= 1
        buf[j] = i
        n += 1
        i = link[i, 0]
    return buf, n


@nb.njit(cache=True)
def _other_face(n_p, nrm, i, face_cos, dim, g_p, sg):
    """True if sample i faces away from the normal n_p (dot < face_cos; -inf: never).

    Only trusted normals (both gradient noises within the GP's gradient gate, spec §8.2) tell
    faces apart: a poorly known normal is not evidence of another surface."""
    if not face_cos > -2.0 or g_p > _FACE_SG or sg[i] > _FACE_SG:
        return False
    c = 0.0
    for k in range(dim):
        c += n_p[k] * nrm[i, k]
    return c < face_cos


@entry
@nb.njit(cache=True)
def _insert(p, geo, root, level_off, L, cgrid, gshape, goff, node_sample, node_internal,
            slot_coord, slot_free, pos, s_slot, s_node, s_free, counts, strict, link, slot_head, n_p,
            nrm, g_p, sg):
    """Insert p (normal n_p, gradient noise g_p); return (sample index, cluster slot) or (-1, -1) when rejected.

    geo = [origin(d), cluster width w, h_min, h_max, strict spacing, face_cos]. counts = [n_samples_hw, n_free_samples,
    n_slots_hw, n_free_slots]. The caller guarantees capacity and grid coverage.
    """
    dim = p.shape[0]
    w = geo[dim]
    hmin = geo[dim + 1]
    if not _in_root_or_grow(p, root, geo[dim + 2], dim):
        return -1, -1
    cc = _cluster_coords(p, geo, w, dim)
    g = _lin(cc, gshape, goff)
    if g < 0:
        return -1, -1
    face_cos = geo[dim + 4]
    if strict and _too_close_neighbours(p, cc, geo[dim + 3], dim, cgrid, gshape, goff,
                                        slot_head, link, pos, n_p, nrm, face_cos, g_p, sg):
        return -1, -1
    s = cgrid[g]
    lo = np.empty(dim)
    for k in range(dim):
        lo[k] = geo[k] + cc[k] * w
    node = 0
    lvl = 0
    if s >= 0:
        while True:
            if node_internal[s, node]:
                lvl += 1
                node = _node_of(p, lo, w, lvl, dim, level_off)
                continue
            q = node_sample[s, node]
            if q < 0:
                break
            d2 = 0.0
            for k in range(dim):
                e = pos[q, k] - p[k]
                d2 += e * e
            if lvl == L or (d2 < hmin * hmin
                            and not (strict and _other_face(n_p, nrm, q, face_cos, dim, g_p, sg))):
                return -1, -1
            node_internal[s, node] = 1
            node_sample[s, node] = -1
            cq = _node_of(pos[q], lo, w, lvl + 1, dim, level_off)
            node_sample[s, cq] = q
            s_node[q] = cq
            lvl += 1
            node = _node_of(p, lo, w, lvl, dim, level_off)
    else:
        if counts[3] > 0:
            counts[3] -= 1
            s = slot_free[counts[3]]
        else:
            s = counts[2]
            counts[2] += 1
        node_sample[s, :] = -1
        node_internal[s, :] = 0
        slot_head[s] = -1
        for k in range(dim):
            slot_coord[s, k] = cc[k]
        cgrid[g] = s
    if counts[1] > 0:
        counts[1] -= 1
        i = s_free[counts[1]]
    else:
        i = counts[0]
        counts[0] += 1
    node_sample[s, node] = i
    for k in range(dim):
        pos[i, k] = p[k]
    s_slot[i] = s
    s_node[i] = node
    _link(i, s, link, slot_head)
    return i, s


@entry
@nb.njit(cache=True)
def _remove(i, dim, level_off, cgrid, gshape, goff, node_sample, node_internal, slot_coord,
            slot_free, s_slot, s_node, s_free, counts, link, slot_head):
    """Remove sample i; collapse parents whose children are all empty leaves; free empty clusters."""
    s = s_slot[i]
    _unlink(i, s, link, slot_head)
    node = np.int64(s_node[i])  # int64 throughout: an int32 first pass compiles _parent twice
    node_sample[s, node] = -1
    s_slot[i] = -1
    s_node[i] = -1
    s_free[counts[1]] = i
    counts[1] += 1
    nch = 1 << dim
    lvl = _level_of(node, level_off)
    while lvl > 0:
        par = _parent(node, lvl, dim, level_off)
        coords = _first_child(par, lvl - 1, dim, level_off)
        empty = True
        for b in range(nch):
            c = _child_index(coords, b, lvl - 1, dim, level_off)
            if node_internal[s, c] or node_sample[s, c] >= 0:
                empty = False
                break
        if not empty:
            return
        node_internal[s, par] = 0
        node = par
        lvl -= 1
    if not node_internal[s, 0] and node_sample[s, 0] < 0:
        g = _lin(slot_coord[s], gshape, goff)
        cgrid[g] = -1
        slot_free[counts[3]] = s
        counts[3] += 1


class Tree:
    """Flat-array cluster tree of dimension 2 or 3 (spec §7); owns the sample arrays.

    Parameters are the spec's: ``init_half`` (root half-length at the origin), ``cluster_half``
    (h_c), ``min_half`` (h_min) and ``max_half`` (h_max), in metres.
    """

    def __init__(self, dim, init_half, cluster_half, min_half, max_half, spacing=None,
                 face_cos=None, leaf_half=None):
        self.dim = dim
        ratio = init_half / cluster_half
        if ratio < 1 or abs(np.log2(ratio) - round(np.log2(ratio))) > 1e-9:
            raise ValueError("init_half / cluster_half must be a power of two >= 1")
        L, h = 0, cluster_half
        leaf = min_half if leaf_half is None else float(leaf_half)
        while not h < leaf:
            h /= 2.0
            L += 1
        self.L = L
        B = 1 << dim
        self.level_off = np.array([(B**lv - 1) // (B - 1) for lv in range(L + 2)], np.int64)
        self.n_nodes = int(self.level_off[L + 1])
        w = 2.0 * cluster_half
        sp = 0.0 if spacing is None else float(spacing)
        if sp > w:
            raise ValueError("sample_spacing must not exceed the cluster cell size 2*cluster_half")
        self.face_cos = -np.inf if face_cos is None else float(face_cos)
        self.geo = np.array([-init_half] * dim + [w, min_half, max_half, sp, self.face_cos],
                            np.float64)
        self.root = np.array([0.0] * dim + [init_half, 0.0], np.float64)
        self.strict = spacing is not None
        self.cgrid = np.full(1, -1, _I32)
        self.gshape = np.ones(dim, np.int64)
        self.goff = np.zeros(dim, np.int64)
        self.counts = np.zeros(4, np.int64)
        self._alloc_slots(16)
        self._alloc_samples(256)

    # -- storage -----------------------------------------------------------------------------
    def _alloc_slots(self, n):
        d = self.dim
        old = getattr(self, "node_sample", None)
        ns = np.full((n, self.n_nodes), -1, _I32)
        ni = np.zeros((n, self.n_nodes), np.uint8)
        sc = np.zeros((n, d), np.int64)
        sf = np.zeros(n, _I32)
        sh = np.full(n, -1, _I32)
        if old is not None:
            m = old.shape[0]
            ns[:m] = old
            ni[:m] = self.node_internal
            sc[:m] = self.slot_coord
            sf[:m] = self.slot_free
            sh[:m] = self.slot_head
        self.node_sample, self.node_internal, self.slot_coord, self.slot_free = ns, ni, sc, sf
        self.slot_head = sh

    def _alloc_samples(self, n):
        d = self.dim
        old = getattr(self, "pos", None)
        arrs = dict(pos=np.zeros((n, d)), nrm=np.zeros((n, d)), sp=np.zeros(n), sg=np.zeros(n),
                    pos_t=np.zeros((n, d)), nrm_t=np.zeros((n, d)), sp_t=np.zeros(n),
                    sg_t=np.zeros(n), run=np.zeros((n, 2)),
                    s_slot=np.full(n, -1, _I32), s_node=np.full(n, -1, _I32),
                    s_free=np.zeros(n, _I32), link=np.full((n, 2), -1, _I32))
        if old is not None:
            m = old.shape[0]
            for k, a in arrs.items():
                a[:m] = getattr(self, k)
        for k, a in arrs.items():
            setattr(self, k, a)

    def reserve(self, points):
        """Make room for inserting ``points`` (n, d): sample and slot capacity, grid coverage."""
        n = len(points)
        need = int(self.counts[0]) + n
        if need > self.pos.shape[0]:
            self._alloc_samples(max(need, 2 * self.pos.shape[0]))
        need = int(self.counts[2]) + n
        if need > self.node_sample.shape[0]:
            self._alloc_slots(max(need, 2 * self.node_sample.shape[0]))
        if n == 0:
            return
        d = self.dim
        w = self.geo[d]
        lim = 4.0 * self.geo[d + 2]
        lo_b = self.root[:d] - lim
        hi_b = self.root[:d] + lim
        p = np.clip(points, lo_b, hi_b)
        lo = np.floor((p.min(0) - self.geo[:d]) / w).astype(np.int64) - 2
        hi = np.floor((p.max(0) - self.geo[:d]) / w).astype(np.int64) + 3
        self._cover(lo, hi)

    def _cover(self, lo, hi):
        """Grow the dense cluster grid to cover integer cluster coordinates [lo, hi)."""
        glo, ghi = self.goff, self.goff + self.gshape
        if self.cgrid.size > 1 and (lo >= glo).all() and (hi <= ghi).all():
            return
        if self.cgrid.size > 1:
            span = ghi - glo
            nlo = np.minimum(lo, np.where(lo < glo, glo - span // 2, glo))
            nhi = np.maximum(hi, np.where(hi > ghi, ghi + span // 2, ghi))
        else:
            nlo, nhi = lo, hi
        shape = nhi - nlo
        grid = np.full(tuple(shape[::-1]), -1, _I32)  # index order: last axis slowest
        if self.cgrid.size > 1:
            old = self.cgrid.reshape(tuple(self.gshape[::-1]))
            sl = tuple(slice(int(a), int(a + s)) for a, s in zip((glo - nlo)[::-1], self.gshape[::-1]))
            grid[sl] = old
        self.cgrid = np.ascontiguousarray(grid).ravel()
        self.gshape = shape.astype(np.int64)
        self.goff = nlo.astype(np.int64)

    # -- operations --------------------------------------------------------------------------
    def insert(self, p, n=None, g=1.0):
        """Insert one point (d,) with normal n (d,) and gradient noise g; returns (sample index,
        slot) or (-1, -1)."""
        n = np.zeros(self.dim) if n is None else np.asarray(n, np.float64)
        return K._insert(p, self.geo, self.root, self.level_off, self.L, self.cgrid, self.gshape,
                       self.goff, self.node_sample, self.node_internal, self.slot_coord,
                       self.slot_free, self.pos, self.s_slot, self.s_node, self.s_free,
                       self.counts, self.strict, self.link, self.slot_head, n, self.nrm, float(g),
                       self.sg)

    def remove(self, i):
        K._remove(i, self.dim, self.level_off, self.cgrid, self.gshape, self.goff, self.node_sample,
                self.node_internal, self.slot_coord, self.slot_free, self.s_slot, self.s_node,
                self.s_free, self.counts, self.link, self.slot_head)

    def args(self):
        """The arrays the numba kernels take, in their order."""
        return (self.geo, self.root, self.level_off, self.L, self.cgrid, self.gshape, self.goff,
                self.node_sample, self.node_internal, self.slot_coord, self.slot_free, self.pos,
                self.s_slot, self.s_node, self.s_free, self.counts, self.strict, self.link,
                self.slot_head)

    def alive(self):
        """Indices of the stored samples, in slot/node order (deterministic)."""
        ns = self.node_sample[: self.counts[2]]
        return ns[ns >= 0].astype(np.int64)

    def cluster_slots(self):
        """Slots of the non-empty clusters, in slot order."""
        ns = self.node_sample[: self.counts[2]]
        ni = self.node_internal[: self.counts[2]]
        used = (ns[:, 0] >= 0) | (ni[:, 0] > 0)
        return np.nonzero(used)[0]

    def slot_centres(self, slots):
        d = self.dim
        w = self.geo[d]
        return self.geo[:d] + (self.slot_coord[slots] + 0.5) * w

    # -- persistence ---------------------------------------------------------------------------
    STATE = ("geo", "root", "cgrid", "gshape", "goff", "counts", "node_sample", "node_internal",
             "slot_coord", "slot_free", "pos", "nrm", "sp", "sg", "s_slot", "s_node", "s_free",
             "pos_t", "nrm_t", "sp_t", "sg_t", "run")

    def state(self):
        return {k: getattr(self, k) for k in self.STATE}

    def set_state(self, st):
        if "run" not in st:     # files before format version 3: no runs recorded, every face runs on
            st = {**st, "run": np.full((len(st["pos"]), 2), np.inf)}
        for k in self.STATE:
            setattr(self, k, np.ascontiguousarray(st[k]).astype(getattr(self, k).dtype, copy=True))
        if self.geo.shape[0] == self.dim + 4:       # files written before face_cos existed
            self.geo = np.append(self.geo, self.face_cos)
        # the tree depth is the file's (2D default maps written before face_cos: one level less)
        B = 1 << self.dim
        L = 0
        while (B ** (L + 1) - 1) // (B - 1) < self.node_sample.shape[1]:
            L += 1
        self.L = L
        self.level_off = np.array([(B**lv - 1) // (B - 1) for lv in range(L + 2)], np.int64)
        self.n_nodes = int(self.level_off[L + 1])
        self.link = np.full((self.pos.shape[0], 2), -1, _I32)
        self.slot_head = np.full(self.node_sample.shape[0], -1, _I32)
        K.rebuild_links(self.node_sample, int(self.counts[2]), self.link, self.slot_head)
