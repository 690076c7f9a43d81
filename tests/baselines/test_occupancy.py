import math

import numpy as np
import pytest
from baselines_scene import ANGLES, world_pose

from polar_sim.baselines import OccupancyGrid2D
from polar_sim.registration import transform2d
from polar_sim.errors import NotUpdatedError

CS = 0.05
HALF_DIAG = CS * math.sqrt(2) / 2


def _one_scan(room, pose_room=(3.0, 2.0, 0.4), **params):
    pose = world_pose(room, *pose_room)
    r = room.scan(pose, ANGLES)
    return OccupancyGrid2D(cell_size=CS, **params).update(ANGLES, r, pose), pose, r


def test_occupied_cells_hold_the_true_walls(room):
    # Every occupied cell is crossed by a true surface (centre within half a cell diagonal of it),
    # and the cell of every beam end point is occupied.
    g, pose, r = _one_scan(room)
    occ = g.occupied_points()
    d, _, _ = room.query(occ)
    assert len(occ) > 300
    assert np.abs(d).max() <= HALF_DIAG + 1e-9
    ends = transform2d(pose, np.column_stack([r * np.cos(ANGLES), r * np.sin(ANGLES)]))
    assert (g.probability(ends) > 0.5).all()


def test_free_space_along_rays_is_free(room):
    # Points on the rays farther than a cell diagonal from any surface lie in free cells.
    g, pose, r = _one_scan(room)
    t = np.linspace(0.0, 1.0, 200)
    pts = np.concatenate([
        transform2d(pose, np.column_stack([t * ri * np.cos(a), t * ri * np.sin(a)]))
        for a, ri in zip(ANGLES[::10], r[::10])
    ])
    d, _, _ = room.query(pts)
    far = pts[d > 2 * HALF_DIAG]
    assert len(far) > 10000
    assert (g.probability(far) < 0.5).all()


def test_unobserved_space_stays_unknown(room):
    # Behind the walls and inside the pillar nothing was observed: probability exactly 0.5.
    g, _, _ = _one_scan(room)
    behind = transform2d(room.pose, np.array([[-0.5, 3.0], [10.5, 1.0], [6.0, 3.0], [5.0, -0.4]]))
    np.testing.assert_array_equal(g.probability(behind), 0.5)


def test_occupied_wins_over_free_within_a_scan():
    # A beam ending in a cell that a longer beam of the same scan crosses leaves that cell occupied.
    g = OccupancyGrid2D(cell_size=0.1)
    g.update(np.array([0.0, 0.0]), np.array([0.5, 1.0]), (0.05, 0.05, 0.0))
    assert g.probability([[0.55, 0.05]])[0] == pytest.approx(0.7)
    assert g.probability([[0.35, 0.05]])[0] == pytest.approx(0.4)
    assert g.probability([[1.05, 0.05]])[0] == pytest.approx(0.7)


def test_log_odds_are_clamped(room):
    # Repeating a scan saturates at logit(p_max) and logit(p_min).
    g, pose, r = _one_scan(room)
    for _ in range(20):
        g.update(ANGLES, r, pose)
    assert g.log_odds_.max() == pytest.approx(math.log(0.97 / 0.03), rel=1e-6)
    assert g.log_odds_.min() == pytest.approx(math.log(0.12 / 0.88), rel=1e-6)
    assert g.n_scans_ == 21


def test_grid_grows_and_keeps_its_content(room):
    # A scan beyond the current extent grows the grid; earlier cells keep their values.
    g = OccupancyGrid2D(cell_size=CS)
    g.update(np.array([0.0]), np.array([1.0]), (0.0, 0.0, 0.0))
    before = g.probability([[1.0, 0.0], [0.5, 0.0]])
    ext0 = g.extent
    g.update(np.array([0.0]), np.array([2.0]), (20.0, -15.0, 0.0))
    assert g.extent[2] > 22.0 and g.extent[1] < -15.0 and g.extent[0] <= ext0[0]
    np.testing.assert_array_equal(g.probability([[1.0, 0.0], [0.5, 0.0]]), before)
    assert g.probability([[22.0, -15.0]])[0] > 0.5
    np.testing.assert_allclose(g.origin_ / CS, np.round(g.origin_ / CS), atol=1e-9)


def test_fixed_bounds_clip_rays():
    # With bounds, the grid keeps its shape and a ray leaving it only updates the cells inside.
    g = OccupancyGrid2D(cell_size=0.1, bounds=(0.0, 0.0, 1.0, 1.0))
    g.update(np.array([0.0]), np.array([3.0]), (0.05, 0.55, 0.0))
    assert g.log_odds_.shape == (10, 10)
    assert (g.log_odds_[:, 5] < 0).all() and (g.log_odds_[:, [4, 6]] == 0).all()


def test_no_return_beams_clear_only_when_asked():
    # inf ranges are ignored by default and clear free space up to no_return_range when it is set.
    a, r = np.array([0.0]), np.array([np.inf])
    g = OccupancyGrid2D(cell_size=0.1, no_return_range=2.0)
    g.update(a, r, (0.05, 0.05, 0.0))
    assert (g.probability([[0.55, 0.05], [1.95, 0.05]]) < 0.5).all()
    assert g.probability([[2.15, 0.05]])[0] == 0.5
    g2 = OccupancyGrid2D(cell_size=0.1)
    g2.update(a, r, (0.05, 0.05, 0.0))
    assert not hasattr(g2, "log_odds_")


def test_sensor_offset_moves_the_rays():
    # The sensor sits at sensor_offset in the base frame: a base at the origin facing +y, sensor 1 m ahead.
    g = OccupancyGrid2D(cell_size=0.1, sensor_offset=(1.0, 0.0))
    g.update(np.array([0.0]), np.array([1.0]), (0.0, 0.0, np.pi / 2))
    assert g.probability([[0.0, 2.0]])[0] > 0.5
    assert g.probability([[0.0, 1.5]])[0] < 0.5
    assert g.probability([[0.0, 0.5]])[0] == 0.5


def test_surface_points_are_occupied_cells_next_to_free_space(room):
    # The seen surface is a subset of the occupied cells and lies on the true walls.
    g, _, _ = _one_scan(room)
    s, occ = g.surface_points(), g.occupied_points()
    assert 0 < len(s) <= len(occ)
    assert {tuple(p) for p in np.round(s, 6)} <= {tuple(p) for p in np.round(occ, 6)}


def test_query_before_update_raises():
    # A grid without data refuses queries.
    with pytest.raises(NotUpdatedError):
        OccupancyGrid2D().probability([[0.0, 0.0]])


@pytest.mark.parametrize(
    "angles, ranges, pose, name",
    [
        (np.zeros(3), np.ones(2), (0, 0, 0), "ranges"),
        (np.zeros(3), np.array([1.0, -1.0, 1.0]), (0, 0, 0), "ranges"),
        (np.array([0.0, np.nan]), np.ones(2), (0, 0, 0), "angles"),
        (np.zeros(2), np.ones(2), (0, np.nan, 0), "pose2d"),
        (np.zeros(2), np.ones(2), (0, 0), "pose2d"),
    ],
)
def test_bad_input_raises_and_leaves_the_grid_unchanged(room, angles, ranges, pose, name):
    # Rejected scans name the argument and do not touch the map.
    g, _, _ = _one_scan(room)
    before = g.log_odds_.copy()
    with pytest.raises(ValueError, match=name):
        g.update(angles, ranges, pose)
    np.testing.assert_array_equal(g.log_odds_, before)


@pytest.mark.parametrize("param, value", [("cell_size", 0.0), ("p_hit", 0.4), ("bounds", (0, 0, 1)), ("p_max", 1.2)])
def test_bad_parameters_raise_on_update(param, value):
    # Parameters are checked when the first scan arrives, naming the parameter.
    with pytest.raises(ValueError, match=param):
        OccupancyGrid2D(**{param: value}).update(np.zeros(1), np.ones(1), (0, 0, 0))
