"""navworld: seeded rooms and clutter with a reachable, distant goal."""

import numpy as np
import pytest

from polar_sim.sim import World


# Start and goal are free, far apart, and the start is where the rover stands.
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_start_goal(seed):
    with World("navworld", seed=seed, kinematic=True) as w:
        start, goal = w.meta.start_pose2d, w.meta.goal
        assert np.linalg.norm(goal - start[:2]) >= 5.0
        r = w.meta.robot_radius
        d = w.sdf(np.array([start[:2], goal]))
        assert np.all(d > r)
        np.testing.assert_allclose(w.truth()["robot_pose2d"][:2], start[:2], atol=1e-9)


# Same seed, same world; options change the layout; bad options list the valid ones.
def test_layout_options():
    a = World("navworld", seed=4)
    b = World("navworld", seed=4)
    assert a.model.ngeom == b.model.ngeom
    np.testing.assert_array_equal(a.model.geom_pos, b.model.geom_pos)
    c = World("navworld", seed=4, rooms=2, clutter=0, lidar_beams=90)
    assert c.lidar_spec("lidar").directions.shape == (90, 3)
    assert not any(c.model.geom(i).name.startswith("clutter") for i in range(c.model.ngeom))
    with pytest.raises(ValueError, match="valid"):
        World("navworld", seed=0, doors=3)


# A pooled world given another layout in place is that layout's world: the same start, goal and
# occupancy, the same exact SDF and lidar scan bit for bit, the same contacts at random poses; and
# its slot geoms carry the bounding sphere and box the compiler would give them.
@pytest.mark.parametrize("rooms, clutter", [(1, 6), (3, 10)])
def test_relayout_gives_the_compiled_world(rooms, clutter):
    kw = dict(rooms=rooms, room_size=6.0 if rooms == 1 else 4.0, clutter=clutter)
    pooled = World("navworld", seed=0, kinematic="planar", pooled=True, **kw)
    rng = np.random.default_rng(rooms)
    for seed in (3, 8):
        assert pooled.relayout(seed) is pooled
        ref = World("navworld", seed=seed, kinematic="planar", **kw)
        for key in ("start_pose2d", "goal", "occupancy", "bounds"):
            np.testing.assert_array_equal(getattr(pooled.meta, key), getattr(ref.meta, key))
        np.testing.assert_array_equal(pooled.truth()["robot_pose2d"], ref.truth()["robot_pose2d"])
        pts = rng.uniform(-kw["room_size"] * rooms / 2, kw["room_size"] * rooms / 2, (500, 2))
        np.testing.assert_array_equal(pooled.sdf(pts), ref.sdf(pts))
        np.testing.assert_array_equal(pooled.lidar("lidar", noise=False).ranges, ref.lidar("lidar", noise=False).ranges)
        hits = 0
        for x, y, th in rng.uniform([-3, -3, -3], [3, 3, 3], (100, 3)):
            for w in (pooled, ref):
                w._kin = (float(x), float(y), float(th))
                w._set_planar_pose(0.0, 0.0)
            assert pooled.robot_collision() == ref.robot_collision()
            hits += ref.robot_collision()
        assert 0 < hits < 100
        m, r = pooled.model, ref.model
        shown = m.geom_group == 0
        pk = np.lexsort(m.geom_pos[shown].T)
        rk = np.lexsort(r.geom_pos[r.geom_group == 0].T)
        for field in ("geom_pos", "geom_size", "geom_rbound", "geom_aabb", "geom_type"):
            np.testing.assert_array_equal(getattr(m, field)[shown][pk], getattr(r, field)[r.geom_group == 0][rk], field)


# relayout needs a pooled world, and a layout seed that cannot be drawn leaves the world as it was.
def test_relayout_refuses_and_keeps_the_world():
    with World("navworld", seed=1) as w:
        with pytest.raises(ValueError, match="pooled"):
            w.relayout(2)
    w = World("navworld", seed=1, kinematic="planar", pooled=True, rooms=1, room_size=6.0, clutter=6)
    before = w.model.geom_pos.copy(), w.meta
    with pytest.raises(ValueError, match="seed"):
        w.relayout(-1)
    np.testing.assert_array_equal(w.model.geom_pos, before[0])
    assert w.meta is before[1]
