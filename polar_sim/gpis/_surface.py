"""Zero level set of a GPIS map: polylines in 2D (marching squares), a mesh in 3D (marching cubes).

In 2D (default mode) the zero level is returned only where the map has evidence for it
(:func:`gate_2d`): a vertex is left out when rays observed free space on its inside (the level
runs on past the end of an observed face, or through a surface that later scans saw through), when
it lies past the end of its face's samples or no sample of its face has a trusted normal, or when
the map's variance there is that of a region it knows nothing about. A sample left with no kept
vertex near it (a post whose normals the beam spacing cannot resolve) is returned as a point at its
measured position (:func:`_with_lone_samples`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polar_sim.gpis._localgp import GRAD_GATE as _TRUSTED_SG
from polar_sim.gpis._scan2d import RUNS

__all__ = ["surface_2d", "surface_3d", "grid_query", "gate_2d", "SurfaceEvidence",
           "FREE_DEPTH", "SUPPORT_RADIUS", "MIN_SUPPORT", "GATE_VAR", "FACE_END", "FACE_END_BARE",
           "FACE_RUN_MARGIN"]

#: Evidence gates of the 2D surface (default mode); each is also an argument of ``surface()``.
#: ``FREE_DEPTH`` (m): a vertex whose inside at this depth (along minus the map's gradient) lies
#: in observed free space is contradicted by the rays that crossed it. ``SUPPORT_RADIUS`` (m) and
#: ``MIN_SUPPORT``: a vertex needs this many samples of its face with a trusted normal within the
#: radius, and samples of its face on both sides along it or one within reach of its end (the
#: zero level of objects below the grid's resolution, :func:`_refined`, passes the variance gate
#: only: their normals are not resolved and a free-space cell is larger than they are). The reach
#: past a sample (:func:`_face_reach`) is ``FACE_END`` (m) where the scans' returns ran on along
#: the face past it, else how far they ran plus ``FACE_RUN_MARGIN`` (m), at least
#: ``FACE_END_BARE`` (m), and only near the sample's tangent line (``_LINE_OFF``). ``GATE_VAR``: a vertex where the map's variance reaches this is
#: unsupported (the prior is ``1 + map_noise``). Chosen on the dev seeds of office2d and
#: warehouse2d (benchmarks/RESULTS.md).
FREE_DEPTH, SUPPORT_RADIUS, MIN_SUPPORT, GATE_VAR, FACE_END = 0.05, 0.5, 1, 0.5, 0.175
FACE_END_BARE, FACE_RUN_MARGIN = 0.1, 0.03


def grid_query(m, axes, band, var_max, chunk=100_000):
    """SDF on the grid spanned by ``axes`` (indexing 'ij') at nodes within ``band`` of a sample.

    Returns (sdf, mask): nodes outside the band, or (legacy) with GP variance >= var_max, are
    masked out and hold +band.
    """
    mesh = np.meshgrid(*axes, indexing="ij")
    P = np.stack([g.ravel() for g in mesh], 1)
    kd, _ = m._kd()
    dist, _ = kd.query(P, k=1, distance_upper_bound=band)
    idx = np.nonzero(np.isfinite(dist))[0]
    sdf = np.full(len(P), band)
    keep = np.zeros(len(P), bool)
    for a in range(0, len(idx), chunk):
        j = idx[a:a + chunk]
        d, _, v = m.query(P[j])
        sdf[j] = d
        keep[j] = v < var_max
    shape = tuple(len(x) for x in axes)
    # cells touching an unevaluated node would see the +band filler: erode the mask by one node
    from scipy.ndimage import binary_erosion

    keep = binary_erosion(keep.reshape(shape), structure=np.ones((3,) * len(shape), bool),
                          border_value=0)
    return sdf.reshape(shape), keep


def _jumps(sdf, res, k=2.0):
    """Nodes of grid cells whose sign change is a jump, not a zero crossing.

    A distance field changes by at most ``res * sqrt(2)`` across a cell, so at a true zero
    crossing every corner lies within that of zero; a cell with a sign change and a corner beyond
    ``k`` times it straddles a discontinuity of the field (the surfel distance changes sign
    where a point passes the plane of a surfel beyond its rim), which marching squares would
    turn into a spurious surface."""
    a, b, c, d = sdf[:-1, :-1], sdf[1:, :-1], sdf[:-1, 1:], sdf[1:, 1:]
    lo = np.minimum(np.minimum(a, b), np.minimum(c, d))
    hi = np.maximum(np.maximum(a, b), np.maximum(c, d))
    big = np.maximum(np.maximum(np.abs(a), np.abs(b)), np.maximum(np.abs(c), np.abs(d)))
    bad = (lo < 0) & (hi > 0) & (big > k * np.sqrt(2.0) * res)
    out = np.zeros(sdf.shape, bool)
    out[:-1, :-1] |= bad
    out[1:, :-1] |= bad
    out[:-1, 1:] |= bad
    out[1:, 1:] |= bad
    return out


#: Grid nodes :meth:`surface` evaluates at most (about 60 bytes each while it runs).
MAX_SURFACE_NODES = 1 << 24


def _axes(m, res, margin):
    """Grid axes over the samples' bounding box; ``ValueError`` naming ``res`` and the limit
    when the grid would exceed :data:`MAX_SURFACE_NODES` (checked before anything is allocated)."""
    if not (np.isfinite(res) and res > 0):
        raise ValueError(f"res: expected a finite grid step > 0 m, got {res!r}")
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError(f"band: expected a finite band >= 0 m, got {margin!r}")
    pts = m.samples()["points"]
    lo = np.floor((pts.min(0) - margin) / res) * res
    hi = np.ceil((pts.max(0) + margin) / res) * res
    n = np.prod([float(x) for x in np.floor((hi - lo) / res + 1.5)])
    if not n <= MAX_SURFACE_NODES:
        raise ValueError(f"res: a surface grid of {n:.3g} nodes at res={res:g} m over the map's "
                         f"{np.round(hi - lo, 3).tolist()} m extent is over the limit of "
                         f"{MAX_SURFACE_NODES} nodes (MAX_SURFACE_NODES); raise res")
    return [np.arange(a, b + 0.5 * res, res) for a, b in zip(lo, hi)]


def surface_2d(m, res, band, var_max, gates=None):
    """List of polylines (k, 2) along the zero level of the map's query, near observed samples;
    (default mode) with the zero level of objects smaller than ``res`` (:func:`_refined`), where
    a (1, 2) array is a point at which the level only touches zero. With ``gates`` (a dict of
    :func:`gate_2d`'s keywords; default mode only) the :class:`SurfaceEvidence` of the level,
    split where the map has no evidence for it."""
    from skimage.measure import find_contours

    if len(m.tree_.alive()) == 0:
        return [] if gates is None else gated_2d(m, [])
    axes = _axes(m, res, 2 * res + band)
    sdf, mask = grid_query(m, axes, band, var_max)
    if not m._pub("query_mode"):
        mask = mask & ~_jumps(sdf, res)
    lines = find_contours(sdf, 0.0, mask=mask)
    x0 = np.array([a[0] for a in axes])
    out = [x0 + c * res for c in lines if len(c) >= 2]
    small = []
    if not m._pub("query_mode"):
        # closed loops shorter than 4 grid steps enclose at most a cell or two: bubbles of the
        # field's sign (a spurious zero between samples), not a surface the grid can resolve
        out = [ln for ln in out if not _bubble(ln, res)]
        small = _refined(m, out, res)
    if gates is None:
        return out + small
    # an object below the grid's resolution (a post a few cm across) is a sample or two whose
    # normals the beam spacing cannot resolve, inside one free-space cell: only the variance gate
    # can judge it
    lone = gates.pop("lone", False)
    ev = gated_2d(m, out, **gates)
    sv = gated_2d(m, small, **{**gates, "free_depth": None, "min_support": 0})
    ev = SurfaceEvidence(*(a + b for a, b in zip(_fields(ev), _fields(sv))))
    return _with_lone_samples(m, ev, LONE_REACH * res, gates) if lone else ev


#: A sample farther than this many grid steps from every kept vertex is returned as a point.
LONE_REACH = 2


def _with_lone_samples(m, ev, reach, gates):
    """``ev`` with every sample that has no kept vertex within ``reach`` (m) appended as a (1, 2)
    point at its fused position.

    Such a sample is a surface the sensor measured but whose extent the map cannot vouch for: most
    often a post or a rack's upright a few cm across, hit by many scans, whose one or two samples
    have no trusted normal (the beam spacing cannot resolve it), so that the level around it fails
    the support gate and the post would be missing entirely, metres from any returned point. Its
    measured position is evidence; the level the GP rounds around it is not. A sample's support is
    counted as a vertex's is (trusted samples within ``support_radius``, no face test), its sigma is
    its own fused position noise."""
    from scipy.spatial import cKDTree

    idx = m.tree_.alive()
    P = m.tree_.pos[idx]
    if ev.lines:
        far = cKDTree(np.vstack(ev.lines)).query(P, distance_upper_bound=reach)[0] > reach
        P, idx = P[far], idx[far]
    if not len(P):
        return ev
    kd, kidx = m._kd()
    trusted = m.tree_.sg[kidx] <= _TRUSTED_SG
    near = kd.query_ball_point(P, gates["support_radius"], return_sorted=False)
    support = [int(trusted[np.asarray(j, np.int64)].sum()) for j in near]
    sigma = np.sqrt(m.tree_.sp[idx])
    return SurfaceEvidence(ev.lines + [p[None].copy() for p in P], ev.support + [np.array([k]) for k in support],
                           ev.sigma + [np.array([s]) for s in sigma], ev.rejected, ev.reason)


def _bubble(line, res):
    """A closed polyline shorter than 4 grid steps ``res``."""
    return bool(np.allclose(line[0], line[-1]) and np.linalg.norm(np.diff(line, axis=0), axis=1).sum() < 4 * res)


#: Refinement of :func:`surface_2d` around samples its grid misses: the finer step (a share of
#: ``res``) and the window's half-width (in ``res``).
REFINE_STEP, REFINE_HALF = 0.2, 3


def _refined(m, lines, res):
    """The zero level of objects smaller than the grid resolves (a post a few cm across, seen
    end-on, whose zero level at ``res`` is a bubble or no crossing at all).

    Around every sample with no polyline within ``2 res``: the zero level of a window of
    ``REFINE_HALF`` res at ``REFINE_STEP`` res, its own bubbles dropped; a sample that still has
    no polyline near it but where the map is zero (within the finer step) is a point of the zero
    level that only touches zero, returned as a (1, 2) array."""
    from scipy.spatial import cKDTree
    from skimage.measure import find_contours

    P = m.samples()["points"]
    fine, half = REFINE_STEP * res, REFINE_HALF * res
    if len(lines):
        orphan = P[cKDTree(np.vstack(lines)).query(P, distance_upper_bound=2 * res)[0] > 2 * res]
    else:
        orphan = P
    if not len(orphan):
        return []
    ax = np.arange(-half, half + 0.5 * fine, fine)
    win = np.stack(np.meshgrid(ax, ax, indexing="ij"), -1).reshape(-1, 2)
    kd = cKDTree(orphan)
    out, covered = [], np.zeros(len(orphan), bool)
    for i, c in enumerate(orphan):
        if covered[i]:
            continue
        inside = np.array(kd.query_ball_point(c, 0.8 * half), int)   # one window per cluster
        covered[inside] = True
        sdf = m.query(win + c)[0].reshape(len(ax), len(ax))
        found = [ln for ln in (c - half + k * fine for k in find_contours(sdf, 0.0))
                 if len(ln) >= 2 and not _bubble(ln, fine)]
        out += found
        q = orphan[inside]
        if found:
            q = q[cKDTree(np.vstack(found)).query(q, distance_upper_bound=2 * fine)[0] > 2 * fine]
        if len(q):
            out += [p[None] for p, d in zip(q, m.query(q)[0]) if abs(d) < fine]
    return out


def surface_3d(m, res, band, var_max):
    """trimesh.Trimesh of the zero level near observed samples (marching cubes)."""
    import trimesh
    from skimage.measure import marching_cubes

    if len(m.tree_.alive()) == 0:
        return trimesh.Trimesh()
    axes = _axes(m, res, 2 * res + band)
    sdf, mask = grid_query(m, axes, band, var_max)
    if not ((sdf[mask] > 0).any() and (sdf[mask] < 0).any()):
        return trimesh.Trimesh()
    verts, faces, normals, _ = marching_cubes(sdf, 0.0, spacing=(res,) * 3, mask=mask,
                                              gradient_direction="ascent")
    x0 = np.array([a[0] for a in axes])
    return trimesh.Trimesh(verts + x0, faces[:, ::-1], vertex_normals=normals, process=False)


@dataclass(frozen=True)
class SurfaceEvidence:
    """The 2D zero level with its evidence (``surface(..., return_evidence=True)``).

    Attributes
    ----------
    lines : list of ndarray (k, 2)
        The polylines ``surface()`` returns (world metres; a (1, 2) entry is a point).
    support : list of ndarray (k,) of int
        Per vertex of ``lines``: how many samples of its face with a trusted normal lie within
        the support radius (the evidence count).
    sigma : list of ndarray (k,)
        Per vertex of ``lines``: the fused position standard deviation of the nearest such
        sample, metres (how well the map knows where the surface is there).
    rejected : list of ndarray (k, 2)
        The pieces of the zero level left out, each with the kept vertices it joined.
    reason : list of str
        Per rejected piece, the gate most of its vertices failed: ``"free"`` (observed free space
        on its inside), ``"support"`` (too few trusted samples near) or ``"variance"``.
    """

    lines: list
    support: list
    sigma: list
    rejected: list
    reason: list


def _fields(ev):
    """The fields of a :class:`SurfaceEvidence`, in order (no deep copy, unlike dataclasses.astuple)."""
    return ev.lines, ev.support, ev.sigma, ev.rejected, ev.reason


_REASONS = ("free", "support", "variance")
_OFF = {"free_depth": None, "support_radius": SUPPORT_RADIUS, "min_support": 0, "var_max": np.inf,
        "face_end": FACE_END, "face_end_bare": FACE_END_BARE}


def gate_args(m, evidence, free_depth, support_radius, min_support, gate_var, return_evidence,
              face_end=None, face_end_bare=None):
    """The checked gates of ``surface()``: a dict of :func:`gate_2d`'s keywords, or None for the
    plain zero level (3D, or the gates off and no evidence asked for)."""
    from polar_sim._validation import as_int, as_positive_float

    given = {k: v for k, v in (("free_depth", free_depth), ("support_radius", support_radius),
                               ("min_support", min_support), ("gate_var", gate_var),
                               ("face_end", face_end), ("face_end_bare", face_end_bare)) if v is not None}
    if m.dim == 3:
        bad = [k for k, v in (("evidence", evidence), ("return_evidence", return_evidence or None))
               if v is not None] + list(given)
        if bad:
            raise ValueError(f"{bad[0]}: the evidence gates are 2D only (a 3D surface is a mesh)")
        return None
    for k, v in (("evidence", evidence), ("return_evidence", return_evidence)):
        if v is not None and not isinstance(v, (bool, np.bool_)):
            raise TypeError(f"{k}: expected a bool, got {type(v).__name__}")
    on = (not m._pub("query_mode")) if evidence is None else bool(evidence)
    gates = {"free_depth": FREE_DEPTH, "support_radius": SUPPORT_RADIUS, "min_support": MIN_SUPPORT,
             "var_max": GATE_VAR, "face_end": FACE_END, "face_end_bare": FACE_END_BARE}
    if "free_depth" in given:
        gates["free_depth"] = as_positive_float(free_depth, "free_depth")
    if "support_radius" in given:
        gates["support_radius"] = as_positive_float(support_radius, "support_radius")
    if "min_support" in given:
        gates["min_support"] = as_int(min_support, "min_support", minimum=0, maximum=10_000)
    if "gate_var" in given:
        gates["var_max"] = as_positive_float(gate_var, "gate_var")
    if "face_end" in given:
        gates["face_end"] = as_positive_float(face_end, "face_end")
    if "face_end_bare" in given:
        gates["face_end_bare"] = as_positive_float(face_end_bare, "face_end_bare")
    if on:
        return {**gates, "lone": True}
    return dict(_OFF) if return_evidence else None


def _face_support(m, pts, g, reach, end, bare):
    """Per point: the samples of its face within ``reach`` with a trusted normal (n,), and whether
    the point lies between two samples of its face (trusted or not: each is an observed point of
    it) along the face or within reach of one's end, i.e. not past the end of the observed face.

    A sample is of the point's face when its normal is within 45 deg of the map's gradient ``g``
    at the point and it lies within ``end`` of the point's tangent line; its coordinate along
    the face is its offset along that tangent. A point past a sample is within its reach when
    closer than :func:`_face_reach` of the runs the scans saw on that side of it, and within
    ``_LINE_OFF`` of the sample's tangent line."""
    kd, idx = m._kd()
    t = m.tree_
    P, N = t.pos[idx], t.nrm[idx]
    trusted = t.sg[idx] <= _TRUSTED_SG
    count = np.zeros(len(pts), np.int64)
    ok = np.zeros(len(pts), bool)
    tan = np.column_stack([-g[:, 1], g[:, 0]])
    for i, j in enumerate(kd.query_ball_point(pts, reach, return_sorted=False)):
        j = np.asarray(j, np.int64)
        if not len(j):
            continue
        j = j[N[j] @ g[i] > np.cos(np.pi / 4)]
        v = P[j] - pts[i]
        on = np.abs(v @ g[i]) <= end
        s = v[on] @ tan[i]
        count[i] = int(trusted[j[on]].sum())
        if not len(s):
            continue
        if s.min() < 0 < s.max():
            ok[i] = True
            continue
        jo = j[on]
        # which side of each sample (along its own tangent) the point lies on, and that side's run
        side = (N[jo, 0] * v[on, 1] - N[jo, 1] * v[on, 0]) > 0.0      # the point on the sample's -t
        run = t.run[idx[jo], side.astype(np.int64)]
        # a run vouches for the face along the sample's tangent line, where its returns lay (+inf:
        # no runs recorded, a map file before version 3: the face end as it was built)
        off = np.abs(np.einsum("ij,ij->i", v[on], N[jo])) / np.maximum(np.linalg.norm(N[jo], axis=1), 1e-12)
        near = (off <= _LINE_OFF) | np.isinf(run)
        ok[i] = bool(((np.abs(s) <= _face_reach(run, end, bare)) & near).any())
    return count, ok


#: m: how far off a sample's tangent line a point past it may lie and still be of its face: the
#: runs' own tolerance (their returns lay within RUNS["dev"] of the line) plus the margin
_LINE_OFF = RUNS["dev"] + FACE_RUN_MARGIN


def _face_reach(run, end, bare):
    """How far past a sample the zero level is its face's (m), given the run (m) its scans saw on
    that side: ``end`` where the returns ran on to ``RUNS["cap"]`` (a face that goes on, such as a
    pillar's silhouette, whose samples stop before its returns do), else the run plus
    ``FACE_RUN_MARGIN`` (the level's grid step and the range noise), at least ``bare`` (a face
    whose end no scan saw well: a corner's, where the returns leave the face)."""
    return np.where(run >= RUNS["cap"], end, np.minimum(end, np.maximum(bare, run + FACE_RUN_MARGIN)))


def gate_2d(m, pts, *, free_depth=FREE_DEPTH, support_radius=SUPPORT_RADIUS,
            min_support=MIN_SUPPORT, var_max=GATE_VAR, face_end=FACE_END, face_end_bare=FACE_END_BARE):
    """Evidence for the zero level at points ``pts`` (n, 2) of a 2D map.

    A point fails ``"free"`` when observed free space lies ``free_depth`` inside it (along minus
    the map's gradient); ``"support"`` when fewer than ``min_support`` samples of its face with a
    trusted normal lie within ``support_radius``, or when it lies past the end of its face:
    neither between two of its samples along the face nor within reach of one (``face_end``
    where the scans' returns ran on along the face past it, else their run plus
    ``FACE_RUN_MARGIN``, at least ``face_end_bare``; :func:`_face_reach`; and within
    ``_LINE_OFF`` of the sample's tangent line);
    ``"variance"`` when the map's variance there reaches ``var_max``. ``free_depth`` None turns
    the free-space gate off, ``min_support`` 0 the support gate and ``var_max`` inf the variance
    gate. Returns (fail (n,) int: 0 = kept, else 1 + the index of the first failed gate in
    ``("free", "support", "variance")``; support (n,) int; sigma (n,) m)."""
    pts = np.ascontiguousarray(pts, float).reshape(-1, 2)
    n = len(pts)
    fail = np.zeros(n, np.int64)
    if n == 0:
        return fail, np.zeros(0, np.int64), np.zeros(0)
    _, g, var = m.query(pts)
    g = g / np.maximum(np.linalg.norm(g, axis=1), 1e-12)[:, None]    # blended: not always unit
    support, inside = _face_support(m, pts, g, support_radius, face_end, face_end_bare)
    kd, idx = m._kd()
    t = m.tree_
    trusted = t.sg[idx] <= _TRUSTED_SG
    # sigma: the nearest trusted sample's fused position noise (nearest of any when none is trusted)
    _, j = kd.query(pts, k=min(4, len(idx)))
    j = j.reshape(n, -1)
    tj = trusted[j]
    first = np.where(tj.any(1), tj.argmax(1), 0)
    sigma = np.sqrt(t.sp[idx[j[np.arange(n), first]]])
    free = m.free_.observed(pts - free_depth * g) if free_depth is not None else np.zeros(n, bool)
    unsupported = (support < min_support) | (~inside if min_support > 0 else False)
    bad = [free, unsupported, var >= var_max]
    for k in range(len(bad) - 1, -1, -1):           # the first failed gate wins
        fail[bad[k]] = k + 1
    return fail, support, sigma


def _runs(ok):
    """(start, stop) of the runs of True in a 1-D bool array."""
    e = np.diff(np.concatenate([[0], ok.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(e == 1), np.flatnonzero(e == -1)))


def gated_2d(m, lines, **gates):
    """Split polylines at the vertices that fail :func:`gate_2d`: a :class:`SurfaceEvidence`."""
    if not lines:
        return SurfaceEvidence([], [], [], [], [])
    sizes = [len(ln) for ln in lines]
    fail, support, sigma = gate_2d(m, np.vstack(lines), **gates)
    cut = np.cumsum(sizes)[:-1]
    out = SurfaceEvidence([], [], [], [], [])
    for ln, f, s, sg in zip(lines, np.split(fail, cut), np.split(support, cut), np.split(sigma, cut)):
        ok = f == 0
        for a, b in _runs(ok):
            if b - a >= 2 or len(ln) == 1:
                out.lines.append(ln[a:b])
                out.support.append(s[a:b])
                out.sigma.append(sg[a:b])
        for a, b in _runs(~ok):
            lo, hi = max(a - 1, 0), min(b + 1, len(ln))     # with the segments to the kept vertices
            out.rejected.append(ln[lo:hi])
            out.reason.append(_REASONS[int(np.bincount(f[a:b], minlength=4)[1:].argmax())])
    return out
