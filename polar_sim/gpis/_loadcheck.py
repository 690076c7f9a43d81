"""Validation of a loaded GPIS map file: a map file is untrusted input.

:func:`check_arrays` runs before any array reaches a numba kernel. It checks the exact set of
keys, every array's dtype and shape, finiteness of every float array, every index against the
array it indexes (tree nodes, samples, cluster slots, GP observation and factor offsets, the
packed observation kinds), the tree's structure (no split below the maximum depth, no sample in an
internal node, every non-empty node's parent split), the free lists, and that both cell grids
match their declared shapes. Any defect raises ``ValueError`` naming the file and the array. The
kernels index without bounds checks, so a single out-of-range index would otherwise read or write
outside an array.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from polar_sim.gpis.config import MAX_CLUSTER_NODES

__all__ = ["MapFileError", "check_meta", "check_arrays", "META_KEYS", "state_keys"]

META_KEYS = ("format", "version", "cls", "params", "fitted")
_TREE_F = ("pos", "nrm", "pos_t", "nrm_t")
_TREE_V = ("sp", "sg", "sp_t", "sg_t")
_BIG = 1 << 40          # bound of any integer grid coordinate or offset (cells, m / cell width)
_MAX_LEVELS = 16        # deepest cluster subtree a file may declare (nodes also bounded below)


class MapFileError(ValueError):
    """A map file failed validation (a ``ValueError``)."""


def state_keys(dim, version=None):
    """The array names of a fitted map file (of format ``version``; default the current one:
    version 3 added ``tree/run``)."""
    tree = ("geo", "root", "cgrid", "gshape", "goff", "counts", "node_sample", "node_internal",
            "slot_coord", "slot_free", "pos", "nrm", "sp", "sg", "s_slot", "s_node", "s_free",
            "pos_t", "nrm_t", "sp_t", "sg_t") + (("run",) if version is None or version >= 3 else ())
    return (tuple("tree/" + k for k in tree)
            + tuple("gp/" + k for k in ("gp_obs", "gp_tri", "gp_m", "X", "kinds", "alpha", "Lbuf"))
            + ("free/grid", "free/gshape", "free/goff", "slot_gen", "gp_gen", "active", "n_updates"))


class _Ctx:
    def __init__(self, path, data):
        self.path, self.data = path, data

    def fail(self, key, why):
        raise MapFileError(f"path: {self.path}: corrupt or inconsistent GPIS map file: "
                           f"array {key!r} {why}")

    def get(self, key, dtype, ndim=None, shape=None):
        a = self.data[key]
        if a.dtype != np.dtype(dtype):
            self.fail(key, f"has dtype {a.dtype.str}, expected {np.dtype(dtype).str}")
        if ndim is not None and a.ndim != ndim:
            self.fail(key, f"has shape {a.shape}, expected {ndim} dimension(s)")
        if shape is not None:
            for k, (got, want) in enumerate(zip(a.shape, shape)):
                if want is not None and got != want:
                    self.fail(key, f"has shape {a.shape}, expected {_fmt(shape)} (axis {k})")
        return a

    def finite(self, key, a):
        if not np.isfinite(a).all():
            self.fail(key, "contains NaN or inf")

    def within(self, key, a, lo, hi, what=""):
        """lo <= a < hi (Python ints: no overflow)."""
        if a.size and (int(a.min()) < lo or int(a.max()) >= hi):
            self.fail(key, f"has values in [{int(a.min())}, {int(a.max())}], expected "
                           f"[{lo}, {hi}){what}")


def _fmt(shape):
    return "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"


def check_meta(path, data):
    """Header checks: format, integer version, class name, params JSON text, fitted flag.

    Returns ``(version, cls_name, params_text, fitted)``. Raises ``MapFileError``.
    """
    c = _Ctx(path, data)
    for k in META_KEYS:
        if k not in data:
            c.fail(k, "is missing")
        if data[k].ndim != 0:
            c.fail(k, f"has shape {data[k].shape}, expected a scalar")
    for k in ("format", "cls", "params"):
        if data[k].dtype.kind != "U":
            c.fail(k, f"has dtype {data[k].dtype.str}, expected a string")
    v = data["version"]
    if v.dtype.kind not in "iu" or not v.dtype.isnative:   # no bool, float, string, object
        c.fail("version", f"has dtype {v.dtype.str} ({v!r}), expected an integer scalar")
    if data["fitted"].dtype != np.bool_:
        c.fail("fitted", f"has dtype {data['fitted'].dtype.str}, expected bool")
    return int(v), str(data["cls"]), str(data["params"]), bool(data["fitted"])


def check_keys(path, data, fitted, dim, version=None):
    c = _Ctx(path, data)
    want = set(META_KEYS) | (set(state_keys(dim, version)) if fitted else set())
    for k in sorted(want - set(data)):
        c.fail(k, "is missing")
    for k in sorted(set(data) - want):
        c.fail(k, "is not part of the format" + ("" if fitted else " (the map is not fitted)"))


def check_arrays(path, data, m):
    """Validate every state array of a fitted map file against the freshly built map ``m``
    (its tree holds the geometry that the file's parameters imply). Raises ``MapFileError``."""
    c = _Ctx(path, data)
    d = m.dim
    geo, gshape, goff, cgrid, counts = _tree_geometry(c, d, m.tree_)
    tr = _tree_nodes(c, d, counts)
    srow, live = _tree_samples(c, tr)
    _tree_slots(c, tr, gshape, goff, cgrid)
    _samples_in_cells(c, d, geo, tr, srow, live)
    G = _cluster_gps(c, d, tr.S)
    _free_space_and_counters(c, data, d, tr.S, G)


def _tree_geometry(c, d, fresh):
    """The tree's geometry against the fresh map's, and the cluster grid's shape and offset."""
    geo = c.get("tree/geo", np.float64, 1)
    if geo.shape[0] != d + 5:
        c.fail("tree/geo", f"has shape {geo.shape}, expected ({d + 5},)")
    if not np.array_equal(geo, fresh.geo):
        c.fail("tree/geo", "does not match the map's parameters")
    root = c.get("tree/root", np.float64, 1, (d + 2,))
    c.finite("tree/root", root)
    hmax = float(fresh.geo[d + 2])
    if not (root[d] >= fresh.root[d] and root[d] <= 4.0 * hmax + fresh.root[d]
            and root[d + 1] in (0.0, 1.0) and np.abs(root[:d]).max() <= 4.0 * hmax + root[d]):
        c.fail("tree/root", f"is not a root box of this map ({root.tolist()})")
    gshape = c.get("tree/gshape", np.int64, 1, (d,))
    goff = c.get("tree/goff", np.int64, 1, (d,))
    c.within("tree/gshape", gshape, 1, _BIG)
    c.within("tree/goff", goff, -_BIG, _BIG)
    cgrid = c.get("tree/cgrid", np.int32, 1)
    ncell = int(np.prod([int(x) for x in gshape], dtype=object))
    if cgrid.shape[0] != ncell:
        c.fail("tree/cgrid", f"has {cgrid.shape[0]} cells, expected {ncell} (tree/gshape)")
    counts = c.get("tree/counts", np.int64, 1, (4,))
    return geo, gshape, goff, cgrid, counts


def _tree_nodes(c, d, counts):
    """Node, slot and sample arrays: shapes, dtypes, finiteness, counts, and each cluster a
    complete 2**d-ary tree whose non-empty nodes hang under split parents."""
    B = 1 << d
    ns = c.get("tree/node_sample", np.int32, 2)
    S, NN = ns.shape
    L = next((lv for lv in range(_MAX_LEVELS + 1) if (B ** (lv + 1) - 1) // (B - 1) == NN), None)
    if L is None or NN > MAX_CLUSTER_NODES:
        c.fail("tree/node_sample", f"has {NN} nodes per cluster, not a complete {B}-ary tree of "
                                   f"at most {MAX_CLUSTER_NODES} nodes")
    ni = c.get("tree/node_internal", np.uint8, 2, (S, NN))
    sc = c.get("tree/slot_coord", np.int64, 2, (S, d))
    sfree = c.get("tree/slot_free", np.int32, 1, (S,))
    pos = c.get("tree/pos", np.float64, 2, (None, d))
    N = pos.shape[0]
    for k in _TREE_F:
        c.finite("tree/" + k, c.get("tree/" + k, np.float64, 2, (N, d)))
    for k in _TREE_V:
        a = c.get("tree/" + k, np.float64, 1, (N,))
        c.finite("tree/" + k, a)
        if a.size and a.min() < 0:
            c.fail("tree/" + k, "has negative variances")
    if "tree/run" in c.data:        # m along each sample's face, +inf: ran on (files before version 3)
        run = c.get("tree/run", np.float64, 2, (N, 2))
        if np.isnan(run).any() or (run < 0).any():
            c.fail("tree/run", "has NaN or negative runs")
    s_slot = c.get("tree/s_slot", np.int32, 1, (N,))
    s_node = c.get("tree/s_node", np.int32, 1, (N,))
    s_free = c.get("tree/s_free", np.int32, 1, (N,))
    n_hw, n_free, k_hw, k_free = (int(x) for x in counts)
    if not (0 <= n_hw <= N and 0 <= n_free <= n_hw and 0 <= k_hw <= S and 0 <= k_free <= k_hw):
        c.fail("tree/counts", f"{counts.tolist()} do not fit {N} samples and {S} slots")
    c.within("tree/node_internal", ni, 0, 2)
    c.within("tree/node_sample", ns, -1, n_hw, " (sample indices)")
    if (ns[k_hw:] != -1).any() or (ni[k_hw:] != 0).any():
        c.fail("tree/node_sample", "has nodes in slots past the slot count")
    level_off = np.array([(B ** lv - 1) // (B - 1) for lv in range(L + 2)], np.int64)
    used_ns, used_ni = ns[:k_hw], ni[:k_hw].astype(bool)
    if used_ni[:, level_off[L]:].any():
        c.fail("tree/node_internal", "splits a node at the maximum depth")
    has = used_ns >= 0
    if (has & used_ni).any():
        c.fail("tree/node_sample", "puts a sample in an internal node")
    if L > 0:
        # parent of every node at levels 1..L (the same formula as the kernels' _parent)
        par = np.empty(NN - 1, np.int64)
        for lv in range(1, L + 1):
            n = 1 << lv
            r = np.arange(level_off[lv + 1] - level_off[lv])
            idx = np.zeros_like(r)
            stride = 1
            for _ in range(d):
                idx += ((r % n) >> 1) * stride
                r //= n
                stride *= n >> 1
            par[level_off[lv] - 1: level_off[lv + 1] - 1] = level_off[lv - 1] + idx
        nonempty = has[:, 1:] | used_ni[:, 1:]
        if (nonempty & ~used_ni[:, par]).any():
            c.fail("tree/node_internal", "has a non-empty node whose parent is not split")
    return SimpleNamespace(ns=ns, ni=ni, sc=sc, sfree=sfree, pos=pos, N=N, S=S, s_slot=s_slot, s_node=s_node,
                           s_free=s_free, n_hw=n_hw, n_free=n_free, k_hw=k_hw, k_free=k_free, has=has,
                           used_ns=used_ns)


def _tree_samples(c, tr):
    """Each sample stored once, ``s_slot``/``s_node`` pointing back at it, and the free list the
    unused samples. Returns the stored samples' slots and indices."""
    N, s_slot, s_node, s_free, n_hw, n_free = tr.N, tr.s_slot, tr.s_node, tr.s_free, tr.n_hw, tr.n_free
    has, used_ns = tr.has, tr.used_ns
    # samples: each stored once, and s_slot / s_node point back at it
    srow, snode = np.nonzero(has)
    live = used_ns[srow, snode].astype(np.int64)
    if len(np.unique(live)) != len(live):
        c.fail("tree/node_sample", "stores a sample twice")
    if (s_slot[live] != srow).any() or (s_node[live] != snode).any():
        c.fail("tree/s_slot", "does not match tree/node_sample")
    dead = np.ones(N, bool)
    dead[live] = False
    if (s_slot[dead] != -1).any() or (s_node[dead] != -1).any():
        c.fail("tree/s_node", "holds a node for a sample that is not stored")
    fs = s_free[:n_free].astype(np.int64)
    c.within("tree/s_free", fs, 0, n_hw, " (free sample indices)")
    if len(np.unique(fs)) != n_free or not dead[fs].all() or len(live) + n_free != n_hw:
        c.fail("tree/s_free", "is not the list of the unused samples")
    return srow, live


def _tree_slots(c, tr, gshape, goff, cgrid):
    """The grid's slots and the free slots partition [0, k_hw), and each cluster sits in its cell."""
    ns, ni, sc, sfree, k_hw, k_free = tr.ns, tr.ni, tr.sc, tr.sfree, tr.k_hw, tr.k_free
    c.within("tree/cgrid", cgrid, -1, k_hw, " (cluster slots)")
    gcell = np.flatnonzero(cgrid >= 0)
    gslot = cgrid[gcell].astype(np.int64)
    fsl = sfree[:k_free].astype(np.int64)
    c.within("tree/slot_free", fsl, 0, k_hw, " (free slots)")
    both = np.concatenate([gslot, fsl])
    if len(both) != k_hw or len(np.unique(both)) != k_hw:
        c.fail("tree/cgrid", "and tree/slot_free do not partition the slots")
    if (ns[fsl] != -1).any() or (ni[fsl] != 0).any():
        c.fail("tree/slot_free", "lists a slot that holds nodes")
    if len(gslot) and not ((ns[gslot, 0] >= 0) | (ni[gslot, 0] > 0)).all():
        c.fail("tree/cgrid", "points at an empty cluster")
    rel = sc[gslot] - goff
    if len(gslot) and ((rel < 0) | (rel >= gshape)).any():
        c.fail("tree/slot_coord", "places a cluster outside the cluster grid")
    strides = np.cumprod(np.concatenate([[1], gshape[:-1]]))
    if len(gslot) and ((rel * strides).sum(1) != gcell).any():
        c.fail("tree/slot_coord", "does not match tree/cgrid")


def _samples_in_cells(c, d, geo, tr, srow, live):
    """Every stored sample lies in its cluster's cell."""
    sc, pos = tr.sc, tr.pos
    w = float(geo[d])
    lo = geo[:d] + sc[srow] * w
    tol = 1e-6 * w
    p = pos[live]
    if len(live) and ((p < lo - tol) | (p > lo + w + tol)).any():
        c.fail("tree/pos", "puts a sample outside its cluster cell")


def _cluster_gps(c, d, S):
    """The cluster GPs: offsets within their buffers, kinds in order, finite values and every
    Cholesky factor with a positive diagonal. Returns the number of GP slots."""
    gp_m = c.get("gp/gp_m", np.int64, 1)
    G = gp_m.shape[0]
    if G < S:
        c.fail("gp/gp_m", f"has {G} slots, fewer than the tree's {S}")
    gp_obs = c.get("gp/gp_obs", np.int64, 1, (G,))
    gp_tri = c.get("gp/gp_tri", np.int64, 1, (G,))
    X = c.get("gp/X", np.float64, 2, (None, d))
    O = X.shape[0]
    kinds = c.get("gp/kinds", np.int64, 1, (O,))
    alpha = c.get("gp/alpha", np.float64, 1, (O,))
    Lbuf = c.get("gp/Lbuf", np.float64, 1)
    T = Lbuf.shape[0]
    for k, a in (("gp/X", X), ("gp/alpha", alpha), ("gp/Lbuf", Lbuf)):
        c.finite(k, a)
    c.within("gp/gp_m", gp_m, 0, O + 1, " (observations per GP)")
    c.within("gp/gp_obs", gp_obs, 0, O + 1)
    c.within("gp/gp_tri", gp_tri, 0, T + 1)
    lv = np.flatnonzero(gp_m > 0)
    m_ = gp_m[lv]
    if int(m_.sum()) > O:
        c.fail("gp/gp_m", "claims more observations than gp/X holds")
    if len(lv) and ((gp_obs[lv] + m_).max() > O):
        c.fail("gp/gp_obs", "points past the end of gp/X")
    if len(lv) and ((gp_tri[lv] + m_ * (m_ + 1) // 2).max() > T):
        c.fail("gp/gp_tri", "points past the end of gp/Lbuf")
    if len(lv):
        gid = np.repeat(np.arange(len(lv)), m_)
        start = np.concatenate([[0], np.cumsum(m_)[:-1]])
        local = np.arange(len(gid)) - start[gid]
        kk = kinds[gp_obs[lv][gid] + local]
        high, low = kk >> 32, kk & 0xFFFFFFFF
        isval = high == 0
        nv = np.bincount(gid, weights=isval, minlength=len(lv)).astype(np.int64)
        if (isval != (local < nv[gid])).any():
            c.fail("gp/kinds", "does not list the value observations first")
        gr = ~isval
        if ((high[gr] < 1) | (high[gr] > d) | (low[gr] >= nv[gid[gr]])).any():
            c.fail("gp/kinds", "has a gradient observation of no valid component or sample")
        diag = gp_tri[lv][gid] + local * (local + 3) // 2
        if not (Lbuf[diag] > 0).all():
            c.fail("gp/Lbuf", "has a Cholesky factor without a positive diagonal")
    return G


def _free_space_and_counters(c, data, d, S, G):
    """The free-space grid, the generation counters, the active clusters and the update count."""
    fg = c.get("free/grid", np.uint8, 1)
    fsh = c.get("free/gshape", np.int64, 1, (d,))
    fof = c.get("free/goff", np.int64, 1, (d,))
    c.within("free/gshape", fsh, 0, _BIG)
    c.within("free/goff", fof, -_BIG, _BIG)
    c.within("free/grid", fg, 0, 2)
    nf = int(np.prod([int(x) for x in fsh], dtype=object))
    if fg.shape[0] != nf:
        c.fail("free/grid", f"has {fg.shape[0]} cells, expected {nf} (free/gshape)")
    sg_ = c.get("slot_gen", np.int64, 1)
    gg_ = c.get("gp_gen", np.int64, 1)
    if sg_.shape[0] < S:
        c.fail("slot_gen", f"has {sg_.shape[0]} entries, fewer than the {S} slots")
    if gg_.shape[0] < G:
        c.fail("gp_gen", f"has {gg_.shape[0]} entries, fewer than the {G} GP slots")
    c.within("slot_gen", sg_, 0, 1 << 62)
    c.within("gp_gen", gg_, 0, 1 << 62)
    act = c.get("active", np.int64, 2, (None, d))
    c.within("active", act, -_BIG, _BIG)
    nu = data["n_updates"]
    if nu.ndim != 0 or nu.dtype.kind not in "iu" or not nu.dtype.isnative or int(nu) < 0:
        c.fail("n_updates", f"is {nu!r}, expected a non-negative integer scalar")
