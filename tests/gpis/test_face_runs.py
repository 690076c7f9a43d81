"""How far a scan's returns run on along a sample's face (``_scan2d.face_runs``), and the surface
gate's face end that uses it (issue 35, item 2): checked against exact ray casts of segments and
a circle, where the distance from each point to the end of its face is known."""

import numpy as np
import pytest

from polar_sim.gpis import GPISMap2D, _surface
from polar_sim.gpis._scan2d import RUNS, face_runs

from .test_surface_evidence import ANG, END, ROOM, WALL, _cast, _dist, _map

DTH = float(ANG[1] - ANG[0])


def _scan(segs, pose):
    """Sensor-frame returns of the beams ANG from pose (x, y, 0): phi, r (finite), end points."""
    r = _cast(segs, pose)
    ok = np.isfinite(r)
    phi, r = ANG[ok], r[ok]
    return phi, r, np.stack([r * np.cos(phi), r * np.sin(phi)], 1)


def _runs(p, n, phi, r):
    return face_runs(p, n, phi, r, DTH, **RUNS)


def test_a_concave_corner_ends_the_run_at_the_corner():
    # the room's corner (8, 0) seen from (5, 2): a floor-wall point x m before the corner has a
    # run of x toward it (its returns then climb the end wall) and runs on the other way
    phi, r, H = _scan(ROOM, (5.0, 2.0, 0.0))
    x = np.array([0.02, 0.05, 0.1, 0.15])
    p = np.stack([3.0 - x, np.full_like(x, -2.0)], 1)        # sensor frame: the floor wall y = -2
    n = np.tile([0.0, 1.0], (len(x), 1))                    # t = (-1, 0): toward -x
    run = _runs(p, n, phi, r)
    spacing = 2.0 * DTH / np.cos(np.arctan2(3.0, 2.0)) ** 2 * 1.0 + 0.01   # beam spacing there, m
    assert (np.abs(run[:, 1] - x) <= spacing).all()           # +x side (-t): to the corner
    assert (run[:, 0] >= RUNS["cap"]).all()                   # -x side (+t): the floor goes on


def test_a_face_that_goes_on_runs_to_the_cap_and_a_range_jump_stops_it():
    # a box 1 m wide at 3 m seen head on; its face runs on between its edges, and the run toward
    # an edge (an occluding edge: the next beam reaches the room's far wall) ends at the edge
    box = [((3.0, 1.5), (3.0, 2.5))]
    phi, r, H = _scan(ROOM + box, (0.5, 2.0, 0.0))
    p = np.array([[2.5, 0.0], [2.5, 0.4], [2.5, -0.45]])     # sensor frame: the face x = 2.5
    n = np.tile([-1.0, 0.0], (3, 1))                         # t = (0, -1)
    run = _runs(p, n, phi, r)
    assert (run[0] >= RUNS["cap"]).all()
    spacing = 2.5 * DTH * 1.05 + 0.005
    assert abs(run[1, 1] - 0.1) <= spacing and run[1, 0] >= RUNS["cap"]    # 0.1 m to the upper edge
    assert abs(run[2, 0] - 0.05) <= spacing and run[2, 1] >= RUNS["cap"]   # 0.05 m to the lower edge


def test_a_pillar_silhouette_runs_on():
    # along a 0.4 m circle the returns stay within 5 cm of a point's tangent for 0.19 m: enough
    # for the gate's full face end (the level follows the circle past the last sample there)
    c, rad = np.array([3.0, 0.0]), 0.4
    phi = ANG[np.abs(ANG) < 0.2]
    d = np.stack([np.cos(phi), np.sin(phi)], 1)
    b = d @ c
    disc = b * b - (c @ c - rad * rad)
    ok = disc > 0
    phi, r = phi[ok], (b - np.sqrt(np.maximum(disc, 0.0)))[ok]
    a = np.deg2rad([150.0, 180.0, 210.0])                    # facing the sensor, not at the silhouette
    p = c + rad * np.stack([np.cos(a), np.sin(a)], 1)
    n = (p - c) / rad
    run = _runs(p, n, phi, r)
    assert (run + _surface.FACE_RUN_MARGIN >= _surface.FACE_END).all()


def test_an_unseen_point_gets_no_run():
    phi, r, H = _scan(ROOM, (5.0, 2.0, 0.0))
    run = _runs(np.array([[0.0, 0.0], [1.0, 1.0]]), np.array([[1.0, 0.0], [0.0, 1.0]]), phi, r)
    assert (run == 0.0).all()


# -- the map's runs and the gate ----------------------------------------------------------------
@pytest.fixture(scope="module")
def wall_end():
    return _map(ROOM + WALL, [(0.5 + 0.1 * k, 1.2, 0.0) for k in range(40)])


def test_the_map_records_runs_that_end_at_the_corner(wall_end):
    # samples of the wall's lower face (y = 2) nearer its end (4, 2) than the cap: the run toward
    # the end is at most the exact distance to it (plus the beam spacing and the noise); farther
    # from both ends the face runs on, both ways
    t = wall_end.tree_
    i = t.alive()
    P, N, run = t.pos[i], t.nrm[i], t.run[i]
    face = (np.abs(P[:, 1] - 2.0) < 0.03) & (N[:, 1] < -0.9) & (P[:, 0] > 0.5)
    assert face.sum() >= 10
    toward_end = np.where(-N[face, 1] > 0, run[face, 0], run[face, 1])   # t = (-n_y, n_x) = +x
    gap = END[0] - P[face, 0]
    near = gap < RUNS["cap"]
    assert near.sum() >= 1
    assert (toward_end[near] <= gap[near] + 0.04).all()
    # a sample's normal is a few degrees off, so its tangent line leaves a straight wall too; the
    # runs still reach the gate's full face end
    mid = gap > RUNS["cap"] + 0.1
    assert mid.sum() >= 10
    assert (run[face][mid] + _surface.FACE_RUN_MARGIN >= _surface.FACE_END).all()


def test_without_runs_the_face_end_is_the_gate_before(wall_end):
    # runs of +inf (a map file before format version 3) give the face end it was built with: a
    # point is of its face's observed extent when between two of its samples or within face_end
    # of one (checked against that rule written out, at points along and beside the level)
    t = wall_end.tree_
    L = np.vstack(wall_end.surface(evidence=False))
    rng = np.random.default_rng(0)
    pts = L[rng.choice(len(L), 400, replace=False)] + rng.normal(0, 0.05, (400, 2))
    g = wall_end.query(pts)[1]
    g /= np.linalg.norm(g, axis=1)[:, None]
    saved = t.run.copy()
    try:
        t.run[:] = np.inf
        got = _surface._face_support(wall_end, pts, g, _surface.SUPPORT_RADIUS, _surface.FACE_END,
                                     _surface.FACE_END_BARE)[1]
    finally:
        t.run[:] = saved
    kd, idx = wall_end._kd()
    P, N = t.pos[idx], t.nrm[idx]
    want = np.zeros(len(pts), bool)
    for i, j in enumerate(kd.query_ball_point(pts, _surface.SUPPORT_RADIUS)):
        j = np.asarray(j, int)
        j = j[N[j] @ g[i] > np.cos(np.pi / 4)] if len(j) else j
        v = P[j] - pts[i]
        s = v[np.abs(v @ g[i]) <= _surface.FACE_END] @ np.array([-g[i, 1], g[i, 0]])
        want[i] = len(s) > 0 and (np.abs(s).min() <= _surface.FACE_END or s.min() < 0 < s.max())
    np.testing.assert_array_equal(got, want)
    assert 0 < want.sum() < len(want)
    assert (got >= _surface._face_support(wall_end, pts, g, _surface.SUPPORT_RADIUS, _surface.FACE_END,
                                          _surface.FACE_END_BARE)[1]).all()    # the runs only cut
    assert _dist(np.vstack(wall_end.surface()), ROOM + WALL).max() <= 0.10


def test_published_mode_records_no_runs():
    m = GPISMap2D.published()
    for p in [(0.5 + 0.1 * k, 1.2, 0.0) for k in range(5)]:
        m.update(ANG, _cast(ROOM + WALL, p), np.asarray(p, float))
    assert (m.tree_.run[m.tree_.alive()] == 0.0).all()


def _past_the_lower_face(m, points, runs=None):
    """Whether points (k, 2) near the wall's lower face (outward normal (0, -1)) are within reach of
    its samples, with the map's runs or, given ``runs``, with every run set to it."""
    g = np.tile([0.0, -1.0], (len(points), 1))
    args = (_surface.SUPPORT_RADIUS, _surface.FACE_END, _surface.FACE_END_BARE)
    t = m.tree_
    saved = t.run.copy()
    try:
        if runs is not None:
            t.run[:] = runs
        return _surface._face_support(m, np.asarray(points, float), g, *args)[1]
    finally:
        t.run[:] = saved


def _last_lower_face_sample(m):
    t = m.tree_
    i = t.alive()
    P, N = t.pos[i], t.nrm[i]
    face = (np.abs(P[:, 1] - 2.0) < 0.03) & (N[:, 1] < -0.9)
    return P[face][np.argmax(P[face, 0])]


def test_past_a_face_seen_to_end_the_reach_is_the_run(wall_end):
    # a point on the lower face's line 0.13 m past its last sample, i.e. past the wall's true end
    # (4, 2): with the runs the map recorded it is out of reach (the returns ended at the corner);
    # were every face to run on (the gate before the runs) it would be within face_end
    last = _last_lower_face_sample(wall_end)
    q = [[last[0] + 0.13, 2.0]]
    assert q[0][0] - END[0] >= 0.08                                   # off the true surface
    assert not _past_the_lower_face(wall_end, q)[0]
    assert _past_the_lower_face(wall_end, q, runs=np.inf)[0]


def test_a_run_vouches_only_near_the_samples_tangent_line(wall_end):
    # 5 cm past the last sample of the lower face, 4 cm below its line: within reach; 10 cm below
    # it (in free space, where the returns never lay): out of reach, however far the runs went
    last = _last_lower_face_sample(wall_end)
    assert _past_the_lower_face(wall_end, [[last[0] + 0.05, last[1] - 0.04]])[0]
    assert not _past_the_lower_face(wall_end, [[last[0] + 0.05, last[1] - 0.10]], runs=RUNS["cap"])[0]
