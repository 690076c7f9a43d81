"""Bounded work and huge finite numbers (issue 17 findings 4 and 8): far poses grow nothing
without bound, surface() refuses grids over its limit before allocating, parameters whose grids
could explode are refused by name, and points at 1e300 get the documented prior."""

import hashlib

import numpy as np
import pytest

from polar_sim.gpis import GPISMap2D, GPISMap3D
from polar_sim.gpis._base import FAR_COORD
from polar_sim.gpis.config import DistanceConfig2D, TreeConfig2D, TreeConfig3D
from polar_sim.gpis._surface import MAX_SURFACE_NODES
from polar_sim.gpis.localize import localize

from .scenes import intrinsics, room_path, scan_2d
from .test_behaviour import ANG, _map2d, _map3d


def _digest(m, tmp_path):
    p = tmp_path / "d.npz"
    m.save(p)
    return hashlib.sha256(p.read_bytes()).hexdigest()


# a scan taken 1e6 / 1e12 / 1e300 m away adds no samples and no memory beyond the map's reach
@pytest.mark.parametrize("x", [1e6, 1e12, 1e300])
def test_far_pose_2d_bounded(x):
    m = _map2d(3)
    s0 = m.samples()["points"]
    n0 = m.nbytes()
    m.update(ANG, scan_2d(np.zeros(3), ANG), np.array([x, 0.0, 0.0]))
    np.testing.assert_array_equal(m.samples()["points"], s0)
    # the free-space grid is clipped to the reach +-(4 max_half + init_half) = +-422.4 m
    assert m.nbytes() - n0 < 64e6


@pytest.mark.parametrize("x", [1e6, 1e12])
def test_far_pose_3d_bounded(x):
    m = _map3d(1)
    s0 = m.samples()["points"]
    n0 = m.nbytes()
    K = intrinsics(160, 120, 130.0)
    T = np.eye(4)
    T[0, 3] = x
    m.update(np.full((120, 160), 1.0), K, T)
    np.testing.assert_array_equal(m.samples()["points"], s0)
    assert m.nbytes() - n0 < 64e6


# surface() on samples spread over metres at the default 2 mm refuses by name, map unchanged
def test_surface_refuses_huge_grid(tmp_path):
    m = GPISMap3D(tree=TreeConfig3D(init_half=1.6, max_half=3.2))
    K = intrinsics(160, 120, 130.0)
    T = np.eye(4)
    # a plane 2.5 m ahead spanning about 3 x 2.3 m: (1500 x 1150 x 10+) nodes at 2 mm
    depth = np.full((120, 160), 2.5)
    m.update(depth, K, T)
    ext = np.ptp(m.samples()["points"], axis=0)
    # the grid spans the samples' box plus 2 res + band (2 x 14 mm) on every side
    assert np.prod((ext + 0.028) / 0.002 + 1) > MAX_SURFACE_NODES
    before = _digest(m, tmp_path)
    with pytest.raises(ValueError, match="res.*MAX_SURFACE_NODES"):
        m.surface()
    assert _digest(m, tmp_path) == before
    mesh = m.surface(res=0.05, band=0.1)          # a coarser grid is answered
    assert len(mesh.vertices) > 0
    with pytest.raises(ValueError, match="res"):
        m.surface(res=0.0)
    with pytest.raises(ValueError, match="band"):
        m.surface(band=np.nan)


# parameters whose cluster subtree would explode are refused by name, before any map exists;
# set_params on a map names the stage and leaves the map unchanged
def test_param_limits():
    with pytest.raises(ValueError, match="cluster_half/min_half"):
        TreeConfig2D(min_half=1e-6)
    m = GPISMap2D()
    with pytest.raises(ValueError, match="^tree__cluster_half/min_half"):
        m.set_params(tree__min_half=1e-6)
    assert m.tree == TreeConfig2D() and not [k for k in vars(m) if k.endswith("_")]


# issue 34's probe: numbers beyond what memory or arithmetic allow are ValueErrors naming the
# argument and its limit (they were OverflowError / ZeroDivisionError), raised by the stage
# config (by set_params as stage__field, the map unchanged); the limits themselves are accepted
@pytest.mark.parametrize("cls,stage,name,bad,ok,limit", [
    (GPISMap2D, "local_gp", "train_cap", 2**63, 4096, "4096"), (GPISMap3D, "local_gp", "train_cap", 4097, 4096, "4096"),
    (GPISMap2D, "noise", "range_noise", 1e300, 100.0, "100 m"), (GPISMap2D, "noise", "range_noise", 100.5, 100.0, "100 m"),
    (GPISMap2D, "tree", "sample_spacing", 1e-300, 1e-6, "1e-06 m"),
    (GPISMap3D, "tree", "sample_spacing", 1e-300, 1e-6, "1e-06 m")])
def test_probe_limits_name_the_argument(cls, stage, name, bad, ok, limit):
    config = cls._STAGES[stage]
    with pytest.raises(ValueError, match=f"^{name}: .*{limit}"):
        config(**{name: bad})
    m = cls()
    with pytest.raises(ValueError, match=f"^{stage}__{name}: .*{limit}"):
        m.set_params(**{f"{stage}__{name}": bad})
    assert getattr(m, stage) == config()
    m.set_params(**{f"{stage}__{name}": ok})  # the limit itself is a valid value
    assert getattr(getattr(m, stage), name) == ok


# 10**9 query points (an array that costs nothing until read) are refused naming points and the
# limit, before anything of their size is allocated; the map is unchanged
def test_query_refuses_more_points_than_the_limit(tmp_path):
    from polar_sim.gpis._base import MAX_QUERY_POINTS

    m = _map2d(2)
    before = _digest(m, tmp_path)
    huge = np.broadcast_to(np.zeros(2), (10**9, 2))
    with pytest.raises(ValueError, match=f"^points: .*{MAX_QUERY_POINTS}"):
        m.query(huge)
    assert _digest(m, tmp_path) == before
    assert MAX_QUERY_POINTS < 10**9


# a scan that would grow a dense grid past its limit is refused naming the pose, before any
# state changes (first scan: no learned state; later scan: the saved map is unchanged)
def test_grid_limits_refuse_before_state(tmp_path):
    pose = room_path(2)[0]
    m = GPISMap2D(distance=DistanceConfig2D(free_res=1e-4))
    with pytest.raises(ValueError, match="pose2d.*MAX_FREE_CELLS"):
        m.update(ANG, scan_2d(pose, ANG), pose)
    assert not [k for k in vars(m) if k.endswith("_")]
    m = GPISMap2D(tree=TreeConfig2D(max_half=1e5, cluster_half=0.1, min_half=0.05, init_half=0.1),
                  distance=DistanceConfig2D(free_res=20.0))
    m.update(ANG, scan_2d(pose, ANG), pose)
    before = _digest(m, tmp_path)
    with pytest.raises(ValueError, match="pose2d.*MAX_CLUSTER_CELLS"):
        m.update(ANG, scan_2d(pose, ANG), np.array([2e4, 1e4, 0.0]))
    assert _digest(m, tmp_path) == before


# points at 1e300: finite prior answer (distance to the origin, unit gradient, prior variance);
# the other points' answers are unaffected
@pytest.mark.parametrize("make,dim", [(_map2d, 2), (_map3d, 3)])
def test_huge_points_get_the_prior(make, dim):
    m = make()
    near = m.samples()["points"][:5] + 0.01
    far = np.zeros((3, dim))
    far[0, 0], far[1, 0], far[2, -1] = 1e300, -1e300, 3 * FAR_COORD
    d, g, v = m.query(np.vstack([near, far]))
    d0, g0, v0 = m.query(near)
    np.testing.assert_array_equal(d[:5], d0)
    np.testing.assert_array_equal(g[:5], g0)
    np.testing.assert_array_equal(v[:5], v0)
    np.testing.assert_allclose(d[5:], [1e300, 1e300, 3 * FAR_COORD], rtol=1e-15)
    expect = np.zeros((3, dim))
    expect[0, 0], expect[1, 0], expect[2, -1] = 1.0, -1.0, 1.0
    np.testing.assert_array_equal(g[5:], expect)
    np.testing.assert_array_equal(v[5:], 1.0 + m.noise.map_noise)
    assert np.isfinite(d).all() and np.isfinite(g).all() and np.isfinite(v).all()


# published maps answer the same way
def test_huge_points_legacy():
    m = _map2d(3, published=True)
    d, g, v = m.query(np.array([[1e300, 0.0]]))
    assert d[0] == 1e300 and v[0] == 1.0 + m.noise.map_noise


# localisation from a pose 1e300 m away returns without an exception, the map unchanged
def test_localize_huge_pose(tmp_path):
    m = _map2d(4)
    before = _digest(m, tmp_path)
    pose = room_path(4)[1]
    out, _, _ = localize(m, (ANG, scan_2d(pose, ANG)), np.array([1e300, 0.0, 0.0]))
    assert np.isfinite(out).all()
    assert _digest(m, tmp_path) == before
