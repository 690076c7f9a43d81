"""navworld: seeded rooms and clutter with a reachable, distant goal."""

import numpy as np
import pytest

from polar_sim.sim import World


# Start and goal are free, far apart, and the start is where the rover stands.
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_start_goal(seed):
    with World("navworld", seed=seed, kinematic=True) as w:
        start, goal = w.meta["start_pose2d"], w.meta["goal"]
        assert np.linalg.norm(goal - start[:2]) >= 5.0
        r = w.meta["robot_radius"]
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
