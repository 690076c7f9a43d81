"""The navigator's remembered grid and its shortest-path cost-to-go, against exact geometry."""

import numpy as np
import pytest

from polar_sim.envs._gridplan import ObstacleMemory, cost_to_go


# On an open unit-cost grid the 8-connected path length is the octile distance, exactly.
def test_cost_to_go_open_grid_is_octile_distance():
    d = cost_to_go(np.ones((9, 12)), 4, 3)
    i, j = np.mgrid[0:9, 0:12]
    di, dj = np.abs(i - 4), np.abs(j - 3)
    octile = np.maximum(di, dj) + (np.sqrt(2) - 1) * np.minimum(di, dj)
    np.testing.assert_allclose(d, octile, atol=1e-12)


# A wall with one gap forces the path through the gap: the cost is the detour's length, and a
# walled-off region is unreachable.
def test_cost_to_go_detours_through_a_gap_and_marks_enclosed_cells():
    cost = np.ones((7, 7))
    cost[3, :] = np.inf
    cost[3, 6] = 1.0  # the gap, at the right edge
    d = cost_to_go(cost, 0, 0)
    # (0,0) -> (2,5) diagonal-ish, through (3,6), to (6,0): octile legs 5+ (..) computed by hand:
    # (0,0)->(2,5): 5 + 2(sqrt2-1); (2,5)->(3,6): sqrt2; (3,6)->(4,5): sqrt2; (4,5)->(6,0): 5 + 2(sqrt2-1)
    expected = 2 * (5 + 2 * (np.sqrt(2) - 1)) + 2 * np.sqrt(2)
    assert d[6, 0] == pytest.approx(expected, abs=1e-12)
    cost[3, 6] = np.inf
    assert np.isinf(cost_to_go(cost, 0, 0)[6, 0])


# Surface points mark cells, free-space disks clear them; cost is inf within the inflation.
def test_memory_marks_clears_and_inflates():
    mem = ObstacleMemory(half=2.0, cell=0.1, inflate=0.3, clearance=0.5)
    wall = np.c_[np.full(21, 1.05), np.linspace(-1, 1, 21)]
    mem.add(wall, np.zeros((0, 2)), np.zeros(0))
    c = mem.cost()
    ij = mem.index(np.array([[1.05, 0.0], [0.86, 0.0], [0.52, 0.0], [-1.0, 0.0]]))
    assert np.isinf(c[ij[0, 0], ij[0, 1]]) and np.isinf(c[ij[1, 0], ij[1, 1]])   # on / 0.2 m from the wall
    assert np.isfinite(c[ij[2, 0], ij[2, 1]]) and c[ij[2, 0], ij[2, 1]] > 1.0   # 0.5 m: passable, dearer
    assert c[ij[3, 0], ij[3, 1]] == 1.0                                         # 2 m away: plain
    # A free disk of 0.3 m around (1.0, 0.5) clears the wall cells within it.
    mem.add(np.zeros((0, 2)), np.array([[1.0, 0.5]]), np.array([0.3]))
    h = mem.hits
    k = mem.index(np.array([[1.05, 0.5], [1.05, -0.5]]))
    assert h[k[0, 0], k[0, 1]] == 0 and h[k[1, 0], k[1, 1]] > 0
    centre = mem.centre(mem.index(np.array([[0.33, -1.27]])))
    np.testing.assert_allclose(centre, [[0.35, -1.25]], atol=1e-12)


# Geodesic distance on an open grid lies between the straight line and the octile bound
# (8-connected paths overestimate it by at most 1/cos(22.5 deg) - 1 = 8.24 %), give or take the
# goal's offset from its cell's centre (half a diagonal, 0.071 m) and a cell.
def test_geodesic_open_grid_is_bounded_by_the_straight_line():
    from polar_sim.envs._gridplan import GeodesicDistance

    geo = GeodesicDistance(np.zeros((60, 80), bool), (-4.0, -3.0), 0.1, (0.52, 0.31))
    rng = np.random.default_rng(0)
    for xy in rng.uniform([-3.9, -2.9], [3.9, 2.9], (50, 2)):
        e = np.hypot(*(xy - [0.52, 0.31]))
        assert e - 0.0711 <= geo(xy) <= 1.0824 * e + 0.15


# A wall between the point and the goal: the path goes round the wall's end, and the distance is
# the two straight legs via that end, within the octile bound.
def test_geodesic_goes_round_a_wall():
    from polar_sim.envs._gridplan import GeodesicDistance

    occ = np.zeros((60, 60), bool)           # x, y in [-3, 3), 0.1 m cells
    occ[:45, 29:31] = True                   # wall at x in [-0.1, 0.1), from y = -3 up to y = 1.5
    geo = GeodesicDistance(occ, (-3.0, -3.0), 0.1, (1.5, -2.0))
    p, end = np.array([-1.5, -2.0]), np.array([0.0, 1.5])
    legs = np.hypot(*(p - end)) + np.hypot(*(end - [1.5, -2.0]))
    assert legs - 0.2 <= geo(p) <= 1.0824 * legs + 0.2
    assert geo(p) > 2.5 * 3.0                # far more than the 3 m straight line


# The geodesic fields of three navworld layouts equal, bit for bit, those of the numba Dijkstra
# that skimage.graph replaced (recorded with it in data/geodesic_fields.npz, main 969d506).
def test_geodesic_fields_equal_the_recorded_ones():
    from pathlib import Path

    from polar_sim.envs._gridplan import GeodesicDistance

    ref = np.load(Path(__file__).parent / "data" / "geodesic_fields.npz")
    for name in ("room_0", "room_7", "rooms2_3"):
        g = GeodesicDistance(ref[f"{name}/occupancy"], ref[f"{name}/origin"], float(ref[f"{name}/res"]),
                             ref[f"{name}/goal"])
        np.testing.assert_array_equal(g.dist, ref[f"{name}/dist"], err_msg=name)


# A search that stops at a cell gives that cell, and every cheaper one, its final cost; the cells
# it did not reach are inf, never a wrong finite value.
def test_cost_to_go_until_a_cell_is_exact_up_to_that_cell():
    rng = np.random.default_rng(3)
    cost = 1.0 + 3.0 * rng.random((70, 90))
    cost[rng.random(cost.shape) < 0.25] = np.inf
    cost[35, 45] = 1.0
    full = cost_to_go(cost, 35, 45)
    reach = np.argwhere(np.isfinite(full))
    for i, j in reach[rng.choice(len(reach), 20, replace=False)]:
        part = cost_to_go(cost, 35, 45, until=(i, j))
        assert part[i, j] == full[i, j]
        cheaper = full < full[i, j]
        np.testing.assert_array_equal(part[cheaper], full[cheaper])
        assert np.all((part == full) | np.isinf(part))


# A point deep inside an obstacle (no reachable cell around it) is measured from the nearest
# reachable cell: here the one 3 cells above it, unique, plus the straight line to its centre.
def test_geodesic_from_inside_an_obstacle_goes_by_the_nearest_reachable_cell():
    from polar_sim.envs._gridplan import GeodesicDistance

    occ = np.zeros((30, 30), bool)
    occ[10:19, 10:21] = True
    geo = GeodesicDistance(occ, (0.0, 0.0), 0.1, (0.25, 0.25))
    xy = np.array([1.55, 1.25])                      # cell (row 12, column 15)
    centre = np.array([1.55, 0.95])                  # cell (row 9, column 15)
    assert geo(xy) == pytest.approx(geo.dist[9, 15] + np.hypot(*(xy - centre)), abs=1e-12)
    assert geo(centre) == pytest.approx(geo.dist[9, 15], abs=1e-12)
