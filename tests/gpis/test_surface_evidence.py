"""surface() in 2D returns the zero level only where the map has evidence for it (issue 35, item 2):
checked against exact ray casting and the exact distance to the scenes' segments."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from polar_sim.gpis import GPISMap2D, GPISMap3D, _surface

from .scenes import observed_hits_2d, room_path, scan_2d, sdf_2d, wall_points_2d

ANG = np.deg2rad(np.arange(-135.0, 135.0, 0.25))       # the simulator's 1081-beam lidar
ROOM = [((0, 0), (8, 0)), ((8, 0), (8, 6)), ((8, 6), (0, 6)), ((0, 6), (0, 0))]


def _box(x0, y0, x1, y1):
    return [((x0, y0), (x1, y0)), ((x1, y0), (x1, y1)), ((x1, y1), (x0, y1)), ((x0, y1), (x0, y0))]


def _cast(segs, pose):
    """Exact ranges (n,) of the beams ANG from pose (x, y, theta) to the segments."""
    s = np.asarray(segs, float)
    a, e = s[:, 0], s[:, 1] - s[:, 0]
    d = np.stack([np.cos(pose[2] + ANG), np.sin(pose[2] + ANG)], 1)
    w = a[None] - np.asarray(pose[:2], float)[None, None]
    den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[None, :, 1] - w[..., 1] * e[None, :, 0]) / den
        u = (w[..., 0] * d[:, None, 1] - w[..., 1] * d[:, None, 0]) / den
    return np.where((t > 1e-9) & (u >= 0) & (u <= 1) & np.isfinite(t), t, np.inf).min(1)


def _dist(p, segs):
    """Exact distance (n,) from points p to the nearest segment."""
    out = np.full(len(p), np.inf)
    for a, b in np.asarray(segs, float):
        e = b - a
        t = np.clip(((p - a) @ e) / (e @ e), 0, 1)
        out = np.minimum(out, np.linalg.norm(p - (a + t[:, None] * e), axis=1))
    return out


def _map(segs, poses, seed=0):
    rng = np.random.default_rng(seed)
    m = GPISMap2D()
    for p in poses:
        m.update(ANG, _cast(segs, p) + rng.normal(0, 0.01, len(ANG)), np.asarray(p, float))
    return m


# -- a wall end past a corner -------------------------------------------------------------------
# a 15 cm wall from the left wall of the room to x = 4 (a doorway's jamb), seen from a drive below
# it, along it and past its end: the lower face's zero level runs on past the corner at (4, 2)
WALL = _box(0.0, 2.0, 4.0, 2.15)
END = np.array([4.0, 2.0])


@pytest.fixture(scope="module")
def wall_end():
    return _map(ROOM + WALL, [(0.5 + 0.1 * k, 1.2, 0.0) for k in range(40)])


def test_wall_end_stops_at_the_corner(wall_end):
    P = np.vstack(wall_end.surface())
    near = np.linalg.norm(P - END, axis=1) < 0.5
    assert near.sum() >= 5                                         # the face is returned up to the end
    assert _dist(P[near], ROOM + WALL).max() <= 0.10              # and stops within 10 cm of it
    assert _dist(P, ROOM + WALL).max() <= 0.10                    # nothing else strays either


def test_without_the_gates_the_level_runs_past_the_end(wall_end):
    # the test above can fail: the ungated level lies more than 10 cm off past the corner
    P = np.vstack(wall_end.surface(evidence=False))
    near = np.linalg.norm(P - END, axis=1) < 0.5
    assert _dist(P[near], ROOM + WALL).max() > 0.10


def test_rejected_pieces_say_why(wall_end):
    ev = wall_end.surface(return_evidence=True)
    assert ev.rejected and set(ev.reason) <= {"free", "support", "variance"}
    assert len(ev.reason) == len(ev.rejected)
    # kept and rejected vertices together are exactly the ungated level's vertices; what else is
    # returned are lone samples: points at a sample's position, two grid steps from every kept vertex
    raw = np.vstack(wall_end.surface(evidence=False))
    of_level = [cKDTree(raw).query(ln)[0].max() == 0.0 for ln in ev.lines]
    level = [ln for ln, k in zip(ev.lines, of_level) if k]
    both = np.vstack(level + ev.rejected)
    assert cKDTree(both).query(raw)[0].max() == 0.0
    assert cKDTree(raw).query(both)[0].max() == 0.0
    S = wall_end.samples()
    for ln, s, sg, k in zip(ev.lines, ev.support, ev.sigma, of_level):
        assert s.shape == sg.shape == (len(ln),)
        if k and len(ln) == 1:  # a sub-grid object's point (_refined: at a sample where the level
            # touches zero), which the support count does not judge: the sample's position sigma
            assert cKDTree(S["points"]).query(ln)[0][0] < 1e-6 and 0 < sg[0] < 0.05
        elif k:     # the evidence per vertex: trusted samples within the support radius, a position sigma
            assert (s >= _surface.MIN_SUPPORT).all() and (sg > 0).all() and (sg < 0.05).all()
        else:       # a lone sample, with its own position sigma
            d, j = cKDTree(S["points"]).query(ln)
            assert ln.shape == (1, 2) and d[0] == 0.0 and sg[0] == np.sqrt(S["position_noise"][j[0]])
            assert cKDTree(np.vstack(level)).query(ln)[0].min() > _surface.LONE_REACH * 0.05
    assert [np.array_equal(a, b) for a, b in zip(ev.lines, wall_end.surface())] == [True] * len(ev.lines)


# -- a wall glimpsed by two scans -----------------------------------------------------------------
# a box face 1 m away is in view for two scans only; then the robot turns and drives along the floor
# wall (y = 0), 1 m away, for 30 scans (a partition at x = 2.5 hides the box)
GLIMPSE = _box(1.0, 2.0, 2.0, 2.3)
HIDE = [((2.5, 1.2), (2.5, 4.0))]


@pytest.fixture(scope="module")
def glimpse():
    poses = [(1.5, 1.0, np.pi / 2)] * 2 + [(3.0 + 0.1 * k, 1.0, -np.pi / 2) for k in range(30)]
    return _map(ROOM + GLIMPSE + HIDE, poses, seed=1)


def test_a_glimpsed_wall_is_not_returned(glimpse):
    # two scans 1 m away give its samples no trusted normal (normal variance above the local GPs'
    # gate): the zero level there is the GP's guess, not evidence, and is left out; only the
    # measured samples themselves may come back, as lone points on the face
    ev = glimpse.surface(return_evidence=True)
    L = np.vstack([ln for ln in ev.lines if len(ln) > 1])
    assert not (_dist(L, [GLIMPSE[0]]) < 0.05).any()
    pts = np.vstack([ln for ln in ev.lines if len(ln) == 1] + [np.zeros((0, 2))])
    assert (_dist(pts, ROOM + GLIMPSE + HIDE) <= 0.05).all()
    out = [r for r, why in zip(ev.rejected, ev.reason) if (_dist(r, [GLIMPSE[0]]) < 0.05).any()]
    assert out and all(why == "support" for r, why in zip(ev.rejected, ev.reason)
                       if (_dist(r, [GLIMPSE[0]]) < 0.05).mean() > 0.5)
    # the floor wall at the same range, seen by 30 scans, is returned, true and well known
    seen = (np.abs(L[:, 1]) < 0.03) & (L[:, 0] > 3.2) & (L[:, 0] < 5.5)
    assert seen.sum() >= 20
    assert _dist(L, ROOM + GLIMPSE + HIDE).max() <= 0.10
    sigma = np.concatenate([sg for ln, sg in zip(ev.lines, ev.sigma) if len(ln) > 1])
    assert np.median(sigma[seen]) <= 0.01        # the 1 cm range noise, fused


def test_without_the_gates_the_glimpsed_wall_is_returned(glimpse):
    # the test above can fail: the ungated level has the glimpsed face
    L = np.vstack(glimpse.surface(evidence=False))
    assert (_dist(L, [GLIMPSE[0]]) < 0.05).sum() >= 5


# -- a post too thin for a trusted normal -------------------------------------------------------
# a 10 cm post 10 m down a 20 m hall, hit by all of 30 scans: the 1081-beam lidar puts two or three
# beams on it, its one sample has no trusted normal, and the level around it fails the support gate
HALL = [((0, 0), (20, 0)), ((20, 0), (20, 6)), ((20, 6), (0, 6)), ((0, 6), (0, 0))]
POST = _box(12.0, 3.0, 12.1, 3.1)


def test_a_well_seen_post_is_returned():
    m = _map(HALL + POST, [(1.0 + 0.1 * k, 1.5, 0.0) for k in range(30)])
    ev = m.surface(return_evidence=True)
    P = np.vstack(ev.lines)
    assert _dist(P, POST).min() <= 0.02                    # the post is there, at its measured position
    assert _dist(P, HALL + POST).max() <= 0.10             # and nothing strays
    # the level's own vertices leave it out (the cause): it comes back as a lone sample
    L = np.vstack([ln for ln in ev.lines if len(ln) > 1])
    assert _dist(L, POST).min() > 1.0
    assert (_dist(np.vstack(m.surface(evidence=False)), POST) < 0.05).any()


# -- a well-seen room ---------------------------------------------------------------------------
ANG1 = np.deg2rad(np.arange(-135.0, 135.0, 1.0))


@pytest.fixture(scope="module")
def room():
    rng = np.random.default_rng(0)
    path = room_path(60)
    m = GPISMap2D()
    for pose in path:
        m.update(ANG1, scan_2d(pose, ANG1, noise=0.01, rng=rng), pose)
    return m, path


def _well_seen(path, k=10, max_incidence=60.0, corner_r=0.3):
    """True surface points hit by >= k of the drive's scans at incidence <= max_incidence, farther
    than corner_r from a corner of the room or the box: every such point lies between samples of
    its face with trusted normals, 0.2 m apart along it (so within the support gate), and rays end
    at its face (so no observed free space lies behind it)."""
    W = wall_points_2d(0.02)
    hits = np.zeros(len(W), int)
    for pose in path:
        r = scan_2d(pose, ANG1)
        a = pose[2] + ANG1
        H = pose[:2] + r[:, None] * np.stack([np.cos(a), np.sin(a)], 1)
        ok = np.isfinite(r)
        g = (sdf_2d(H[ok] + [1e-5, 0]) - sdf_2d(H[ok] - [1e-5, 0]), sdf_2d(H[ok] + [0, 1e-5]) - sdf_2d(H[ok] - [0, 1e-5]))
        g = np.stack(g, 1)
        g /= np.linalg.norm(g, axis=1)[:, None]
        d = np.stack([np.cos(a[ok]), np.sin(a[ok])], 1)
        inc = np.degrees(np.arccos(np.clip(-np.einsum("ij,ij->i", d, g), -1, 1)))
        Hok = H[ok][inc <= max_incidence]
        j = np.unique(cKDTree(W).query(Hok, distance_upper_bound=0.02)[1])
        hits[j[j < len(W)]] += 1
    corners = np.array([[0, 0], [8, 0], [8, 6], [0, 6], [5, 1], [6, 1], [6, 2], [5, 2]], float)
    return W[(hits >= k) & (cKDTree(corners).query(W)[0] > corner_r)]


def test_well_seen_room_is_claimed_and_true(room):
    m, path = room
    L = np.vstack(m.surface())
    # every returned point within 10 cm of the exact zero level
    assert np.abs(sdf_2d(L)).max() <= 0.10
    # the claimed surface still covers every well-seen wall point (within 10 cm)
    W = _well_seen(path)
    assert len(W) > 500
    assert cKDTree(L).query(W)[0].max() <= 0.10
    # and the observed surface as a whole within the 10 cm the ungated level met (corners included)
    seen = observed_hits_2d(path, step_deg=0.5)
    assert np.mean(cKDTree(L).query(seen)[0] <= 0.10) >= 0.97


# -- arguments and modes ------------------------------------------------------------------------
def test_gate_arguments_are_checked(wall_end):
    before = [ln.copy() for ln in wall_end.surface()]
    for kw, exc in [({"free_depth": -0.1}, ValueError), ({"free_depth": np.inf}, ValueError),
                    ({"support_radius": 0.0}, ValueError), ({"min_support": 1.5}, TypeError),
                    ({"min_support": -1}, ValueError), ({"gate_var": np.nan}, ValueError),
                    ({"face_end": 0}, ValueError), ({"face_end_bare": -0.1}, ValueError),
                    ({"face_end_bare": "0.1"}, TypeError),
                    ({"evidence": "yes"}, TypeError), ({"return_evidence": 1}, TypeError)]:
        with pytest.raises(exc, match=next(iter(kw))):
            wall_end.surface(**kw)
    after = wall_end.surface()
    assert len(after) == len(before) and all(np.array_equal(a, b) for a, b in zip(after, before))


def test_gates_are_arguments(wall_end):
    # a looser support gate and no free-space gate let more of the level through
    n = sum(map(len, wall_end.surface()))
    loose = wall_end.surface(free_depth=0.5, min_support=0, gate_var=2.0, face_end=1.0, face_end_bare=1.0)
    assert sum(map(len, loose)) > n


def test_published_mode_is_ungated():
    m = GPISMap2D.published()
    segs = ROOM + WALL
    for p in [(1.0 + 2.5 * k / 11, 1.0, 0.6) for k in range(12)]:
        m.update(ANG, _cast(segs, p), np.asarray(p, float))
    a, b = m.surface(), m.surface(evidence=False)
    assert len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b))
    assert len(m.surface(evidence=True)) >= 1


def test_3d_refuses_the_2d_gates():
    m = GPISMap3D()
    with pytest.raises(ValueError, match="return_evidence"):
        m.surface(return_evidence=True)
