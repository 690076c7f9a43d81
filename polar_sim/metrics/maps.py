"""Scores of distance-field maps (GPIS, grids, EDT) against an exact SDF, in 2D and for 3D objects.

The ground truth comes in as arrays or as a callable ``sdf(points (n, d)) -> (n,)`` (for example
``World.sdf``); nothing here knows a simulator. Definitions:

- **Observed** (2D, :class:`ObservedArea`), from the noise-free beams of the scans that built the
  map, never from a map: a point is *crossed* if it lies in a 2 cm cell some beam crossed or ended
  in; *reached* the same with every beam lengthened by ``behind`` (0.3 m); its *nearest hit*
  holds if some beam end point lies within ``|sdf| + tol`` of it (the true surface point nearest
  to it was seen). The *near* set is reached & nearest hit & |sdf| < 0.3 m; the *far* set is
  crossed & nearest hit & 0.3 < sdf < 2 m.
- **SDF scores** (:func:`sdf_map_scores`): RMSE, median and p90 of |error| on *near*, mean on
  *far*, median gradient angle on each (medial-axis points, where the exact gradient has norm
  < 0.5 by central differences, are left out of the angles).
- **Surface scores** (:func:`surface_scores_2d`): surface RMSE = RMS of the exact |SDF| at the
  estimated surface points inside the observed area; Hausdorff = the larger of its maximum and
  the largest distance from an observed true surface point (a noise-free end point) to the
  estimate.
- **Where the worst errors lie** (:func:`classify_worst`): the worst ``top`` share of both
  directed errors, each moved onto the true surface, classed as corner / sparsely seen / wall.
- **Per-class report** (:func:`class_report`): per point class, the error, the predicted standard
  deviation and the coverage of the 95 % interval (|error| <= 1.96 sigma).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from polar_sim._validation import as_float, as_float_array, as_int, as_points, as_positive_float

__all__ = ["hit_points", "beam_cells", "ObservedArea", "scan_hit_counts", "sdf_gradient", "angle_deg",
           "sample_eval_points", "sdf_map_scores", "surface_scores_2d", "classify_worst", "class_report",
           "object_map_scores", "polyline_points", "map_scores_2d", "WORST_CLASSES", "MAX_GRID_CELLS", "MAX_EVAL_POINTS"]

#: Classes of :func:`classify_worst`, in the order of its labels 0, 1, 2.
WORST_CLASSES = ("corner", "sparse", "wall")

#: The most cells a grid of :func:`beam_cells` (one byte each) may hold: 4e8, 400 MB.
MAX_GRID_CELLS = 400_000_000
#: The most evaluation points :func:`sample_eval_points` draws (about 100 bytes each).
MAX_EVAL_POINTS = 10_000_000


def _scans(angles, poses, ranges):
    """Checked scans: beam angles (m,) rad, sensor poses (n, 3) and ranges (n, m) m (inf or NaN: no
    return), as float64 arrays."""
    a = as_float_array(angles, "angles")
    if a.ndim != 1 or not np.isfinite(a).all():
        raise ValueError(f"angles: expected finite beam angles of shape (m,), got shape {a.shape}")
    p = as_float_array(poses, "poses")
    if p.ndim != 2 or p.shape[1] != 3 or not np.isfinite(p).all():
        raise ValueError(f"poses: expected finite sensor poses (x, y, theta) of shape (n, 3), got shape {p.shape}")
    r = as_float_array(ranges, "ranges")
    if r.shape != (len(p), len(a)):
        raise ValueError(f"ranges: expected one scan of {len(a)} ranges per pose, shape ({len(p)}, {len(a)}), "
                         f"got {r.shape}")
    return a, p, r


def _max_range(x):
    return as_float(x, "max_range", minimum=0.0, exclusive_minimum=True, allow_inf=True)


def _callable(f, name):
    if not callable(f):
        raise TypeError(f"{name}: expected a function of points (n, d), got {type(f).__name__}")
    return f


def _observed(obs):
    if not isinstance(obs, ObservedArea):
        raise TypeError(f"obs: expected an ObservedArea, got {type(obs).__name__}")
    return obs


def _values(x, name, n=None, *, finite=True):
    """A 1-D float64 array (of ``n`` values if given)."""
    a = as_float_array(x, name)
    if a.ndim != 1 or (n is not None and len(a) != n):
        raise ValueError(f"{name}: expected shape ({'n' if n is None else n},), got {a.shape}")
    if finite and not np.isfinite(a).all():
        raise ValueError(f"{name}: contains NaN or inf")
    return a


def _corners(c):
    """True corners (c, 2) (or an empty array), finite."""
    a = as_float_array(c, "corners")
    if a.size and (a.ndim != 2 or a.shape[1] != 2 or not np.isfinite(a).all()):
        raise ValueError(f"corners: expected finite points of shape (c, 2), got shape {a.shape}")
    return a.reshape(-1, 2)


def _flags(x, name, n):
    """A 1-D boolean array of ``n`` values."""
    if x is None or isinstance(x, (str, bytes)):
        raise TypeError(f"{name}: expected a boolean array, got {type(x).__name__}")
    a = np.asarray(x)
    if a.dtype != bool:
        raise TypeError(f"{name}: expected a boolean array, got dtype {a.dtype}")
    if a.shape != (n,):
        raise ValueError(f"{name}: expected shape ({n},), got {a.shape}")
    return a


def _valid(r, max_range):
    with np.errstate(invalid="ignore"):
        return np.isfinite(r) & (r > 0) & (r < max_range)


def hit_points(angles, poses, ranges, max_range=30.0):
    """World end points (m, 2) of the returns (0 < r < ``max_range``) of scans at sensor poses (n, 3)
    with beam angles (m,) and ranges (n, m)."""
    angles, poses, ranges = _scans(angles, poses, ranges)
    max_range = _max_range(max_range)
    out = []
    for p, r in zip(poses, ranges):
        ok = _valid(r, max_range)
        a = angles[ok] + p[2]
        out.append(np.column_stack([p[0] + r[ok] * np.cos(a), p[1] + r[ok] * np.sin(a)]))
    return np.vstack(out) if out else np.zeros((0, 2))


def beam_cells(angles, poses, ranges, *, cell, origin, shape, extend=0.0, max_range=30.0):
    """Boolean grid ``shape`` (nx, ny): the cells of side ``cell`` (lower-left corner of cell [0, 0]
    at ``origin``) that a beam crossed or ended in.

    A beam is a return with ``0 < r + extend < max_range``, lengthened by ``extend`` metres. The
    cells a segment crosses are its start and end cells and the two cells on either side of each
    crossing of a grid line (exact, as a DDA traversal, except at measure-zero corner passes).
    """
    angles, poses, ranges = _scans(angles, poses, ranges)
    cs = as_positive_float(cell, "cell")
    origin = as_float_array(origin, "origin")
    if origin.shape != (2,) or not np.isfinite(origin).all():
        raise ValueError(f"origin: expected a finite point (x, y), got shape {origin.shape}")
    if shape is None or isinstance(shape, (str, bytes)):
        raise TypeError(f"shape: expected (nx, ny), got {type(shape).__name__}")
    if np.shape(shape) != (2,):
        raise ValueError(f"shape: expected (nx, ny), got shape {np.shape(shape)}")
    nx, ny = (as_int(v, "shape", minimum=1) for v in shape)
    if nx * ny > MAX_GRID_CELLS:
        raise ValueError(f"shape: {nx} x {ny} cells is more than the limit of {MAX_GRID_CELLS:,}")
    extend = as_float(extend, "extend")
    max_range = _max_range(max_range)
    out = np.zeros((nx, ny), bool)

    def mark(ix, iy):
        ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        out[ix[ok], iy[ok]] = True

    for p, r in zip(poses, ranges):
        rr = r + extend
        ok = _valid(rr, max_range)
        if not ok.any():
            continue
        a = angles[ok] + p[2]
        sx, sy = (p[0] - origin[0]) / cs, (p[1] - origin[1]) / cs
        ex, ey = sx + rr[ok] * np.cos(a) / cs, sy + rr[ok] * np.sin(a) / cs
        mark(np.array([int(np.floor(sx))]), np.array([int(np.floor(sy))]))
        mark(np.floor(ex).astype(np.int64), np.floor(ey).astype(np.int64))
        for u0, u1, v0, v1, swap in ((sx, ex, sy, ey, False), (sy, ey, sx, ex, True)):
            # crossings of the lines u = m (integers strictly after floor(u0), up to floor(u1))
            a0, a1 = np.floor(u0), np.floor(u1)
            lo = np.minimum(a0, a1) + 1
            cnt = np.abs(a1 - a0).astype(np.int64)
            if cnt.sum() == 0:
                continue
            beam = np.repeat(np.arange(len(u1)), cnt)
            first = np.repeat(np.cumsum(cnt) - cnt, cnt)
            m = np.repeat(lo, cnt) + (np.arange(cnt.sum()) - first)
            t = (m - u0) / (u1 - u0)[beam]
            v = np.floor(v0 + t * (v1 - v0)[beam]).astype(np.int64)
            mi = m.astype(np.int64)
            for iu in (mi - 1, mi):
                mark(*((v, iu) if swap else (iu, v)))
    return out


class ObservedArea:
    """What the noise-free beams of a drive observed; defines "observed" for the 2D scores.

    Parameters
    ----------
    angles : (m,) beam angles, rad; poses : (n, 3) sensor poses; ranges : (n, m) noise-free
        ranges, m (inf = no return).
    tol : float, default 0.03
        Slack of :meth:`nearest_hit`, m (covers the gap between 0.25 deg beams up to about 12 m).
    behind : float, default 0.3
        How far past an end point :meth:`reached` extends a beam, m.
    cell : float, default 0.02
        Cell of the crossed / reached grids, m.

    Attributes
    ----------
    hits : (k, 2) the noise-free end points, a dense sampling of the observed true surface.
    count : callable ``count(points (q, 2)) -> (q,)``: how many scans hit within about 7 cm
        (:func:`scan_hit_counts`).
    """

    def __init__(self, angles, poses, ranges, *, tol=0.03, behind=0.3, cell=0.02):
        self.tol = as_float(tol, "tol", minimum=0.0)
        self.behind = as_float(behind, "behind", minimum=0.0)
        self.cell = as_positive_float(cell, "cell")
        angles, poses, ranges = _scans(angles, poses, ranges)
        self.hits = hit_points(angles, poses, ranges)
        if not len(self.hits):
            raise ValueError("ranges: the scans have no returns, nothing was observed")
        b = poses[:, :2]
        lo = np.minimum(self.hits.min(0), b.min(0)) - behind - 0.1
        hi = np.maximum(self.hits.max(0), b.max(0)) + behind + 0.1
        self.origin = lo
        cells = np.ceil((hi - lo) / cell - 1e-9)
        if np.prod(cells) > MAX_GRID_CELLS:
            raise ValueError(f"cell: {cell:g} m cells over the scans' {hi[0] - lo[0]:.4g} x {hi[1] - lo[1]:.4g} m "
                             f"are more than the limit of {MAX_GRID_CELLS:,}")
        self.shape = tuple(cells.astype(int))
        kw = dict(cell=cell, origin=lo, shape=self.shape)
        self._crossed = beam_cells(angles, poses, ranges, **kw)
        self._reached = beam_cells(angles, poses, ranges, extend=behind, **kw)
        self._kd = cKDTree(self.hits)
        self.count = scan_hit_counts(angles, poses, ranges)

    def _known(self, grid, P):
        idx = np.floor((np.asarray(P, float) - self.origin) / self.cell).astype(np.int64)
        nx, ny = grid.shape
        inside = (idx[:, 0] >= 0) & (idx[:, 0] < nx) & (idx[:, 1] >= 0) & (idx[:, 1] < ny)
        out = np.zeros(len(idx), bool)
        out[inside] = grid[idx[inside, 0], idx[inside, 1]]
        return out

    def crossed(self, P):
        """(n,) bool: P lies in a cell a beam crossed or ended in."""
        return self._known(self._crossed, P)

    def reached(self, P):
        """(n,) bool: P is crossed, or at most ``behind`` past an end point along its beam."""
        return self._known(self._reached, P)

    def nearest_hit(self, P, gt):
        """(n,) bool: some end point lies within ``|gt| + tol`` of P (gt: exact SDF at P)."""
        return self._kd.query(P)[0] <= np.abs(gt) + self.tol

    def sets(self, P, gt):
        """Masks ``near`` and ``far`` (see the module docstring) of points P with exact SDF gt."""
        nh = self.nearest_hit(P, gt)
        return {"near": self.reached(P) & nh & (np.abs(gt) < 0.3),
                "far": self.crossed(P) & nh & (gt > 0.3) & (gt < 2.0)}


def scan_hit_counts(angles, poses, ranges, cell=0.05):
    """Per ``cell`` of the plane, how many scans hit it: a function ``count(points (n, 2)) -> (n,)``
    giving the largest count over the 3 x 3 cells around each point (so "hit by k scans" means
    within about 1.5 cells, 7 cm)."""
    angles, poses, ranges = _scans(angles, poses, ranges)
    cell = as_positive_float(cell, "cell")
    keys = []
    for p, r in zip(poses, ranges):
        ok = np.isfinite(r)
        a = angles[ok] + p[2]
        h = np.column_stack([p[0] + r[ok] * np.cos(a), p[1] + r[ok] * np.sin(a)])
        c = np.floor(h / cell).astype(np.int64)
        keys.append(np.unique(c[:, 0] * 1_000_003 + c[:, 1]))
    uk, cnt = np.unique(np.concatenate(keys) if keys else np.zeros(0, np.int64), return_counts=True)

    def count(points):
        c = np.floor(as_points(points, 2, "points", allow_empty=True) / cell).astype(np.int64)
        best = np.zeros(len(c), np.int64)
        if len(uk) == 0:
            return best
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                key = (c[:, 0] + dx) * 1_000_003 + (c[:, 1] + dy)
                j = np.clip(np.searchsorted(uk, key), 0, len(uk) - 1)
                best = np.maximum(best, np.where(uk[j] == key, cnt[j], 0))
        return best

    return count


def sdf_gradient(sdf, P, h=1e-4):
    """Gradient (n, d) of a signed distance function ``sdf`` at points P (n, d) by central differences
    of step ``h``."""
    sdf = _callable(sdf, "sdf")
    P = as_float_array(P, "P")
    if P.ndim != 2 or P.shape[1] not in (2, 3) or not np.isfinite(P).all():
        raise ValueError(f"P: expected finite points of shape (n, 2) or (n, 3), got shape {P.shape}")
    h = as_positive_float(h, "h")
    out = np.zeros_like(P)
    for j in range(P.shape[1]):
        e = np.zeros(P.shape[1])
        e[j] = h
        out[:, j] = (sdf(P + e) - sdf(P - e)) / (2 * h)
    return out


def angle_deg(a, b):
    """Angle (n,) in degrees between the rows of a and b (n, 2|3); 90 degrees to a zero vector."""
    a = as_float_array(a, "a")
    if a.ndim != 2 or a.shape[1] not in (2, 3) or not np.isfinite(a).all():
        raise ValueError(f"a: expected finite vectors of shape (n, 2) or (n, 3), got shape {a.shape}")
    b = as_float_array(b, "b")
    if b.shape != a.shape or not np.isfinite(b).all():
        raise ValueError(f"b: expected finite vectors of the shape of a {a.shape}, got {b.shape}")
    return _angles(a, b)


def _angles(a, b):
    na = np.linalg.norm(a, axis=1)
    nb = np.linalg.norm(b, axis=1)
    c = np.einsum("ij,ij->i", a, b) / np.maximum(na * nb, 1e-300)
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def sample_eval_points(obs: ObservedArea, sdf, n, seed, margin=0.5):
    """``n`` uniform points over the box of the observed surface (plus ``margin`` m), with their
    exact SDF ``gt``, its gradient ``G`` (on the near and far sets only) and the masks
    ``near``/``far`` (:meth:`ObservedArea.sets`)."""
    obs, sdf = _observed(obs), _callable(sdf, "sdf")
    n = as_int(n, "n", minimum=1, maximum=MAX_EVAL_POINTS)
    rng = np.random.default_rng(np.random.SeedSequence([as_int(seed, "seed", minimum=0), 3131]))
    margin = as_float(margin, "margin", minimum=0.0)
    lo, hi = obs.hits.min(0) - margin, obs.hits.max(0) + margin
    P = rng.uniform(lo, hi, (n, 2))
    gt = sdf(P)
    out = {"P": P, "gt": gt}
    out.update(obs.sets(P, gt))
    G = np.zeros_like(P)
    sel = out["near"] | out["far"]
    G[sel] = sdf_gradient(sdf, P[sel])
    out["G"] = G
    return out


def sdf_map_scores(d, grad, E):
    """SDF and gradient errors of a map's answers ``d`` (n,), ``grad`` (n, 2) at the points of
    :func:`sample_eval_points` ``E``. Returns (scores dict, signed errors (n,)). A map's NaN or inf
    answers count as they are (they make the scores NaN or inf)."""
    if not isinstance(E, dict) or not {"gt", "near", "far", "G"} <= set(E):
        raise TypeError(f"E: expected the dict of sample_eval_points (gt, near, far, G), got {type(E).__name__}")
    n = len(E["gt"])
    e = _values(d, "d", n, finite=False) - E["gt"]
    grad = as_float_array(grad, "grad")
    if grad.shape != (n, 2):
        raise ValueError(f"grad: expected shape ({n}, 2), got {grad.shape}")
    near, far = E["near"], E["far"]
    ok = np.linalg.norm(E["G"], axis=1) > 0.5
    ang = _angles(grad, E["G"])
    a = np.abs(e)

    def stat(f, x):
        return float(f(x)) if len(x) else float("nan")

    return {"near_rmse_m": stat(lambda x: np.sqrt(np.mean(x ** 2)), e[near]), "near_median_abs_m": stat(np.median, a[near]),
            "near_p90_abs_m": stat(lambda x: np.percentile(x, 90), a[near]), "far_mae_m": stat(np.mean, a[far]),
            "far_median_abs_m": stat(np.median, a[far]),
            "grad_near_median_deg": stat(np.median, ang[near & ok]), "grad_far_median_deg": stat(np.median, ang[far & ok]),
            "n_near": int(near.sum()), "n_far": int(far.sum())}, e


def polyline_points(lines, spacing=0.01):
    """Points every ``spacing`` metres along a list of polylines (k, 2); a (1, 2) entry is a point."""
    from polar_sim.metrics.surface import sample_polyline

    if lines is None or isinstance(lines, (str, bytes, dict)) or not hasattr(lines, "__iter__"):
        raise TypeError(f"lines: expected a list of polylines (k, 2), got {type(lines).__name__}")
    spacing = as_positive_float(spacing, "spacing")
    lines = [as_float_array(ln, f"lines[{i}]") for i, ln in enumerate(lines)]
    for i, ln in enumerate(lines):
        if ln.size and (ln.ndim != 2 or ln.shape[1] != 2):
            raise ValueError(f"lines[{i}]: expected a polyline of shape (k, 2), got {ln.shape}")
    pts = [sample_polyline(ln, spacing) if len(ln) >= 2 else ln.reshape(-1, 2) for ln in lines if len(ln)]
    return np.vstack(pts) if pts else np.zeros((0, 2))


def surface_scores_2d(est, sdf, obs: ObservedArea, well_k=None):
    """Surface errors of estimated surface points ``est`` (m, 2) against the exact ``sdf``.

    Surface -> truth: |sdf| at the estimated points inside the observed area (``obs.reached``), its
    RMS the surface RMSE, its max the directed Hausdorff distance; truth -> surface: the distance
    from every observed true surface point (``obs.hits``) to the nearest estimated point;
    Hausdorff = the larger maximum. With ``well_k``: ``hausdorff_wellseen_m`` and
    ``surface_rmse_wellseen_m`` on the part of the surface hit by at least ``well_k`` scans.
    Returns (scores, details for :func:`classify_worst`; None when no estimate is observed).
    """
    est = as_points(est, 2, "est", allow_empty=True)
    sdf, obs = _callable(sdf, "sdf"), _observed(obs)
    if well_k is not None:
        well_k = as_int(well_k, "well_k", minimum=0)
    est = est[obs.reached(est)] if len(est) else est
    if len(est) == 0:
        nan = float("nan")
        return {"surface_rmse_m": nan, "hausdorff_m": nan, "h_est_to_true_m": nan, "h_true_to_est_m": nan,
                "n_surface_points": 0}, None
    dA = np.abs(sdf(est))
    dB = cKDTree(est).query(obs.hits)[0]
    m = {"surface_rmse_m": float(np.sqrt(np.mean(dA ** 2))), "h_est_to_true_m": float(dA.max()),
         "h_true_to_est_m": float(dB.max()), "hausdorff_m": float(max(dA.max(), dB.max())),
         "p99_est_to_true_m": float(np.percentile(dA, 99)), "p99_true_to_est_m": float(np.percentile(dB, 99)),
         "n_surface_points": int(len(est))}
    if well_k is not None:
        wa = obs.count(est) >= well_k
        wb = obs.count(obs.hits) >= well_k
        ha = float(dA[wa].max()) if wa.any() else 0.0
        hb = float(dB[wb].max()) if wb.any() else 0.0
        m.update(hausdorff_wellseen_m=max(ha, hb),
                 surface_rmse_wellseen_m=float(np.sqrt(np.mean(dA[wa] ** 2))) if wa.any() else float("nan"))
    return m, {"est": est, "dA": dA, "dB": dB}


def classify_worst(details, sdf, obs: ObservedArea, corners, *, top=0.01, corner_r=0.3, sparse_k=3):
    """Where the worst surface errors are: the top ``top`` share of both directed errors of
    :func:`surface_scores_2d`, each located at its true surface point (an estimated point moved
    onto the true surface along the exact gradient; an observed true point is itself) and classed
    ``corner`` (within ``corner_r`` of a true corner), ``sparse`` (hit by fewer than ``sparse_k``
    scans) or ``wall`` (a well-seen flat stretch). Returns the shares and (points (k, 2), labels
    (k,) indexing :data:`WORST_CLASSES`)."""
    if details is not None and (not isinstance(details, dict) or not {"est", "dA", "dB"} <= set(details)):
        raise TypeError(f"details: expected None or the details of surface_scores_2d (est, dA, dB), "
                        f"got {type(details).__name__}")
    sdf, obs = _callable(sdf, "sdf"), _observed(obs)
    top = as_float(top, "top", minimum=0.0, maximum=1.0, exclusive_minimum=True)
    corner_r = as_float(corner_r, "corner_r", minimum=0.0)
    sparse_k = as_int(sparse_k, "sparse_k", minimum=0)
    corners = _corners(corners)
    if details is None:
        return {f"worst_{c}_share": float("nan") for c in WORST_CLASSES}, (np.zeros((0, 2)), np.zeros(0, int))
    est, dA, dB = details["est"], details["dA"], details["dB"]
    ia = np.argsort(-dA)[: max(1, int(np.ceil(top * len(dA))))]
    ib = np.argsort(-dB)[: max(1, int(np.ceil(top * len(dB))))]
    qa = est[ia]
    sd = sdf(qa)
    g = sdf_gradient(sdf, qa)
    g /= np.maximum(np.linalg.norm(g, axis=1), 1e-9)[:, None]
    q = np.vstack([qa - sd[:, None] * g, obs.hits[ib]])
    dc = cKDTree(corners).query(q)[0] if len(corners) else np.full(len(q), np.inf)
    cls = np.where(dc < corner_r, 0, np.where(obs.count(q) < sparse_k, 1, 2))
    return {f"worst_{c}_share": float(np.mean(cls == k)) for k, c in enumerate(WORST_CLASSES)}, (q, cls)


def class_report(err, var, classes, *, z=1.959964):
    """Per point class: what the map promises there and what it delivers.

    ``err`` (n,) signed errors; ``var`` (n,) the map's predicted variance (or None); ``classes``
    a dict ``name -> mask (n,)``. Returns one dict per class: ``n``, ``rmse_m``,
    ``median_abs_m``, ``p90_abs_m``, ``pred_std_median_m`` (median predicted sigma) and
    ``coverage95`` (share of points with |err| <= z sigma; the interval is calibrated when it is
    about 0.95).
    """
    err = _values(err, "err", finite=False)
    sd = None if var is None else np.sqrt(np.maximum(_values(var, "var", len(err), finite=False), 0.0))
    if not isinstance(classes, dict):
        raise TypeError(f"classes: expected a dict {{name: mask (n,)}}, got {type(classes).__name__}")
    z = as_positive_float(z, "z")
    out = []
    for name, mask in classes.items():
        mask = _flags(mask, f"classes[{name!r}]", len(err))
        e = err[mask]
        row = {"class": name, "n": int(mask.sum())}
        if len(e):
            a = np.abs(e)
            row.update(rmse_m=float(np.sqrt(np.mean(e * e))), median_abs_m=float(np.median(a)),
                       p90_abs_m=float(np.percentile(a, 90)))
            if sd is not None:
                row.update(pred_std_median_m=float(np.median(sd[mask])), coverage95=float(np.mean(a <= z * sd[mask])))
        out.append(row)
    return out


def object_map_scores(sdf_est, sdf_true, *, dist, visible, to_surface, vertex_grad, true_normals):
    """Accuracy of a 3D object map from arrays (see :class:`polar_sim.sim.recorders.orbits.ObjectTruth`).

    ``sdf_est``, ``sdf_true`` (k,): the map's and the exact SDF at points within 1 cm of the
    observed surface; ``dist`` (v,): distance of each reconstructed vertex to the true mesh;
    ``visible`` (v,) bool: its nearest true point was observed; ``to_surface`` (s,): distance from
    observed true surface samples to the reconstruction; ``vertex_grad`` (u, 3): the map's gradient
    at the visible vertices; ``true_normals`` (u, 3): the true normals there. Chamfer is the mean
    of the two directed means (``metrics.chamfer``'s definition).
    """
    sdf_est = _values(sdf_est, "sdf_est", finite=False)
    e = sdf_est - _values(sdf_true, "sdf_true", len(sdf_est))
    dist = _values(dist, "dist")
    visible = _flags(visible, "visible", len(dist))
    dA, dB = dist[visible], _values(to_surface, "to_surface")
    vertex_grad, true_normals = as_float_array(vertex_grad, "vertex_grad"), as_float_array(true_normals, "true_normals")
    if vertex_grad.ndim != 2 or vertex_grad.shape[1] != 3:
        raise ValueError(f"vertex_grad: expected shape (u, 3), got {vertex_grad.shape}")
    if true_normals.shape != vertex_grad.shape:
        raise ValueError(f"true_normals: expected the shape of vertex_grad {vertex_grad.shape}, got {true_normals.shape}")
    nan = float("nan")
    out = {"n_sdf_points": int(len(e)), "sdf_rmse_m": float(np.sqrt(np.mean(e * e))) if len(e) else nan,
           "sdf_median_abs_m": float(np.median(np.abs(e))) if len(e) else nan,
           "sdf_p90_abs_m": float(np.percentile(np.abs(e), 90)) if len(e) else nan,
           "n_vertices": int(len(dist)), "n_vertices_observed": int(visible.sum())}
    if not len(dA) or not len(dB):
        out.update(chamfer_m=nan, surface_to_mesh_m=nan, mesh_to_surface_m=nan, normal_median_deg=nan,
                   normal_mean_deg=nan)
        return out
    ang = _angles(vertex_grad, true_normals)
    out.update(surface_to_mesh_m=float(dA.mean()), mesh_to_surface_m=float(dB.mean()),
               chamfer_m=float(0.5 * (dA.mean() + dB.mean())), surface_to_mesh_max_m=float(dA.max()),
               surface_to_mesh_all_m=float(dist.mean()), normal_median_deg=float(np.median(ang)),
               normal_mean_deg=float(np.mean(ang)), normal_p90_deg=float(np.percentile(ang, 90)))
    return out


def map_scores_2d(query, surface, sdf, obs: ObservedArea, corners, *, n_eval=60_000, seed=0, well_k=10,
                  sparse_k=10, corner_r=0.3):
    """Every 2D score of one map, as the GPIS experiments report them.

    ``query(points) -> (d, grad, var or None)`` is the map's; ``surface`` (m, 2) its estimated
    surface points (or None); ``sdf`` the exact SDF; ``obs`` the observed area of the scans the map
    fused; ``corners`` (c, 2) the true corners. Scores: :func:`sdf_map_scores` on
    :func:`sample_eval_points`; ``near_rmse_wellseen_m`` (near points whose nearest true surface
    point is at least ``corner_r`` from a corner and was hit by at least ``well_k`` scans); a
    per-class report (:func:`class_report`) of the near set by where its nearest true surface
    point lies (corner / sparse: fewer than ``sparse_k`` scans / wall), with the 95 % coverage of
    the map's variance; :func:`surface_scores_2d` with ``well_k``; :func:`classify_worst` with
    ``sparse_k``. Returns (flat dict of scalars, dict of arrays for pictures).
    """
    query = _callable(query, "query")
    n_eval = as_int(n_eval, "n_eval", minimum=1, maximum=MAX_EVAL_POINTS)
    corner_r = as_float(corner_r, "corner_r", minimum=0.0)
    well_k, sparse_k = as_int(well_k, "well_k", minimum=0), as_int(sparse_k, "sparse_k", minimum=0)
    corners = _corners(corners)
    E = sample_eval_points(obs, sdf, n_eval, seed)
    d, g, var = query(E["P"])
    row, e = sdf_map_scores(d, g, E)
    near = E["near"]
    gn = E["G"] / np.maximum(np.linalg.norm(E["G"], axis=1), 1e-9)[:, None]
    q = E["P"] - E["gt"][:, None] * gn                      # nearest true surface point
    dc = cKDTree(corners).query(q)[0] if len(corners) else np.full(len(q), np.inf)
    cnt = obs.count(q)
    corner, sparse = dc < corner_r, (dc >= corner_r) & (cnt < sparse_k)
    well = near & (dc >= corner_r) & (cnt >= well_k)
    row["near_rmse_wellseen_m"] = float(np.sqrt(np.mean(e[well] ** 2))) if well.any() else float("nan")
    row["n_near_wellseen"] = int(well.sum())
    classes = {"all": near, "corner": near & corner, "sparse": near & sparse, "wall": near & ~corner & ~sparse}
    for c in class_report(e, var, classes):
        for k in ("rmse_m", "coverage95", "n"):
            if k in c:
                row[f"{c['class']}_{k}" if c["class"] != "all" else f"near_{k}"] = c[k]
    arrays = {"P": E["P"][near], "err": e[near]}
    if surface is not None:
        surf, det = surface_scores_2d(surface, sdf, obs, well_k=well_k)
        row.update(surf)
        shares, (wq, wcls) = classify_worst(det, sdf, obs, corners, corner_r=corner_r, sparse_k=sparse_k)
        row.update(shares)
        arrays.update(worst=wq, worst_cls=wcls, est=det["est"] if det else np.zeros((0, 2)),
                      dA=det["dA"] if det else np.zeros(0))
    return row, arrays
