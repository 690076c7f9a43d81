"""The shared GPIS mapping pipeline (spec §0): re-evaluate, add, retrain, query.

Subclasses (:class:`GPISMap2D`, :class:`GPISMap3D`) provide the sensor model: how a scan becomes
an observation GP, sensor-frame points and the occupancy test ``oc`` (spec §3), and the
dimension-specific constants. Everything else (fusion, tree updates, training, query, I/O) is here.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import math

import numpy as np

from polar_sim._validation import as_points, as_positive_float, check_updated
from polar_sim.gpis.config import SWITCHES
from polar_sim.params import Parameterised, check_fields, replace_fields, split_nested
from polar_sim.gpis import _io
from polar_sim.gpis import _icp, _kernels  # noqa: F401  (their kernels, called through K)
from polar_sim.gpis._distance import FreeSpace, far_field, far_weights
from polar_sim.gpis._native import K
from polar_sim.gpis._query import PARALLEL_POINTS, query_gp
from polar_sim.gpis._localgp import NOGRAD_VALUE_NOISE, GPStore, _var_consts
from polar_sim.gpis._tree import Tree

logger = logging.getLogger(__name__)

__all__ = ["GPISMapBase", "FAR_COORD", "MAX_CLUSTER_CELLS", "MAX_FREE_CELLS", "MAX_QUERY_POINTS"]

#: Query points with a coordinate beyond this (metres) get the prior (see ``query``).
FAR_COORD = 1e100
#: Cells of the dense cluster grid (int32) and of the free-space grid (uint8) a map may grow to
#: (both cover only the data, clipped to the map's reach): ``update`` refuses a scan beyond them.
MAX_CLUSTER_CELLS = 1 << 27
MAX_FREE_CELLS = 1 << 29
#: Points per ``query`` call: the answers take 8 * (dim + 2) bytes a point (2.7 GB at the limit in
#: 3D) and the kernels as much again; query larger sets in parts.
MAX_QUERY_POINTS = 1 << 26

_STATE = ("tree_", "gps_", "n_updates_")


def _grown(lo, hi, goff, gshape, frac, keep_inside):
    """The extent [lo, hi) (lists of floats, one per axis) a grid at [goff, goff + gshape) grows
    to for data over [lo, hi): unchanged when the data lies inside (``keep_inside``: the grid's
    own extent then), else padded by 1/frac of its span on each side that grows
    (``FreeSpace._cover``, ``Tree._cover``)."""
    glo = [float(g) for g in goff]
    ghi = [g + float(n) for g, n in zip(glo, gshape)]
    if keep_inside and all(a >= g for a, g in zip(lo, glo)) and all(b <= g for b, g in zip(hi, ghi)):
        return glo, ghi
    pad = [_floor((b - a) / frac) for a, b in zip(glo, ghi)]
    if keep_inside:
        return ([min(a, g - (p if a < g else 0.0)) for a, g, p in zip(lo, glo, pad)],
                [max(b, g + (p if b > g else 0.0)) for b, g, p in zip(hi, ghi, pad)])
    return ([min(a, g - p if a < g else g) for a, g, p in zip(lo, glo, pad)],
            [max(b, g + p if b > g else g) for b, g, p in zip(hi, ghi, pad)])


def _floor(x):
    return float(math.floor(x))


def _clip(x, a, b):
    return min(max(x, a), b)


def _refuse_over(n, limit, name, what, const, advice):
    if n > limit:
        raise ValueError(f"{name}: this scan would grow the {what.format(n=n)}, over the limit "
                         f"of {limit} cells ({const}); {advice}")


class GPISMapBase(Parameterised):
    """Common machinery; see :class:`GPISMap2D` / :class:`GPISMap3D` for the parameters.

    The module contract is :class:`polar_sim.params.Parameterised`'s: ``get_params()``,
    ``set_params()`` (checked, the map unchanged on a bad value), ``reset()``, and the published
    behaviour as a named preset, ``published(**overrides)``: every stage config's ``published()``
    (:mod:`polar_sim.gpis.config`).
    """

    #: Stage name -> config class (each map's dimension's variant), in constructor order.
    _STAGES: dict = {}

    dim = 0
    _T_BLEND = 0.4          # query blending threshold (spec §9.1)
    _OC_SKIP = -0.1         # re-eval occlusion threshold (spec §6.2)
    _TRAIN_R = 4.0          # training radius in units of h_c (spec §8.1)
    _UPDATE_R = 4.0         # legacy retraining box half-width in units of h_c
    _QUERY_W = None         # query search half-width; None = 4 * map_scale
    _SURF_RES, _SURF_BAND, _SURF_VAR = 0.05, 0.3, 0.4
    _VAR_BLEND = False      # default mode: weight the GPIS by its information (blend_gp)
    _NOGRAD_NOISE = NOGRAD_VALUE_NOISE   # default mode: value noise of samples without a
                            # gradient observation (<= 0: their position noise plus -this)
    _VALUE_FLOOR = 0.0      # default mode: added to every GP value noise (m^2)
    _SIGN_GATE = np.inf     # default mode: surfels with gradient noise above this do not set the
                            # far-field sign where observed free space says otherwise
    _FACE_COS = None        # default mode: samples whose normals' dot is below this are on
                            # different faces and not subject to the sample spacing (None: off)
    _BEHIND = 0.5           # default mode: the blend band behind surfaces, as a fraction
    _IMLS_WIDTH = 0.0       # default mode: width of the far field's implicit-MLS sign, in units
                            # of the sample spacing (0: the side of the closest surfel)

    # -- lifecycle -----------------------------------------------------------------------------
    def __setattr__(self, name, value):
        # a parameter (re)bound, by set_params or directly: its checked values are stale (the
        # stage configs are frozen, so rebinding is the only way they change)
        if not (name.startswith("_") or name.endswith("_")):
            self.__dict__.pop("_params", None)
        object.__setattr__(self, name, value)

    def _pub(self, name):
        """True when behaviour switch ``name`` (a field of one stage config) is the published one."""
        return self._checked_params()["pub"][name]

    @classmethod
    def published(cls, **overrides):
        """A map with the published C++'s behaviour (GPisMap v2, quirks and bugs included, spec
        [quirk]/[bug]): every stage config's ``published()``. ``overrides`` are parameters
        (``sensor_offset=(0.08, 0)``, a whole stage config, used as given) or stage fields
        (``local_gp__map_scale=1.0``, on top of the stage's published config). The laser offset
        is not part of the preset: pass ``sensor_offset=(0.08, 0)`` with the demo's base poses."""
        flat, nested = split_nested(overrides)
        names = cls._param_names()
        unknown = sorted(set(flat) - set(names)) + sorted(f"{s}__{f}" for s, fs in nested.items()
                                                          if s not in cls._STAGES for f in fs)
        if unknown:
            raise ValueError(f"{unknown[0]}: unknown parameter of {cls.__name__}; valid: {', '.join(names)}")
        for stage, config in cls._STAGES.items():
            fields = nested.get(stage, {})
            if stage in flat:
                flat[stage] = replace_fields(flat[stage], stage, fields) if fields else flat[stage]
            else:
                check_fields(config, stage, fields)
                try:
                    flat[stage] = config.published(**fields)
                except (TypeError, ValueError) as exc:
                    raise type(exc)(f"{stage}__{exc}") from None
        return cls(**flat)

    def _check_params(self):
        return self._checked_params()

    def _checked_params(self):
        """The checked parameters as one dict of clean values, the stage fields flattened
        (``{"min_range": 0.2, ..., "map_scale": 1.2, ...}``), and under ``"pub"`` whether each
        behaviour switch is the published one; raises ``ValueError``/``TypeError`` naming a bad
        parameter. The stage configs checked their own fields when they were made.

        Checked once per binding of the parameters (construction, ``set_params``, an assignment)
        and kept, so that updates do not check them again; the dict is shared: read it only.
        Array parameters are kept as checked copies: an array changed in place after it was given
        takes effect at the next ``set_params``."""
        p = self.__dict__.get("_params")
        if p is None:
            p = self._params = self._check_all()
        return p

    def _check_all(self):
        for stage, config in self._STAGES.items():
            cfg = getattr(self, stage)
            if type(cfg) is not config:
                raise TypeError(f"{stage}: expected a {config.__name__}, got {type(cfg).__name__}")
        p = self._check_sensor()
        for stage in self._STAGES:
            cfg = getattr(self, stage)
            for f in dataclasses.fields(cfg):
                v = getattr(cfg, f.name)
                p[f.name] = v if v is None or isinstance(v, str) else (
                    int(v) if f.name == "train_cap" else float(v))
        p["pub"] = {name: p[name] == SWITCHES[name][1] for name in SWITCHES if name in p}
        return p

    def set_params(self, **params):
        """Change parameters (checked; the map unchanged on a bad value).

        On a fitted map, a change that would give the map another tree or free-space geometry
        (``init_half``, ``cluster_half``, ``min_half``, ``max_half``, the sample spacing, the
        free-space resolution, ...) is refused with ``ValueError``: the learned state was built
        on the old geometry, and neither queries nor a saved file could use it. Call
        :meth:`reset` first.
        """
        if hasattr(self, "tree_"):
            trial = copy.copy(self)
            Parameterised.set_params(trial, **params)
            trial._init_state()            # rebinds the copy's state only; self's stays
            same = (np.array_equal(trial.tree_.geo, self.tree_.geo)
                    and (trial.free_.res, trial.free_.reach) == (self.free_.res, self.free_.reach))
            if not same:
                raise ValueError(f"{sorted(params)[0]}: changes the geometry of a fitted map "
                                 f"(params {sorted(params)}); call reset() first")
        return Parameterised.set_params(self, **params)

    def reset(self):
        """Forget everything learned; parameters stay."""
        for k in list(vars(self)):
            if k.endswith("_"):
                delattr(self, k)
        return self

    def _reach(self, p):
        """Half-width (m) of the box around the origin that the tree's root can ever cover."""
        return 4.0 * p["max_half"] + p["init_half"]

    def _singletons(self, scan):
        """Whether re-evaluation takes the sample of a cluster that holds only one (spec §6.1's
        [quirk] leaves it as it was born, forever). Off here; 2D ``noise.reevaluation="on_returns"``
        turns it on."""
        return False

    def _precheck(self, scan):
        """Refuse (``ValueError`` naming the pose argument) a scan that would grow the dense
        cluster grid or the free-space grid past their limits, before any state changes.

        Both grids cover only what the data needs, clipped to the map's reach (the tree cannot
        hold samples beyond it), so this triggers only for fine grids over large extents. (The
        clipped extremes are the extremes clipped: the arithmetic runs on the bounding boxes.)"""
        p = self._checked_params()
        name = getattr(scan, "pose_name", "pose")
        have = hasattr(self, "tree_")
        hits = getattr(scan, "free_hits", scan.hits)
        o = [float(x) for x in scan.origin_sensor]
        lo_h, hi_h = (hits.min(0).tolist(), hits.max(0).tolist()) if len(hits) else (o, o)
        res = self._free_res()
        lim = _floor(self._reach(p) / res) + 2.0
        lo = [_clip(_floor(min(a, b) / res) - 1, -lim, lim) for a, b in zip(lo_h, o)]
        hi = [_clip(_floor(max(a, b) / res) + 2, -lim, lim) for a, b in zip(hi_h, o)]
        if all(b > a for a, b in zip(lo, hi)):
            if have and self.free_.grid.size:
                lo, hi = _grown(lo, hi, self.free_.goff, self.free_.gshape, 4, keep_inside=True)
            _refuse_over(math.prod(b - a for a, b in zip(lo, hi)), MAX_FREE_CELLS, name,
                         f"free-space grid to {{n:.3g}} cells of {res:g} m", "MAX_FREE_CELLS",
                         "raise free_res")
        if len(scan.hits):
            w = 2.0 * p["cluster_half"]
            org = -p["init_half"]
            rc = self.tree_.root[:self.dim].tolist() if have else [0.0] * self.dim
            limb = 4.0 * p["max_half"]
            if scan.hits is not hits:
                lo_h, hi_h = scan.hits.min(0).tolist(), scan.hits.max(0).tolist()
            lo = [_floor((_clip(a, c - limb, c + limb) - org) / w) - 2 for a, c in zip(lo_h, rc)]
            hi = [_floor((_clip(b, c - limb, c + limb) - org) / w) + 3 for b, c in zip(hi_h, rc)]
            if have and self.tree_.cgrid.size > 1:
                lo, hi = _grown(lo, hi, self.tree_.goff, self.tree_.gshape, 2, keep_inside=False)
            _refuse_over(math.prod(b - a for a, b in zip(lo, hi)), MAX_CLUSTER_CELLS, name,
                         f"cluster grid to {{n:.3g}} cells of {w:g} m", "MAX_CLUSTER_CELLS",
                         "raise cluster_half or lower max_half")

    def _init_state(self):
        p = self._checked_params()
        chain = self._pub("spacing_rule")
        faces = None if chain else self._FACE_COS
        self.tree_ = Tree(self.dim, p["init_half"], p["cluster_half"], p["min_half"],
                          p["max_half"], spacing=None if chain else self._spacing(),
                          face_cos=faces,
                          # leaves small enough for both faces of a wall thinner than min_half
                          leaf_half=None if faces is None else 0.5 * p["min_half"])
        self.slot_gen_ = np.zeros(self.tree_.node_sample.shape[0], np.int64)
        self.gps_ = GPStore(self.dim)
        self.gp_gen_ = np.zeros(0, np.int64)
        self.active_ = np.zeros((0, self.dim), np.int64)
        self.free_ = FreeSpace(self.dim, self._free_res(), reach=self._reach(p))
        self.n_updates_ = 0
        self.version_ = 0
        self._index_samples()

    # -- helpers --------------------------------------------------------------------------------
    def _hc(self):
        return self.tree_.geo[self.dim] / 2.0

    def _sync_slot_arrays(self):
        n = self.tree_.node_sample.shape[0]
        if self.slot_gen_.shape[0] < n:
            g = np.zeros(n, np.int64)
            g[: self.slot_gen_.shape[0]] = self.slot_gen_
            self.slot_gen_ = g
        self.gps_.ensure_slots(n)
        if self.gp_gen_.shape[0] < self.gps_.gp_m.shape[0]:
            g = np.zeros(self.gps_.gp_m.shape[0], np.int64)
            g[: self.gp_gen_.shape[0]] = self.gp_gen_
            self.gp_gen_ = g

    def _tree_args(self):
        t = self.tree_
        return t.args() + (t.nrm, t.sp, t.sg, self.slot_gen_)

    # -- the update pipeline --------------------------------------------------------------------
    def _run_update(self, scan):
        """Stages 2-4 given a prepared scan (subclass ``_prepare`` output)."""
        self._precheck(scan)
        if not hasattr(self, "tree_"):
            self._init_state()
        tr = self.tree_
        changed = []                      # world positions whose training sets changed
        # stage 2: re-evaluate visible samples
        cent, ptr, samp = K.candidates(np.ascontiguousarray(scan.origin, np.float64), scan.rmax, tr.geo, tr.cgrid, tr.gshape,
                                     tr.goff, tr.node_internal, tr.level_off, self._hc(),
                                     tr.slot_head, tr.link, tr.s_node,
                                     tr.node_sample, self._singletons(scan))
        if len(cent):
            vis = self._child_visible(cent, scan)
            sel = np.repeat(vis, np.diff(ptr))
            cand = samp[sel]
        else:
            cand = samp[:0]
        touched = []
        seen = cand[:0]
        if len(cand):
            action, P, N, sp, sg = self._reeval(cand, scan)
            tr.reserve(P[action == 2])
            self._sync_slot_arrays()
            run = tr.run[cand]
            new = K.apply_reeval(cand, action, P, N, sp, sg, *self._tree_args())
            moved = (action == 2) & (new >= 0)
            tr.run[new[moved]] = run[moved]         # a re-inserted sample keeps its runs
            seen = np.concatenate([cand[action < 2], new[moved]])
            # which changes the trained GPs must see (all of them with the published retraining)
            ch, kept = K.reeval_changes(cand, action, new, tr.pos, tr.nrm, tr.sp, tr.sg, tr.pos_t,
                                      tr.nrm_t, tr.sp_t, tr.sg_t, self._retrain_tol(),
                                      bool(self._pub("retrain") or self._retrain_tol() <= 0))
            changed.append(ch)
            touched.append(kept)
        # stage 3: new samples
        P, ok, bad, N, sp, sg = self._new_samples(scan)
        tr.reserve(P[ok])
        self._sync_slot_arrays()
        new = K.apply_new(P, ok, bad, N, sp, sg, *self._tree_args())
        kept = new[new >= 0]
        tr.run[kept] = 0.0
        self._observe_runs(scan, np.concatenate([seen, kept]))
        self._snapshot(kept)
        changed.append(tr.pos[kept])
        touched.append(tr.pos[kept])
        self._sync_slot_arrays()
        # stage 4: retrain
        if self._pub("retrain"):
            self._retrain_legacy(np.concatenate(touched) if touched else np.zeros((0, self.dim)))
        else:
            self._retrain_dirty(np.concatenate(changed))
        self.free_.mark(scan.origin_sensor, getattr(scan, "free_hits", scan.hits))
        self._index_samples()
        self.n_updates_ += 1
        self.version_ += 1

    def _observe_runs(self, scan, idx):
        """Record on samples ``idx`` how far this scan's returns ran on along their faces (2D)."""

    def _snapshot(self, idx):
        tr = self.tree_
        tr.pos_t[idx], tr.nrm_t[idx] = tr.pos[idx], tr.nrm[idx]
        tr.sp_t[idx], tr.sg_t[idx] = tr.sp[idx], tr.sg[idx]

    def _cluster_coords(self, pts):
        tr = self.tree_
        d = self.dim
        return np.floor((pts - tr.geo[:d]) / tr.geo[d]).astype(np.int64)

    def _slots_of(self, coords):
        """Slots of the non-empty clusters at integer coordinates (k, d); -1 where none."""
        tr = self.tree_
        if len(coords) == 0:
            return np.zeros(0, np.int64)
        rel = coords - tr.goff
        inside = ((rel >= 0) & (rel < tr.gshape)).all(1)
        strides = np.cumprod(np.concatenate([[1], tr.gshape[:-1]]))
        flat = (np.where(inside[:, None], rel, 0) * strides).sum(1)
        s = np.where(inside, tr.cgrid[flat], -1).astype(np.int64)
        return s

    def _neigh(self, coords, reach):
        d = self.dim
        off = np.stack(np.meshgrid(*[np.arange(-reach, reach + 1)] * d, indexing="ij"), -1)
        off = off.reshape(-1, d)
        allc = (coords[:, None, :] + off[None]).reshape(-1, d)
        return np.unique(allc, axis=0)

    def _train(self, slots):
        tr = self.tree_
        if len(slots) == 0:
            return
        R = self._TRAIN_R * self._hc()
        ptr, idx = K.gather_training(slots, R, tr.geo, tr.cgrid, tr.gshape, tr.goff, tr.slot_head,
                                   tr.link, tr.s_node, tr.slot_coord, tr.pos, self._train_cap())
        nonempty = np.diff(ptr) > 0
        slots = slots[nonempty]
        ptr = np.concatenate([[0], np.cumsum(np.diff(ptr)[nonempty])])
        self._sync_slot_arrays()
        self.gps_.train(slots, ptr, idx, tr, float(self.local_gp.map_scale), float(self.local_gp.fbias),
                        self._pub("gp_noise") and self.dim == 2,
                        NOGRAD_VALUE_NOISE if self._pub("gp_noise") else self._NOGRAD_NOISE,
                        0.0 if self._pub("gp_noise") else self._VALUE_FLOOR)
        self._sync_slot_arrays()
        self.gp_gen_[slots] = self.slot_gen_[slots]

    def _retrain_legacy(self, touched):
        """Spec §8.1: clusters near the active ones, with the |U| <= 1 carry-over quirk."""
        act = np.concatenate([self.active_, self._cluster_coords(touched)])
        act = np.unique(act, axis=0) if len(act) else act
        reach = int(round(self._UPDATE_R / 2.0))
        U = self._neigh(act, reach) if len(act) else act
        slots = self._slots_of(U)
        slots = np.unique(slots[slots >= 0])
        if len(slots) <= (1 if self.dim == 2 else 0):
            self.active_ = act
            return
        self._train(slots)
        self.active_ = np.zeros((0, self.dim), np.int64)

    def _retrain_dirty(self, changed):
        """Default: retrain exactly the clusters whose training set changed."""
        if len(changed) == 0:
            return
        tr, g = self.tree_, self.gps_
        self._sync_slot_arrays()
        slots = K.dirty_slots(np.ascontiguousarray(changed, np.float64), self._TRAIN_R * self._hc(),
                            self._train_cap(), tr.geo, tr.cgrid, tr.gshape, tr.goff, tr.slot_coord,
                            tr.node_sample.shape[0], g.gp_obs, g.gp_m, g.X, g.kinds)
        self._train(slots)

    def _train_cap(self):
        """Samples per local GP at most (0: no cap; the published retraining has none)."""
        cap = self.local_gp.train_cap
        return 0 if (cap is None or self._pub("retrain")) else int(cap)

    # -- query ----------------------------------------------------------------------------------
    def _gp_query(self, pts):
        """Raw published query (spec §9): rows [f, grad(d), var_f, var_grad(d)] per point."""
        tr, g = self.tree_, self.gps_
        self._sync_slot_arrays()
        out = np.empty((len(pts), 2 * self.dim + 2))
        W = self._QUERY_W if self._QUERY_W is not None else 4.0 * self.local_gp.map_scale
        v0, g0 = _var_consts(self.dim, float(self.local_gp.map_scale))
        mmax = g.m_max
        query_gp(pts, float(W), self._T_BLEND, self._pub("query_mode"), float(self.local_gp.map_scale), v0, g0,
                 1.0 + float(self.noise.map_noise), tr.geo, tr.cgrid, tr.gshape, tr.goff,
                 tr.node_sample, tr.node_internal, self.slot_gen_, self.gp_gen_, g.gp_m, g.gp_obs,
                 g.gp_tri, g.X, g.kinds, g.alpha, g.Lbuf, max(mmax, 1), out)
        return out

    def query(self, points):
        """Signed distance, gradient and variance at points.

        Parameters
        ----------
        points : array_like of shape (n, dim)
            World coordinates, metres.

        Returns
        -------
        sdf : ndarray of shape (n,)
            Signed distance in metres: positive in free space, negative behind surfaces.
            ``distance.query_mode="published"`` returns the published ``f + fbias``.
        grad : ndarray of shape (n, dim)
            Gradient of the distance (unit outward normal near surfaces).
        var : ndarray of shape (n,)
            Variance of the distance (see the module docs for its meaning).

        Notes
        -----
        Any finite point is answered. A point with a coordinate beyond ``FAR_COORD`` (1e100 m),
        where squared distances overflow, gets the prior: its distance to the origin (positive,
        finite, overflow-safe), the unit gradient away from the origin and the prior variance
        ``1 + map_noise``; no NaN. More than ``MAX_QUERY_POINTS`` (2**26) points in one call raise
        ``ValueError`` (query them in parts).
        """
        check_updated(self, "tree_")
        _check_count(points)
        # C order: a strided view would compile every distance kernel a second time (layout A)
        pts = np.ascontiguousarray(as_points(points, self.dim, "points", allow_empty=True))
        _check_count(pts)
        n = len(pts)
        d = self.dim
        if n == 0:
            return np.zeros(0), np.zeros((0, d)), np.zeros(0)
        if np.abs(pts).max() > FAR_COORD:
            # squared distances of such points overflow; the map knows nothing there: the prior
            return self._far_prior(pts, np.abs(pts).max(1) > FAR_COORD)
        if self._pub("query_mode"):
            out = self._gp_query(pts)
            return out[:, 0] + self.local_gp.fbias, out[:, 1:d + 1].copy(), out[:, d + 1].copy()
        return self._faithful(pts)

    def _far_prior(self, pts, far):
        """Query with the points beyond :data:`FAR_COORD` answered by the prior: their distance
        to the origin (overflow-safe; the map lies within far less than that), its gradient, and
        the prior variance ``1 + map_noise``."""
        d = self.dim
        n = len(pts)
        dist, grad, var = np.empty(n), np.empty((n, d)), np.empty(n)
        near = ~far
        if near.any():
            r = self.query(pts[near])
            dist[near], grad[near], var[near] = r
        x = pts[far]
        s = np.abs(x).max(1)
        u = x / s[:, None]
        nu = np.linalg.norm(u, axis=1)
        dist[far] = s * nu
        grad[far] = u / nu[:, None]
        var[far] = 1.0 + float(self.noise.map_noise)
        return dist, grad, var

    def _kd(self):
        """KD-tree over the samples, rebuilt when the map changed."""
        if getattr(self, "_kd_version", -1) != self.version_:
            from scipy.spatial import cKDTree

            idx = self.tree_.alive()
            self._kd_idx = idx
            self._kd_tree = cKDTree(self.tree_.pos[idx]) if len(idx) else None
            self._kd_version = self.version_
        return self._kd_tree, self._kd_idx

    def _sign_width(self):
        """Width (m) of the far field's implicit-MLS sign (0: off)."""
        return self._IMLS_WIDTH * self._spacing() if self._IMLS_WIDTH > 0 else 0.0

    def _faithful(self, pts):
        """Default query: GPIS near surfaces, surfel distance far away, blended smoothly."""
        tr = self.tree_
        sptr, sidx = self._sample_index_
        var_unobs = 1.0 + float(self.noise.map_noise)
        n, d = pts.shape
        if len(sidx) == 0:
            return far_field(pts, None, tr.pos, tr.nrm, tr.sp, tr.sg, self._surfel_radius(),
                             self.free_, var_unobs)
        near, far = self._blend_band()
        t_info = self._T_BLEND if self._VAR_BLEND else 0.0
        k = min(4, len(sidx))
        if n >= PARALLEL_POINTS:            # the GP part on all cores
            gi = np.empty((n, k), np.int64)
            K.knn(pts, k, tr.geo, tr.cgrid, tr.gshape, tr.goff, sptr, sidx, tr.pos, gi)
            dist, grad, var, w = far_weights(pts, gi, tr.pos, tr.nrm, tr.sp, tr.sg,
                                             self._surfel_radius(), self.free_, var_unobs, near,
                                             far, gate=self._SIGN_GATE, sign_h=self._sign_width(),
                                             behind=self._BEHIND)
            sel = np.flatnonzero(w > 0)
            if len(sel):
                out = self._gp_query(pts[sel])
                K.blend_gp(sel, out, w, float(self.local_gp.fbias), var_unobs - 1e-12, dist, grad, var,
                         t_info)
            return dist, grad, var
        dist, grad, var = np.empty(n), np.empty((n, d)), np.empty(n)
        K.faithful(pts, *self._faithful_args(), dist, grad, var)
        return dist, grad, var

    def _faithful_args(self):
        """The default query's kernel arguments after the points (``_query.faithful``)."""
        tr, g, fr = self.tree_, self.gps_, self.free_
        sptr, sidx = self._sample_index_
        self._sync_slot_arrays()
        W = self._QUERY_W if self._QUERY_W is not None else 4.0 * self.local_gp.map_scale
        v0, g0 = _var_consts(self.dim, float(self.local_gp.map_scale))
        near, far = self._blend_band()
        return (min(4, len(sidx)), sptr, sidx, tr.pos, tr.nrm, tr.sp, tr.sg, float(self._SIGN_GATE),
                bool(np.isfinite(self._SIGN_GATE)), float(self._surfel_radius()), fr.grid, fr.gshape,
                fr.goff, float(fr.res), 1.0 + float(self.noise.map_noise), float(near), float(far),
                float(self._sign_width()), float(self._BEHIND), float(W), self._T_BLEND, False,
                float(self.local_gp.map_scale), v0, g0, float(self.local_gp.fbias),
                self._T_BLEND if self._VAR_BLEND else 0.0, tr.geo, tr.cgrid, tr.gshape, tr.goff,
                tr.node_sample, tr.node_internal, self.slot_gen_, self.gp_gen_, g.gp_m, g.gp_obs,
                g.gp_tri, g.X, g.kinds, g.alpha, g.Lbuf, max(g.m_max, 1))

    def _register_native(self, pts, x0, opts):
        """ICP-G of the base-frame points pts (n, 2) from the pose x0 in compiled code, for
        :func:`polar_sim.registration.register_sdf` (same algorithm, same bits as its Python
        loop); None where that loop must run instead: a 3D or published-mode map, one without
        samples, or poses within reach of ``FAR_COORD``."""
        if (self.dim != 2 or self._pub("query_mode") or not hasattr(self, "tree_")
                or len(self._sample_index_[1]) == 0 or len(pts) >= PARALLEL_POINTS
                or not np.abs(x0).max() + opts.step[0] * opts.max_iterations < 1e90):
            return None
        H = np.zeros((3, 3))
        out = K.register_2d(pts, np.array(x0, np.float64), opts.max_iterations, opts.min_points,
                          opts.tolerance, opts.kind, opts.scale, opts.sigma2, opts.max_variance,
                          opts.step[0], opts.step[1], opts.corr[0], opts.corr[1],
                          *self._faithful_args(), H)
        return out[:9] + (H if out[11] else None,) + out[9:]

    def _index_samples(self):
        """Each cluster slot's samples (CSR), for the query's nearest-sample search; rebuilt
        whenever the tree changed (the end of an update, a load)."""
        tr = self.tree_
        self._sample_index_ = K._slot_samples(tr.node_sample, int(tr.counts[2]))

    def surface(self, res=None, band=None, *, evidence=None, free_depth=None, support_radius=None,
                min_support=None, gate_var=None, face_end=None, face_end_bare=None,
                return_evidence=False):
        """Zero level set of :meth:`query` near the observed samples.

        Parameters
        ----------
        res : float, optional
            Grid step, metres (default 0.05 m in 2D, 0.002 m in 3D).
        band : float, optional
            Only grid nodes within this distance of a sample are used (default 0.3 m in 2D,
            0.01 m in 3D); legacy mode also drops nodes with GP variance >= 0.4 (2D) / 0.1 (3D),
            as the published demos do.
        evidence : bool, optional
            2D only: return the zero level only where the map has evidence for it (default: on
            in default mode, off in the published ``query_mode``). A vertex is left out when
            observed free space lies ``free_depth`` inside it; when fewer than ``min_support``
            samples of its face with a trusted normal lie within ``support_radius``, or it lies
            past the end of its face (not between two of them along the face, and out of reach
            of each: ``face_end`` past a sample whose scans saw their returns run on along the
            face, else as far as they ran plus 3 cm, at least ``face_end_bare``, and within 8 cm
            of the sample's tangent line); or when the
            map's variance there reaches ``gate_var`` (defaults ``_surface.FREE_DEPTH`` 0.05 m,
            ``SUPPORT_RADIUS`` 0.5 m, ``MIN_SUPPORT`` 1, ``FACE_END`` 0.175 m,
            ``FACE_END_BARE`` 0.1 m, ``GATE_VAR`` 0.5; chosen on dev seeds). A sample left with no
            returned vertex within two grid steps (a post a few cm across, whose one or two
            samples have no trusted normal) is returned as a (1, 2) point at its measured
            position: the sensor's evidence for a surface there, without the level's guess at
            its extent.
        free_depth, support_radius, min_support, gate_var, face_end, face_end_bare : optional
            The gates above (2D; finite, > 0; ``min_support`` an int >= 0). To turn them all off,
            pass ``evidence=False``.
        return_evidence : bool, default False
            2D only: return a :class:`~polar_sim.gpis._surface.SurfaceEvidence` (the polylines
            with an evidence count and a position sigma per vertex, and the rejected pieces with
            the gate they failed) instead of the list of polylines.

        Returns
        -------
        list of ndarray (k, 2) in 2D (polylines, world metres); trimesh.Trimesh in 3D.
        In 2D (default mode) objects smaller than ``res`` are kept: around samples the grid
        misses, the zero level is traced on a grid five times finer, and a sample where the map
        only touches zero (a post seen end-on) is returned as a (1, 2) array, a point.

        Raises
        ------
        ValueError
            Naming ``res`` when the grid over the samples' bounding box would exceed
            ``_surface.MAX_SURFACE_NODES`` (2**24) nodes: a coarser ``res`` is needed (e.g. a
            3D map spanning a room at the default 2 mm). Nothing is allocated before the check.
            Naming a gate argument that is out of range, or ``return_evidence`` in 3D.
        """
        from polar_sim.gpis import _surface

        gates = _surface.gate_args(self, evidence, free_depth, support_radius, min_support, gate_var,
                                   return_evidence, face_end, face_end_bare)
        check_updated(self, "tree_")
        res = self._SURF_RES if res is None else as_positive_float(res, "res")
        band = self._SURF_BAND if band is None else as_positive_float(band, "band", allow_zero=True)
        var_max = self._SURF_VAR if self._pub("query_mode") else np.inf
        if self.dim == 3:
            return _surface.surface_3d(self, res, band, var_max)
        out = _surface.surface_2d(self, res, band, var_max, gates)
        return out.lines if gates is not None and not return_evidence else out

    # -- samples, persistence --------------------------------------------------------------------
    def samples(self):
        """Surface samples held by the map.

        Returns
        -------
        dict with ``points`` (n, dim) m, ``normals`` (n, dim) outward unit normals,
        ``position_noise`` (n,) and ``gradient_noise`` (n,) (variances, as in the spec).
        """
        check_updated(self, "tree_")
        idx = self.tree_.alive()
        t = self.tree_
        return {"points": t.pos[idx].copy(), "normals": t.nrm[idx].copy(),
                "position_noise": t.sp[idx].copy(), "gradient_noise": t.sg[idx].copy()}

    def nbytes(self):
        """Bytes held by the map's arrays (samples, tree, cluster GPs, free-space grid)."""
        if not hasattr(self, "tree_"):
            return 0
        n = sum(v.nbytes for v in self.tree_.state().values())
        return n + self.gps_.nbytes() + self.free_.nbytes() + self.slot_gen_.nbytes

    def save(self, path):
        """Write the map to ``path`` (.npz, versioned, no pickle)."""
        _io.save(self, path)

    @classmethod
    def load(cls, path):
        """Read a map written by :meth:`save`; raises ``ValueError`` on a bad file."""
        return _io.load(cls, path)


def _check_count(points):
    """Refuse more than :data:`MAX_QUERY_POINTS` points, before anything of their size is allocated."""
    n = len(points) if isinstance(points, np.ndarray) and points.ndim >= 1 else None
    if n is not None and n > MAX_QUERY_POINTS:
        raise ValueError(f"points: {n} points in one query, more than the limit {MAX_QUERY_POINTS} "
                         "(MAX_QUERY_POINTS); query them in parts")
