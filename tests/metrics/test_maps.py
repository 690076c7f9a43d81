"""Distance-field map scores against analytic cases (a circular room, a square, Gaussian errors)."""

import numpy as np
import pytest

from polar_sim.metrics import (ObservedArea, angle_deg, beam_cells, class_report, classify_worst, hit_points,
                               object_map_scores, sample_eval_points, sdf_gradient, sdf_map_scores,
                               surface_scores_2d)

R = 3.0


def room_sdf(P):
    """Inside a circular room of radius R centred at the origin: distance to the wall (positive inside)."""
    return R - np.linalg.norm(P, axis=1)


def room_scans(n_scans=4, n_beams=721):
    """Scans from points near the centre; every beam ends exactly on the wall."""
    angles = np.linspace(-np.pi, np.pi, n_beams, endpoint=False)
    poses = np.array([[0.2 * np.cos(k), 0.2 * np.sin(k), 0.3 * k] for k in range(n_scans)])
    ranges = []
    for x, y, th in poses:
        d = np.c_[np.cos(angles + th), np.sin(angles + th)]
        b = d @ [x, y]
        ranges.append(-b + np.sqrt(b * b - (x * x + y * y - R * R)))     # ray-circle intersection
    return angles, poses, np.array(ranges)


# The cells of a horizontal beam are exactly those between its ends; an oblique beam's cells equal
# those of a dense sampling of the segment.
def test_beam_cells_exact():
    g = beam_cells(np.array([0.0]), np.array([[0.5, 0.5, 0.0]]), np.array([[3.0]]), cell=1.0, origin=(0, 0),
                   shape=(6, 3))
    assert set(zip(*np.nonzero(g))) == {(0, 0), (1, 0), (2, 0), (3, 0)}
    rng = np.random.default_rng(1)
    a = rng.uniform(-np.pi, np.pi, 40)
    r = rng.uniform(0.5, 6.0, 40)
    pose = np.array([[3.37, 2.81, 0.0]])
    g = beam_cells(a, pose, r[None], cell=0.1, origin=(-5, -5), shape=(150, 150))
    t = np.linspace(0, 1, 200_001)[:, None]
    want = set()
    for ai, ri in zip(a, r):
        p = pose[0, :2] + t * ri * np.array([np.cos(ai), np.sin(ai)])
        want |= set(map(tuple, np.floor((p + 5) / 0.1).astype(int)))
    assert set(zip(*np.nonzero(g))) == want
    # a no-return beam (inf) and one lengthened past the maximum range mark nothing
    g = beam_cells(np.array([0.0, 1.0]), pose, np.array([[np.inf, 29.9]]), cell=0.1, origin=(-5, -5),
                   shape=(150, 150), extend=0.3)
    assert not g.any()


# In a circular room: every end point is on the wall; crossed = inside the wall, reached extends
# 0.3 m past it; the near and far sets follow their definitions.
def test_observed_area_in_a_circular_room():
    angles, poses, ranges = room_scans()
    obs = ObservedArea(angles, poses, ranges)
    assert np.abs(room_sdf(obs.hits)).max() < 1e-9
    rng = np.random.default_rng(0)
    P = rng.uniform(-4, 4, (20_000, 2))
    rad = np.linalg.norm(P, axis=1)
    assert obs.crossed(P[rad < R - 0.05]).all() and not obs.crossed(P[rad > R + 0.05]).any()
    assert obs.reached(P[rad < R + 0.25]).all() and not obs.reached(P[rad > R + 0.35]).any()
    s = obs.sets(P, room_sdf(P))
    gt = room_sdf(P)
    np.testing.assert_array_equal(s["near"] & (rad < R + 0.25), (np.abs(gt) < 0.3) & (rad < R + 0.25))
    np.testing.assert_array_equal(s["far"], (gt > 0.3) & (gt < 2.0))
    assert obs.count(np.array([[R, 0.0]]))[0] == 4       # every scan hit the wall there


# A perfect map scores zero; a map offset by 1 cm scores exactly 1 cm, with exact gradients.
def test_sdf_map_scores():
    angles, poses, ranges = room_scans()
    obs = ObservedArea(angles, poses, ranges)
    E = sample_eval_points(obs, room_sdf, 20_000, seed=3)
    G = sdf_gradient(room_sdf, E["P"])
    s, e = sdf_map_scores(room_sdf(E["P"]), G, E)
    assert s["near_rmse_m"] < 1e-12 and s["far_mae_m"] < 1e-12 and s["grad_near_median_deg"] < 1e-3
    s, e = sdf_map_scores(room_sdf(E["P"]) + 0.01, G, E)
    assert s["near_rmse_m"] == pytest.approx(0.01) and s["far_mae_m"] == pytest.approx(0.01)
    assert s["n_near"] == E["near"].sum() > 1000 and s["n_far"] == E["far"].sum() > 1000
    # the exact gradient points to the centre (the SDF grows inwards)
    q = np.array([[1.0, 0.0], [0.0, 2.0]])
    np.testing.assert_allclose(sdf_gradient(room_sdf, q), [[-1, 0], [0, -1]], atol=1e-6)
    assert angle_deg(np.array([[1.0, 0.0]]), np.array([[0.0, 2.0]]))[0] == pytest.approx(90.0)


# Surface points on a circle 2 cm outside the wall: surface RMSE = 2 cm; Hausdorff = 2 cm (plus
# at most half the sampling gap); a spur 20 cm off the wall sets the Hausdorff distance.
def test_surface_scores_and_worst_classes():
    angles, poses, ranges = room_scans()
    obs = ObservedArea(angles, poses, ranges)
    t = np.linspace(0, 2 * np.pi, 20_000, endpoint=False)
    est = (R + 0.02) * np.c_[np.cos(t), np.sin(t)]
    m, det = surface_scores_2d(est, room_sdf, obs, well_k=2)
    assert m["surface_rmse_m"] == pytest.approx(0.02, abs=1e-9)
    assert 0.02 <= m["hausdorff_m"] <= 0.02 + 1e-3
    spur = np.array([[R - 0.2, 0.0]])
    m2, det2 = surface_scores_2d(np.vstack([est, spur]), room_sdf, obs)
    assert m2["hausdorff_m"] == pytest.approx(0.2, abs=1e-9)
    # worst errors: the spur is at a "corner" when a corner is put there, else on a well-seen wall
    shares, (q, cls) = classify_worst(det2, room_sdf, obs, np.array([[R, 0.0]]), top=1e-4)
    assert np.allclose(q[0], [R, 0.0], atol=1e-6) and cls[0] == 0
    shares, (q, cls) = classify_worst(det2, room_sdf, obs, np.zeros((0, 2)), top=1e-4, sparse_k=2)
    assert cls[0] == 2 and shares["worst_wall_share"] == 1.0
    assert surface_scores_2d(np.zeros((0, 2)), room_sdf, obs)[1] is None


# Gaussian errors with the right variance cover their 95 % interval 95 % of the time; with the
# variance underestimated 4x, only P(|z| < 0.98) = 67 %.
def test_class_report_coverage():
    rng = np.random.default_rng(0)
    sig = rng.uniform(0.005, 0.05, 200_000)
    e = rng.normal(0, sig)
    cls = {"all": np.ones(len(e), bool), "big": sig > 0.03}
    rows = class_report(e, sig ** 2, cls)
    assert rows[0]["coverage95"] == pytest.approx(0.95, abs=0.003)
    assert rows[1]["coverage95"] == pytest.approx(0.95, abs=0.005) and rows[1]["n"] == cls["big"].sum()
    assert class_report(e, (sig / 2) ** 2, cls)[0]["coverage95"] == pytest.approx(0.6729, abs=0.004)
    assert "coverage95" not in class_report(e, None, cls)[0]


# Object scores from arrays: the means and the Chamfer definition.
def test_object_map_scores():
    s = object_map_scores(np.array([0.001, -0.001]), np.zeros(2), dist=np.array([0.001, 0.003, 0.5]),
                          visible=np.array([True, True, False]), to_surface=np.array([0.002, 0.004]),
                          vertex_grad=np.array([[0, 0, 1.0], [1.0, 0, 0]]), true_normals=np.array([[0, 0, 2.0], [0, 1.0, 0]]))
    assert s["sdf_rmse_m"] == pytest.approx(0.001) and s["surface_to_mesh_m"] == pytest.approx(0.002)
    assert s["mesh_to_surface_m"] == pytest.approx(0.003) and s["chamfer_m"] == pytest.approx(0.0025)
    assert s["normal_median_deg"] == pytest.approx(45.0) and s["n_vertices_observed"] == 2


# End points of scans: only returns within (0, max_range) count.
def test_hit_points():
    P = hit_points(np.array([0.0, np.pi / 2]), np.array([[1.0, 2.0, 0.0]]), np.array([[2.0, np.inf]]))
    np.testing.assert_allclose(P, [[3.0, 2.0]])
