import math

import numpy as np
import pytest

from polar_sim import metrics
from polar_sim.metrics import (
    chamfer,
    hausdorff,
    nearest_distances,
    normal_angle_error,
    normal_angles,
    sample_polyline,
    sdf_error,
    surface_rmse,
)


def test_hand_computed_hausdorff_and_chamfer():
    # A = {(0,0), (1,0)}, B = {(0,.5), (1,.5), (3,.5)}: A->B all 0.5; B->A 0.5, 0.5, hypot(2, .5).
    A = np.array([[0.0, 0.0], [1.0, 0.0]])
    B = np.array([[0.0, 0.5], [1.0, 0.5], [3.0, 0.5]])
    far = math.hypot(2.0, 0.5)
    assert hausdorff(A, B) == pytest.approx(far)
    assert hausdorff(B, A) == pytest.approx(far)
    assert chamfer(A, B) == pytest.approx(0.5 * (0.5 + (1.0 + far) / 3))
    np.testing.assert_allclose(nearest_distances(B, A), [0.5, 0.5, far])


def test_offset_surfaces_give_the_offset():
    # Two identical samplings of a segment shifted by 7 cm along the normal: all three figures are 0.07.
    line = sample_polyline([[0.0, 0.0], [2.0, 0.0]], 0.01)
    moved = line + [0.0, 0.07]
    assert hausdorff(line, moved) == pytest.approx(0.07)
    assert chamfer(line, moved) == pytest.approx(0.07)
    assert surface_rmse(moved, line) == pytest.approx(0.07)


def test_metrics_work_in_3d_and_are_symmetric():
    # Random clouds in 3D: Hausdorff and Chamfer are symmetric and zero for identical sets.
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(200, 3)), rng.normal(size=(150, 3))
    assert hausdorff(a, b) == pytest.approx(hausdorff(b, a))
    assert chamfer(a, b) == pytest.approx(chamfer(b, a))
    assert hausdorff(a, a) == 0.0 and chamfer(a, a) == 0.0


def test_surface_rmse_hand_case():
    # Distances 0.1, 0.2 (to the nearest of two truth points): RMSE sqrt((0.01 + 0.04) / 2).
    est = np.array([[0.1, 0.0], [5.0, 0.2]])
    truth = np.array([[0.0, 0.0], [5.0, 0.0]])
    assert surface_rmse(est, truth) == pytest.approx(math.sqrt(0.025))


def test_sdf_error_statistics():
    # Errors (0, 1, 2): mean 1, RMSE sqrt(5/3), median 1, 90th percentile 1.8, max 2, bias 1.
    s = sdf_error([1.0, 2.0, 3.0], [1.0, 1.0, 1.0])
    assert (s.n, s.mean, s.median, s.max, s.bias) == (3, 1.0, 1.0, 2.0, 1.0)
    assert s.rmse == pytest.approx(math.sqrt(5 / 3)) and s.p90 == pytest.approx(1.8)
    m = sdf_error(np.array([1.0, -2.0, 9.0]), np.zeros(3), mask=np.array([True, True, False]))
    assert (m.n, m.mean, m.bias) == (2, 1.5, -0.5)


def test_normal_angles():
    # 90 and 45 degrees, unnormalised input; unoriented flips the opposite normal to 0 deg.
    est = np.array([[1.0, 0.0], [2.0, 2.0], [-1.0, 0.0]])
    true = np.array([[0.0, 3.0], [1.0, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(normal_angles(est, true), [90.0, 45.0, 180.0])
    np.testing.assert_allclose(normal_angles(est, true, oriented=False), [90.0, 45.0, 0.0], atol=1e-12)
    assert normal_angle_error(est, true).median == pytest.approx(90.0)


def test_sample_polyline_spacing_and_vertices():
    # A closed unit square at 0.3 m spacing: 4 points a side, on the square, gaps at most 0.3 m.
    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    p = sample_polyline(sq, 0.3, closed=True)
    assert p.shape == (16, 2)
    gaps = np.linalg.norm(np.diff(np.vstack([p, p[:1]]), axis=0), axis=1)
    assert gaps.max() <= 0.3 + 1e-12
    on_edge = np.isclose(p, 0.0) | np.isclose(p, 1.0)
    assert on_edge.any(axis=1).all()
    assert len(sample_polyline(sq, 0.3)) == 3 * 4 + 1


def test_exported_from_the_metrics_package():
    # The contract names are reachable as polar_sim.metrics.hausdorff / chamfer.
    assert metrics.hausdorff is hausdorff and metrics.chamfer is chamfer


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: hausdorff(np.zeros((3, 2)), np.zeros((3, 3))), "points_b"),
        (lambda: chamfer(np.zeros((0, 2)), np.zeros((3, 2))), "points_a"),
        (lambda: hausdorff([[0.0, np.nan]], [[0.0, 0.0]]), "points_a"),
        (lambda: surface_rmse(np.zeros((3, 4)), np.zeros((3, 4))), "points_est"),
        (lambda: sdf_error([1.0, 2.0], [1.0]), "truth"),
        (lambda: sdf_error([1.0, np.nan], [1.0, 1.0]), "est"),
        (lambda: sdf_error([1.0, 2.0], [1.0, 1.0], mask=np.array([True, False, True])), "mask"),
        (lambda: normal_angles(np.zeros((2, 2)), np.ones((2, 2))), "est_normals"),
        (lambda: normal_angles(np.ones((2, 2)), np.ones((3, 2))), "true_normals"),
        (lambda: sample_polyline([[0.0, 0.0], [1.0, 0.0]], 0.0), "spacing"),
        (lambda: sample_polyline([[0.0, 0.0]], 0.1), "vertices"),
    ],
)
def test_bad_input_raises(call, name):
    # Wrong shapes, NaN, mismatched lengths, zero normals, bad spacing: ValueError naming the argument.
    with pytest.raises(ValueError, match=name):
        call()


# issue 34: hausdorff on 10^8 broadcast points hung. A point set beyond MAX_SURFACE_POINTS is refused
# by name and with the limit, before anything as large is allocated (the broadcast view is 24 bytes).
@pytest.mark.parametrize("fn", [hausdorff, chamfer, nearest_distances, surface_rmse])
def test_too_many_points_are_refused_before_any_work(fn):
    from polar_sim.metrics import MAX_SURFACE_POINTS

    huge = np.broadcast_to(np.zeros(3), (10**8, 3))
    assert huge.base.nbytes == 24
    with pytest.raises(ValueError, match=r"^\w+: at most 10,000,000 points") as e:
        fn(huge, np.ones((3, 3)))
    assert str(e.value).split(":")[0] in ("points_a", "points", "points_est")
    with pytest.raises(ValueError, match=r"^(points_b|reference|points_true): at most"):
        fn(np.ones((3, 3)), huge)
    assert MAX_SURFACE_POINTS == 10_000_000
