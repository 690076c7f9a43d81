"""``map_scores_2d`` end to end on an analytic case: a square room whose exact SDF is known, scanned
by noise-free beams that end exactly on its walls, and "maps" whose errors are known by construction
(the exact SDF plus a constant, a gradient turned by a known angle, surface points a known
distance outside the walls), so every score has an exact expected value. numpy only."""

import numpy as np
import pytest

from polar_sim.metrics.maps import WORST_CLASSES, ObservedArea, map_scores_2d

A = 3.0                                    # half side of the square room, m
CORNERS = np.array([[A, A], [A, -A], [-A, A], [-A, -A]])
N_SCANS = 4


def room_sdf(P):
    """Exact SDF of the square room [-A, A]^2: distance to the nearest wall, positive inside."""
    q = np.abs(P) - A
    return -(np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0))


def room_grad(P):
    """Exact gradient of ``room_sdf`` (away from the medial axis): unit, pointing into the room."""
    q, s = np.abs(P) - A, np.sign(P)
    out = np.zeros_like(P)
    outside = (q > 0).any(axis=1)
    m = np.maximum(q, 0.0)
    out[outside] = -(s * m)[outside] / np.linalg.norm(m[outside], axis=1, keepdims=True)
    j = np.argmax(q, axis=1)
    inside = np.nonzero(~outside)[0]
    out[inside, j[inside]] = -s[inside, j[inside]]
    return out


def nearest_wall_point(P):
    """The true surface point nearest to P (inside: the nearest wall; outside: the clamped point)."""
    q = np.clip(P, -A, A)
    inside = (np.abs(P) < A).all(axis=1)
    j = np.argmax(np.abs(P), axis=1)
    idx = np.nonzero(inside)[0]
    q[idx, j[idx]] = np.sign(P[idx, j[idx]]) * A
    return q


def room_scans(n_beams=1441):
    """Scans from 4 poses near the centre; every beam ends exactly on a wall (ray-box intersection)."""
    angles = np.linspace(-np.pi, np.pi, n_beams, endpoint=False)
    poses = np.array([[0.3 * np.cos(k), 0.3 * np.sin(k), 0.4 * k] for k in range(N_SCANS)])
    ranges = []
    for x, y, th in poses:
        d = np.c_[np.cos(angles + th), np.sin(angles + th)]
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = np.where(d[:, 0] != 0, (np.sign(d[:, 0]) * A - x) / d[:, 0], np.inf)
            ty = np.where(d[:, 1] != 0, (np.sign(d[:, 1]) * A - y) / d[:, 1], np.inf)
        ranges.append(np.minimum(tx, ty))
    return angles, poses, np.array(ranges)


def offset_surface(s, n_edge=3001, n_arc=50):
    """Points at distance exactly ``s`` outside the walls: four edges and four quarter circles."""
    t = np.linspace(-A, A, n_edge)
    edges = [np.c_[np.full_like(t, A + s), t], np.c_[np.full_like(t, -A - s), t],
             np.c_[t, np.full_like(t, A + s)], np.c_[t, np.full_like(t, -A - s)]]
    phi = np.linspace(0, np.pi / 2, n_arc)
    arcs = [c + s * np.c_[np.sign(c[0]) * np.cos(phi), np.sign(c[1]) * np.sin(phi)] for c in CORNERS]
    return np.vstack(edges + arcs)


def rotate(G, deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return G @ np.array([[c, s], [-s, c]])


@pytest.fixture(scope="module")
def obs():
    o = ObservedArea(*room_scans())
    assert np.abs(room_sdf(o.hits)).max() < 1e-12                  # the beams end on the walls
    assert (o.count(np.array([[A, 0.0], [0.0, -A], [A, A - 0.01]])) == N_SCANS).all()   # every scan saw every wall
    return o


# A map = exact SDF + 1 cm, its gradient turned by 10 deg, variance (1 cm)^2; surface points 2 cm
# outside the walls plus one spur 10 cm inside, mid-wall. Every score is known exactly.
def test_offset_map_scores_exactly(obs):
    c, s, turn = 0.01, 0.02, 10.0
    surf = offset_surface(s)
    spur = np.array([[A - 0.1, 0.0]])

    def query(P):
        return room_sdf(P) + c, rotate(room_grad(P), turn), np.full(len(P), c ** 2)

    row, arr = map_scores_2d(query, np.vstack([surf, spur]), room_sdf, obs, CORNERS, n_eval=20_000, seed=1,
                             well_k=N_SCANS, sparse_k=N_SCANS)
    # SDF errors: the constant offset, on the near and the far sets alike
    for k in ("near_rmse_m", "near_median_abs_m", "near_p90_abs_m", "far_mae_m", "far_median_abs_m",
              "near_rmse_wellseen_m", "corner_rmse_m", "wall_rmse_m"):
        assert row[k] == pytest.approx(c, rel=1e-9), k
    assert row["grad_near_median_deg"] == pytest.approx(turn, abs=1e-6)
    assert row["grad_far_median_deg"] == pytest.approx(turn, abs=1e-6)
    np.testing.assert_allclose(arr["err"], c, rtol=1e-9)
    # the near set, split by where each point's nearest true surface point lies
    n_near = row["n_near"]
    assert n_near > 1000 and row["n_far"] > 1000 and row["near_n"] == n_near == len(arr["P"])
    assert np.abs(room_sdf(arr["P"])).max() < 0.3
    dc = np.min(np.linalg.norm(nearest_wall_point(arr["P"])[:, None] - CORNERS[None], axis=2), axis=1)
    assert row["corner_n"] == int((dc < 0.3).sum()) > 100
    assert row["sparse_n"] == 0 and row["wall_n"] == n_near - row["corner_n"] == row["n_near_wellseen"]
    # 95 % coverage: |error| = 1 cm <= 1.96 sigma everywhere
    assert row["near_coverage95"] == row["corner_coverage95"] == row["wall_coverage95"] == 1.0
    # surface: every point 2 cm off but the spur (10 cm); the sampling gap of the edges (2 mm) bounds
    # the distance from the walls to the estimate
    n = len(surf)
    assert row["n_surface_points"] == n + 1
    assert row["surface_rmse_m"] == pytest.approx(np.sqrt((n * s ** 2 + 0.1 ** 2) / (n + 1)), rel=1e-9)
    assert row["h_est_to_true_m"] == pytest.approx(0.1, rel=1e-9) == row["hausdorff_m"]
    assert s <= row["h_true_to_est_m"] <= np.hypot(s, 0.001 + 1e-9)
    # well seen is judged where a point lies: no scan hit near the spur, so only the 2 cm offset counts
    assert row["hausdorff_wellseen_m"] == row["h_true_to_est_m"]
    assert row["surface_rmse_wellseen_m"] == pytest.approx(s, rel=1e-9)
    # worst errors: the spur comes first, moved onto the wall at (A, 0), a well-seen wall
    np.testing.assert_allclose(arr["worst"][0], [A, 0.0], atol=1e-6)
    assert arr["worst_cls"][0] == WORST_CLASSES.index("wall")
    assert sum(row[f"worst_{k}_share"] for k in WORST_CLASSES) == pytest.approx(1.0)
    np.testing.assert_allclose(np.abs(arr["dA"][:-1]), s, rtol=1e-9)


# The thresholds move points between classes as defined: asking for more scans than were taken
# makes every non-corner wall sparse and nothing well seen; a variance 4x too small (sigma = c / 4)
# covers nothing; no variance, no coverage; no surface, no surface scores. Same seed, same scores.
def test_thresholds_variance_and_optional_parts(obs):
    c = -0.005

    def query(P, sigma=abs(c) / 4):
        return room_sdf(P) + c, room_grad(P), np.full(len(P), sigma ** 2)

    row, arr = map_scores_2d(query, None, room_sdf, obs, CORNERS, n_eval=20_000, seed=2,
                             well_k=N_SCANS + 1, sparse_k=N_SCANS + 1)
    assert row["near_rmse_m"] == pytest.approx(abs(c), rel=1e-9) and row["grad_near_median_deg"] < 1e-6
    assert row["n_near_wellseen"] == 0 and np.isnan(row["near_rmse_wellseen_m"])
    assert row["wall_n"] == 0 and row["sparse_n"] == row["n_near"] - row["corner_n"] > 0
    assert row["near_coverage95"] == 0.0
    assert not any(k.startswith(("surface_", "hausdorff", "worst_")) for k in row) and set(arr) == {"P", "err"}
    # well_k and sparse_k act apart: every wall seen by 4 scans is not sparse at 4, yet not well seen at 5
    row1, _ = map_scores_2d(query, None, room_sdf, obs, CORNERS, n_eval=20_000, seed=2, well_k=N_SCANS + 1,
                            sparse_k=N_SCANS)
    assert row1["sparse_n"] == 0 and row1["wall_n"] == row["sparse_n"] and row1["n_near_wellseen"] == 0
    # no corners given: nothing is a corner
    row2, _ = map_scores_2d(query, None, room_sdf, obs, np.zeros((0, 2)), n_eval=20_000, seed=2,
                            well_k=N_SCANS + 1, sparse_k=N_SCANS + 1)
    assert row2["corner_n"] == 0 and row2["sparse_n"] == row2["n_near"]
    # a map without variance gets no coverage columns
    row3, _ = map_scores_2d(lambda P: (room_sdf(P), room_grad(P), None), None, room_sdf, obs, CORNERS,
                            n_eval=20_000, seed=2)
    assert row3["near_rmse_m"] < 1e-12 and not any(k.endswith("coverage95") for k in row3)
    # deterministic in the seed; another seed draws other points
    again, _ = map_scores_2d(query, None, room_sdf, obs, CORNERS, n_eval=20_000, seed=2,
                             well_k=N_SCANS + 1, sparse_k=N_SCANS + 1)
    np.testing.assert_equal(again, row)
    other, _ = map_scores_2d(query, None, room_sdf, obs, CORNERS, n_eval=20_000, seed=3,
                             well_k=N_SCANS + 1, sparse_k=N_SCANS + 1)
    assert other["n_near"] != row["n_near"]
