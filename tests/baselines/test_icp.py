import numpy as np
import pytest
from baselines_scene import ANGLES, pose_error, world_pose

from polar_sim.baselines import DiscreteSDF2D, ICPLocalizer, RoomSDF3D
from polar_sim.errors import NotUpdatedError
from polar_sim.geometry import se3_exp, so3_log
from polar_sim.metrics import sample_polyline

# The perturbation of the brief: 0.3 m and 10 deg.
PERTURB = np.array([0.3 * np.cos(1.0), 0.3 * np.sin(1.0), np.radians(10.0)])
TRUE_POSES_ROOM = [(3.0, 2.0, 0.4), (7.5, 4.2, -2.0), (4.0, 4.5, 1.2)]


@pytest.mark.parametrize("pose_room", TRUE_POSES_ROOM)
def test_icp_d_recovers_a_known_perturbation(room, mapped_grid, pose_room):
    # ICP-D on the signed EDT of a 5 cm grid brings a 0.3 m / 10 deg error below 1 cm / 0.2 deg.
    truth = world_pose(room, *pose_room)
    icp = ICPLocalizer(method="sdf").fit(mapped_grid)
    pose, cov, info = icp.localize((ANGLES, room.scan(truth, ANGLES)), truth + PERTURB)
    dp, dth = pose_error(pose, truth)
    assert info["status"] == "ok"
    assert dp < 0.01 and dth < 0.2
    assert cov.shape == (3, 3) and np.all(np.linalg.eigvalsh(cov) > 0)


@pytest.mark.parametrize("pose_room", TRUE_POSES_ROOM)
def test_point_icp_recovers_a_known_perturbation(room, pose_room):
    # Point-to-point ICP against 5 mm samples of the true walls brings the error below 1 cm / 0.2 deg.
    truth = world_pose(room, *pose_room)
    ref = np.vstack([sample_polyline(p, 0.005) for p in room.polylines()])
    icp = ICPLocalizer(method="point", max_iterations=100).fit(ref)
    pose, cov, info = icp.localize((ANGLES, room.scan(truth, ANGLES)), truth + PERTURB)
    dp, dth = pose_error(pose, truth)
    assert info["status"] == "ok"
    assert dp < 0.01 and dth < 0.2
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_point_icp_on_grid_surface_points(room, mapped_grid):
    # Point-to-point ICP also runs on a grid's surface cells, to within the grid's resolution.
    truth = world_pose(room, *TRUE_POSES_ROOM[0])
    icp = ICPLocalizer(method="point", max_iterations=100).fit(mapped_grid)
    pose, _, info = icp.localize((ANGLES, room.scan(truth, ANGLES)), truth + PERTURB)
    dp, dth = pose_error(pose, truth)
    assert info["status"] == "ok" and dp < 0.02 and dth < 0.5


def test_icp_d_accepts_a_prebuilt_field(room, mapped_grid):
    # fit() takes a DiscreteSDF2D as well as a grid, with the same result.
    truth = world_pose(room, *TRUE_POSES_ROOM[0])
    scan = (ANGLES, room.scan(truth, ANGLES))
    a = ICPLocalizer().fit(mapped_grid).localize(scan, truth + PERTURB)[0]
    b = ICPLocalizer().fit(DiscreteSDF2D.from_grid(mapped_grid)).localize(scan, truth + PERTURB)[0]
    np.testing.assert_array_equal(a, b)


def test_icp_without_valid_beams_returns_the_prior(room, mapped_grid):
    # No valid beam: both methods return the prior pose with status "no_data".
    prior = world_pose(room, 3.0, 2.0, 0.4)
    scan = (ANGLES, np.full(ANGLES.shape, np.nan))
    for icp in (ICPLocalizer(method="sdf").fit(mapped_grid), ICPLocalizer(method="point").fit(mapped_grid)):
        pose, _, info = icp.localize(scan, prior)
        np.testing.assert_array_equal(pose, prior)
        assert info["status"] == "no_data"


def test_icp_bad_input_raises(room, mapped_grid):
    # Unknown method, use before fit, and a non-finite initial pose raise ValueError naming the argument.
    with pytest.raises(ValueError, match="method"):
        ICPLocalizer(method="plane").fit(mapped_grid)
    with pytest.raises(NotUpdatedError):
        ICPLocalizer().localize((ANGLES, np.ones_like(ANGLES)), np.zeros(3))
    for method in ("sdf", "point"):
        icp = ICPLocalizer(method=method).fit(mapped_grid)
        with pytest.raises(ValueError, match="initial_pose"):
            icp.localize((ANGLES, np.ones_like(ANGLES)), np.array([0.0, np.inf, 0.0]))
    with pytest.raises(ValueError, match="target"):
        ICPLocalizer(method="point").fit(np.zeros((5, 4)))


def test_point_icp_in_3d_from_a_depth_image():
    # SE(3) point-to-point ICP: a depth image registered to the clouds of two other views of the room.
    room = RoomSDF3D()
    base = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # optical axis along +x

    def cam(yaw, pitch, t):
        T = np.eye(4)
        T[:3, :3] = se3_exp([0, 0, yaw, 0, 0, 0])[:3, :3] @ se3_exp([pitch, 0, 0, 0, 0, 0])[:3, :3] @ base
        T[:3, 3] = t
        return T

    def cloud(T, K, shape):
        d = room.depth_image(T, K, shape)
        v, u = np.mgrid[0 : shape[0], 0 : shape[1]]
        p = np.stack([(u - K[0, 2]) / K[0, 0] * d, (v - K[1, 2]) / K[1, 1] * d, d], -1).reshape(-1, 3)
        return p @ T[:3, :3].T + T[:3, 3]

    K_map = np.array([[240.0, 0.0, 160.0], [0.0, 240.0, 120.0], [0.0, 0.0, 1.0]])
    K = np.array([[120.0, 0.0, 80.0], [0.0, 120.0, 60.0], [0.0, 0.0, 1.0]])
    cloud_map = np.vstack([cloud(cam(0.1, 0.25, [0.5, 1.4, 1.3]), K_map, (240, 320)),
                           cloud(cam(0.5, 0.1, [0.7, 1.0, 1.1]), K_map, (240, 320))])
    T = cam(0.3, 0.2, [0.6, 1.3, 1.2])
    axis = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
    T0 = se3_exp(np.r_[np.radians(5.0) * axis, 0.1 * np.array([0.6, -0.64, 0.48])]) @ T
    icp = ICPLocalizer(method="point", max_iterations=100).fit(cloud_map)
    pose, cov, info = icp.localize((room.depth_image(T, K, (120, 160)), K), T0)
    assert info["status"] == "ok" and cov.shape == (6, 6)
    assert np.linalg.norm(pose[:3, 3] - T[:3, 3]) < 0.01
    assert np.degrees(np.linalg.norm(so3_log(T[:3, :3].T @ pose[:3, :3]))) < 0.5
