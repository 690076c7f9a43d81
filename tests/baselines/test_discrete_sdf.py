import numpy as np
import pytest

from polar_sim.baselines import DiscreteSDF2D, DiscreteSDF3D
from polar_sim.errors import NotUpdatedError

CS = 0.05


def _cell_grid(grid):
    xs, ys = grid.cell_centers()
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel()])


def test_edt_matches_the_analytic_distance_in_free_space(room, mapped_grid):
    # At the known-free cell centres inside the room the signed EDT is within one cell of the exact SDF.
    sdf = DiscreteSDF2D.from_grid(mapped_grid)
    P = _cell_grid(mapped_grid)
    truth, _, _ = room.query(P)
    est, _, var = sdf.query(P)
    m = mapped_grid.free_mask().ravel() & (truth > 0)
    assert m.sum() > 20000
    assert np.abs(est[m] - truth[m]).max() <= CS
    np.testing.assert_allclose(var[m], CS * CS / 12)


def test_interpolated_queries_stay_within_a_cell(room, mapped_grid):
    # Bilinear interpolation between the cell centres keeps the error below one cell at random points.
    sdf = DiscreteSDF2D.from_grid(mapped_grid)
    rng = np.random.default_rng(1)
    local = np.column_stack([rng.uniform(0.1, 9.9, 5000), rng.uniform(0.1, 5.9, 5000)])
    P = local @ room._R.T + room._t
    truth, _, _ = room.query(P)
    P = P[truth > 0]
    est, _, _ = sdf.query(P)
    assert np.abs(est - room.query(P)[0]).max() <= CS


def test_sign_is_negative_behind_walls_and_in_the_pillar(room, mapped_grid):
    # "enclosed": unknown space behind the walls and inside the pillar is negative, free space positive.
    sdf = DiscreteSDF2D.from_grid(mapped_grid)
    local = np.array([[-0.5, 3.0], [10.4, 2.0], [5.0, -0.3], [6.0, 3.0], [5.0, 2.0], [1.0, 1.0]])
    d, _, _ = sdf.query(local @ room._R.T + room._t)
    assert (d[:4] < 0).all() and (d[4:] > 0).all()


def test_unknown_policy_changes_the_sign_of_unknown_space(room, mapped_grid):
    # unknown="free" leaves the unobserved outside positive; "occupied" makes it negative.
    P = np.array([[-0.5, 3.0]]) @ room._R.T + room._t
    free = DiscreteSDF2D(unknown="free").fit(mapped_grid.occupied_mask(), mapped_grid.origin_, CS,
                                             free=mapped_grid.free_mask())
    occ = DiscreteSDF2D(unknown="occupied").fit(mapped_grid.occupied_mask(), mapped_grid.origin_, CS,
                                                free=mapped_grid.free_mask())
    assert free.query(P)[0][0] > 0 and occ.query(P)[0][0] < 0


def test_zero_level_runs_through_boundary_cell_centres():
    # A single occupied column: 0 at its centres, +cell at the next column, slope 1 in between.
    occ = np.zeros((6, 4), dtype=bool)
    occ[2, :] = True
    sdf = DiscreteSDF2D(unknown="free").fit(occ, (0.0, 0.0), 1.0)
    d, g, _ = sdf.query([[2.5, 1.5], [3.5, 1.5], [3.0, 2.0], [4.5, 1.0]])
    np.testing.assert_allclose(d, [0.0, 1.0, 0.5, 2.0])
    np.testing.assert_allclose(g[[1, 3]], [[1.0, 0.0]] * 2)


def test_gradient_follows_the_true_normal(room, mapped_grid):
    # In free space 0.1-1 m from the walls the EDT gradient is within a few degrees of the exact one.
    sdf = DiscreteSDF2D.from_grid(mapped_grid)
    P = _cell_grid(mapped_grid) + 0.013
    truth, g_true, _ = room.query(P)
    P, g_true = P[(truth > 0.1) & (truth < 1.0)], g_true[(truth > 0.1) & (truth < 1.0)]
    _, g, _ = sdf.query(P)
    cosang = np.einsum("ij,ij->i", g, g_true) / np.linalg.norm(g, axis=1)
    ang = np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))
    assert np.median(ang) < 5.0 and np.percentile(ang, 90) < 15.0


def test_3d_sphere_distance_within_a_voxel():
    # Signed EDT of a solid voxelised sphere: within one voxel of |p - c| - R, normals nearly radial.
    v, R = 0.02, 0.3
    n = 50
    centres = (np.arange(n) + 0.5) * v
    X, Y, Z = np.meshgrid(centres, centres, centres, indexing="ij")
    c = np.array([0.5, 0.5, 0.5])
    occ = (X - c[0]) ** 2 + (Y - c[1]) ** 2 + (Z - c[2]) ** 2 <= R**2
    sdf = DiscreteSDF3D().fit(occ, (0.0, 0.0, 0.0), v)
    rng = np.random.default_rng(3)
    u = rng.normal(size=(2000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    P = c + u * rng.uniform(R - 0.1, R + 0.15, (2000, 1))
    d, g, _ = sdf.query(P)
    truth = np.linalg.norm(P - c, axis=1) - R
    assert np.abs(d - truth).max() <= v
    cosang = np.einsum("ij,ij->i", g, u) / np.linalg.norm(g, axis=1)
    assert np.median(np.degrees(np.arccos(np.clip(cosang, -1, 1)))) < 5.0


def test_outside_the_grid_reports_the_no_data_variance(mapped_grid):
    # Points beyond the grid get the nearest grid value and variance outside_variance.
    sdf = DiscreteSDF2D.from_grid(mapped_grid, outside_variance=2.0)
    far = np.array([mapped_grid.extent[2] + 5.0, 0.0])
    _, _, var = sdf.query(far[None])
    assert var[0] == 2.0


def test_query_before_fit_raises():
    # An unfitted field refuses queries.
    with pytest.raises(NotUpdatedError):
        DiscreteSDF2D().query([[0.0, 0.0]])


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(occupied=np.zeros((4, 4), bool), origin=(0, 0), cell_size=0.1), "occupied"),
        (dict(occupied=np.ones((4, 4), bool), origin=(0, 0), cell_size=0.1), "occupied"),
        (dict(occupied=np.eye(4, dtype=bool)[None], origin=(0, 0), cell_size=0.1), "occupied"),
        (dict(occupied=np.eye(4, dtype=bool), origin=(0, np.nan), cell_size=0.1), "origin"),
        (dict(occupied=np.eye(4, dtype=bool), origin=(0, 0), cell_size=-1.0), "cell_size"),
        (dict(occupied=np.eye(4, dtype=bool), origin=(0, 0), cell_size=0.1, free=np.eye(4, dtype=bool)), "free"),
    ],
)
def test_bad_fit_input_raises(kwargs, name):
    # Empty or full occupancy, wrong dimension, bad origin, cell size or overlapping free cells.
    with pytest.raises(ValueError, match=name):
        DiscreteSDF2D().fit(**kwargs)


def test_bad_points_and_unknown_policy_raise(mapped_grid):
    # Query points of the wrong shape or with NaN, and an unknown policy name, name the argument.
    sdf = DiscreteSDF2D.from_grid(mapped_grid)
    with pytest.raises(ValueError, match="points"):
        sdf.query(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="points"):
        sdf.query([[np.nan, 0.0]])
    with pytest.raises(ValueError, match="unknown"):
        DiscreteSDF2D.from_grid(mapped_grid, unknown="maybe")


# from_values: an exact SDF sampled at the cell centres (a disc of radius 1 m) is interpolated
# bilinearly: exact at the centres, within the bilinear bound between them, and refused when bad.
def test_from_values_samples_an_exact_sdf():
    from polar_sim.baselines import DiscreteSDF2D

    cell, lo = 0.05, np.array([-2.0, -2.0])
    c = lo[0] + (np.arange(80) + 0.5) * cell
    X, Y = np.meshgrid(c, c, indexing="ij")
    sdf = DiscreteSDF2D.from_values(np.hypot(X, Y) - 1.0, lo, cell)
    centres = np.column_stack([X.ravel(), Y.ravel()])
    d, g, v = sdf.query(centres)
    np.testing.assert_allclose(d, np.hypot(*centres.T) - 1.0, atol=1e-12)
    p = np.random.default_rng(0).uniform(-1.8, 1.8, (2000, 2))
    p = p[np.hypot(*p.T) > 2 * cell]  # away from the cone's tip, where r - 1 is not smooth
    r = np.hypot(*p.T)
    # bilinear error <= cell^2 / 8 (|f_xx| + |f_yy|) = cell^2 / (8 r') with r' the cell's smallest radius
    assert np.all(np.abs(sdf.query(p)[0] - (r - 1.0)) <= cell**2 / (8 * (r - cell)) + 1e-12)
    assert sdf.inside_.sum() > 0 and np.all(v[: len(centres)] == cell * cell / 12.0)
    with pytest.raises(ValueError, match="values"):
        DiscreteSDF2D.from_values(np.full((3, 3), np.nan), lo, cell)
    with pytest.raises(ValueError, match="cell_size"):
        DiscreteSDF2D.from_values(np.zeros((3, 3)), lo, -1.0)
