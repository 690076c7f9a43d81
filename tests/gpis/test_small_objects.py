"""surface() keeps objects smaller than its grid resolves: a post 4 cm across, scanned from one
side, which the 5 cm grid alone drops (a bubble, or a level that only touches zero)."""

import numpy as np
import pytest

from polar_sim.gpis import GPISMap2D, _surface

POST, R_POST = np.array([2.0, 0.3]), 0.02       # a post 4 cm across, 2 m ahead
WALL_X = 4.0                                     # a wall behind it
ANG = np.deg2rad(np.arange(-135.0, 135.0, 0.25))


def _ranges(origin, th):
    d = np.stack([np.cos(th + ANG), np.sin(th + ANG)], 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_wall = np.where(d[:, 0] > 1e-9, (WALL_X - origin[0]) / d[:, 0], np.inf)
    t_wall = np.where(np.abs(origin[1] + t_wall * d[:, 1]) <= 3.0, t_wall, np.inf)
    oc = origin - POST
    b = d @ oc
    disc = b**2 - (oc @ oc - R_POST**2)
    with np.errstate(invalid="ignore"):
        t_post = -b - np.sqrt(disc)
    t_post = np.where((disc >= 0) & (t_post > 0), t_post, np.inf)
    r = np.minimum(t_wall, t_post)
    return np.where(r < 30.0, r, np.inf)


@pytest.fixture(scope="module")
def post_map():
    m = GPISMap2D()
    for y in np.linspace(-0.3, 0.3, 25):              # a short sideways drive, facing the post
        o = np.array([0.0, y])
        m.update(ANG, _ranges(o, 0.0), np.array([o[0], o[1], 0.0]))
    return m


def _post_distance(lines):
    pts = np.vstack([ln for ln in lines]) if lines else np.zeros((0, 2))
    return np.linalg.norm(pts - POST, axis=1) - R_POST if len(pts) else np.zeros(0)


@pytest.mark.parametrize("evidence", [None, False])
def test_small_post_is_in_the_surface(post_map, evidence):
    # the level itself (evidence=False: the refinement alone, no lone samples) and the gated surface
    d = _post_distance(post_map.surface(evidence=evidence))
    near = d[np.abs(d) < 0.1]
    assert len(near) >= 1                              # a polyline or a point on the post
    assert np.abs(near).max() < 0.01                   # within 1 cm of the exact circle


def test_without_refinement_the_post_is_lost(post_map, monkeypatch):
    # the test can fail: the grid alone (bubble filter, no refinement) drops the post from the
    # level (the gated surface would still return its sample as a lone point)
    monkeypatch.setattr(_surface, "_refined", lambda m, lines, res: [])
    d = _post_distance(post_map.surface(evidence=False))
    assert not (np.abs(d) < 0.02).any()


def test_refinement_adds_nothing_away_from_samples(post_map):
    # every refined polyline lies near a sample (the wall and the post are the only surfaces)
    lines = post_map.surface()
    pts = np.vstack(lines)
    wall = np.abs(pts[:, 0] - WALL_X)
    post = np.abs(np.linalg.norm(pts - POST, axis=1) - R_POST)
    assert np.minimum(wall, post).max() < 0.05
