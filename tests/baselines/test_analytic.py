import numpy as np
import pytest
from baselines_scene import ANGLES, world_pose

from polar_sim.baselines import RoomSDF2D, RoomSDF3D
from polar_sim.registration import transform2d


def test_ray_end_points_lie_on_the_zero_level(room):
    # Exact ray casting and exact SDF agree: every end point has SDF 0.
    pose = world_pose(room, 2.0, 2.0, 0.3)
    r = room.scan(pose, ANGLES, sensor_offset=(0.1, 0.05))
    sensor = transform2d(pose, np.array([[0.1, 0.05]]))[0]
    a = ANGLES + pose[2]
    ends = sensor + r[:, None] * np.column_stack([np.cos(a), np.sin(a)])
    np.testing.assert_allclose(room.query(ends)[0], 0.0, atol=1e-9)


def test_sdf_gradient_is_unit_and_matches_finite_differences(room):
    # The gradient is a unit vector and the derivative of the SDF (inside, outside, in the pillar).
    rng = np.random.default_rng(0)
    local = np.column_stack([rng.uniform(-1, 11, 3000), rng.uniform(-1, 7, 3000)])
    P = local @ room._R.T + room._t
    _, g, var = room.query(P)
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-12)
    assert (var == 0).all()
    h = 1e-7
    for k in range(2):
        e = np.zeros(2)
        e[k] = h
        fd = (room.query(P + e)[0] - room.query(P - e)[0]) / (2 * h)
        ok = np.abs(fd - g[:, k]) < 1e-5
        assert ok.mean() > 0.99  # all but points on a medial axis, where the SDF has a kink


def test_known_distances(room):
    # Hand-checked values: room centre line, behind a wall, pillar centre, corner outside.
    local = np.array([[1.0, 3.0], [-0.5, 3.0], [6.0, 3.0], [-3.0, -4.0], [6.0, 4.0]])
    d, _, _ = room.query(local @ room._R.T + room._t)
    np.testing.assert_allclose(d, [1.0, -0.5, -0.5, -5.0, 0.5], atol=1e-12)


def test_depth_image_points_lie_on_the_surface():
    # Back-projected exact depth pixels of the 3D room have SDF 0.
    room = RoomSDF3D()
    K = np.array([[100.0, 0.0, 40.0], [0.0, 100.0, 30.0], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # camera looks along +x
    T[:3, 3] = [0.5, 1.5, 1.0]
    depth = room.depth_image(T, K, (60, 80))
    v, u = np.mgrid[0:60, 0:80]
    p = np.stack([(u - 40) / 100 * depth, (v - 30) / 100 * depth, depth], -1).reshape(-1, 3)
    np.testing.assert_allclose(room.query(p @ T[:3, :3].T + T[:3, 3])[0], 0.0, atol=1e-9)
    assert depth.min() < 2.0 - 0.4 + 1e-9  # the ball in front is seen


def test_bad_scene_and_sensor_raise(room):
    # Pillars outside the room and sensors inside obstacles are rejected with the argument named.
    with pytest.raises(ValueError, match="pillars"):
        RoomSDF2D(pillars=((9.9, 3.0, 0.5),))
    with pytest.raises(ValueError, match="origin"):
        room.scan(world_pose(room, 6.0, 3.0, 0.0), ANGLES)
    with pytest.raises(ValueError, match="pose2d"):
        room.scan((np.nan, 0.0, 0.0), ANGLES)
