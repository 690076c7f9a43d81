import numpy as np
import pytest

from polar_sim.baselines import DiscreteSDF2D, RoomSDF2D, RoomSDF3D
from polar_sim.errors import NotUpdatedError
from polar_sim.geometry import se3_exp, so3_log
from polar_sim.gpis.localize import localize

ANGLES = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 1081)
PERTURB = np.array([0.3 * np.cos(1.0), 0.3 * np.sin(1.0), np.radians(10.0)])
K = np.array([[120.0, 0.0, 80.0], [0.0, 120.0, 60.0], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def room():
    # A 10 m x 6 m room with a round pillar, off the world axes: exact SDF, gradient and ranges.
    return RoomSDF2D(size=(10.0, 6.0), pillars=((6.0, 3.0, 0.5),), pose=(0.37, -0.21, 0.35))


def _err2d(est, truth):
    dth = (est[2] - truth[2] + np.pi) % (2 * np.pi) - np.pi
    return np.hypot(*(est[:2] - truth[:2])), abs(np.degrees(dth))


def _err3d(T, T_true):
    return np.linalg.norm(T[:3, 3] - T_true[:3, 3]), np.degrees(np.linalg.norm(so3_log(T_true[:3, :3].T @ T[:3, :3])))


def _camera():
    # A camera at 1.2 m looking along +x, yawed and pitched so it sees the walls, floor and the ball.
    T = np.eye(4)
    T[:3, :3] = se3_exp([0, 0, 0.3, 0, 0, 0])[:3, :3] @ se3_exp([0.2, 0, 0, 0, 0, 0])[:3, :3] @ np.array(
        [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    T[:3, 3] = [0.6, 1.3, 1.2]
    return T


def _perturb3d():
    axis = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
    return se3_exp(np.r_[np.radians(10.0) * axis, 0.3 * np.array([0.6, -0.64, 0.48])])


class OffsetRoom:
    """The analytic room seen through a map that carries a sensor offset, like GPISMap2D."""

    def __init__(self, room, offset):
        self.room, self.sensor_offset = room, offset

    def query(self, points):
        return self.room.query(points)


class EmptyMap:
    def query(self, points):
        raise NotUpdatedError("EmptyMap has no data yet")


@pytest.mark.parametrize("truth", [(2.5, 1.9, 0.7), (7.0, 2.5, -2.5), (4.0, 4.0, 3.0)])
@pytest.mark.parametrize("robust", ["huber", "tukey", "none"])
def test_icp_g_recovers_a_known_perturbation(room, truth, robust):
    # On the exact SDF a 0.3 m / 10 deg error is removed to round-off with every robust kernel.
    truth = np.array(truth)
    pose, cov, info = localize(room, (ANGLES, room.scan(truth, ANGLES)), truth + PERTURB, robust=robust)
    dp, dth = _err2d(pose, truth)
    assert info["status"] == "ok" and dp < 1e-6 and dth < 1e-5
    assert info["n_valid"] == 1081 and 10 <= info["n_points"] <= 200


def test_icp_g_with_range_noise_and_a_consistent_covariance(room):
    # 1 cm range noise: errors stay below 1 cm / 0.2 deg and the GN covariance matches their spread.
    truth = np.array([2.5, 1.9, 0.7])
    r0 = room.scan(truth, ANGLES)
    errs, sd = [], []
    for seed in range(60):
        r = r0 + np.random.default_rng(seed).normal(0.0, 0.01, r0.shape)
        pose, cov, info = localize(room, (ANGLES, r), truth + PERTURB)
        assert info["status"] == "ok"
        errs.append(pose - truth)
        sd.append(np.sqrt(np.diag(cov)))
    errs = np.array(errs)
    assert np.hypot(errs[:, 0], errs[:, 1]).max() < 0.01 and np.degrees(np.abs(errs[:, 2])).max() < 0.2
    ratio = errs.std(axis=0) / np.mean(sd, axis=0)
    assert ((ratio > 0.6) & (ratio < 1.6)).all(), ratio


def test_step_control_tames_an_overshooting_field(room):
    # An SDF 2.5x too steep makes plain Gauss-Newton overshoot and diverge; halving steps converges.
    class Steep:
        def query(self, points):
            d, g, v = room.query(points)
            return 2.5 * d, g, v

    truth = np.array([2.5, 1.9, 0.7])
    pose, _, info = localize(Steep(), (ANGLES, room.scan(truth, ANGLES)), truth + PERTURB, robust="none")
    dp, dth = _err2d(pose, truth)
    assert info["status"] == "ok" and dp < 1e-3 and dth < 0.01


def test_sensor_offset_from_the_map_or_the_keyword(room):
    # The base pose is recovered when the laser sits at an offset given by the map or by keyword.
    truth = np.array([3.0, 2.0, 0.4])
    off = (0.25, -0.1)
    scan = (ANGLES, room.scan(truth, ANGLES, sensor_offset=off))
    a, _, _ = localize(OffsetRoom(room, off), scan, truth + PERTURB)
    b, _, _ = localize(room, scan, truth + PERTURB, sensor_offset=off)
    assert _err2d(a, truth)[0] < 1e-6 and _err2d(b, truth)[0] < 1e-6


def test_icp_g_runs_on_a_discrete_sdf(room):
    # Any map with query() works: a signed EDT built from the true occupancy at 2 cm.
    cs = 0.02
    xs = np.arange(-1.0, 11.0, cs) + cs / 2
    ys = np.arange(-1.5, 7.0, cs) + cs / 2
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    d, _, _ = room.query(np.column_stack([X.ravel(), Y.ravel()]))
    occ = (np.abs(d) <= cs / 2).reshape(X.shape)
    sdf = DiscreteSDF2D().fit(occ, (xs[0] - cs / 2, ys[0] - cs / 2), cs, free=(d > cs / 2).reshape(X.shape))
    truth = np.array([3.0, 2.0, 0.4])
    pose, _, info = localize(sdf, (ANGLES, room.scan(truth, ANGLES)), truth + PERTURB)
    dp, dth = _err2d(pose, truth)
    assert info["status"] == "ok" and dp < 0.01 and dth < 0.2


def test_icp_g_on_se3_from_a_depth_image():
    # SE(3): a depth image of the 3D room, camera moved 0.3 m / 10 deg, is registered to round-off.
    room = RoomSDF3D()
    T = _camera()
    depth = room.depth_image(T, K, (120, 160))
    depth[:10] = np.nan  # some pixels without return
    pose, cov, info = localize(room, (depth, K), _perturb3d() @ T)
    dp, dr = _err3d(pose, T)
    assert info["status"] == "ok" and dp < 1e-6 and dr < 1e-5
    assert cov.shape == (6, 6) and info["n_valid"] > info["n_points"]


def test_icp_g_on_se3_from_a_3d_lidar():
    # SE(3): directions + ranges of a 16-ring lidar are registered the same way.
    room = RoomSDF3D()
    az, el = np.meshgrid(np.linspace(-np.pi, np.pi, 360, endpoint=False), np.radians(np.linspace(-15, 15, 16)))
    dirs = np.column_stack([(np.cos(el) * np.cos(az)).ravel(), (np.cos(el) * np.sin(az)).ravel(), np.sin(el).ravel()])
    T = np.eye(4)
    T[:3, 3] = [1.2, 1.0, 1.0]
    pose, _, info = localize(room, (dirs, room.ranges(T, dirs)), _perturb3d() @ T)
    dp, dr = _err3d(pose, T)
    assert info["status"] == "ok" and dp < 1e-6 and dr < 1e-5


def test_scan_without_valid_beams_returns_the_prior(room):
    # All beams without return: the prior comes back with status "no_data", and nothing raises.
    prior = np.array([3.0, 2.0, 0.4])
    for r in (np.full(ANGLES.shape, np.inf), np.full(ANGLES.shape, np.nan)):
        pose, cov, info = localize(room, (ANGLES, r), prior)
        np.testing.assert_array_equal(pose, prior)
        assert info["status"] == "no_data" and np.isinf(np.diag(cov)).all()


def test_scan_outside_the_mapped_area_is_no_data(room):
    # If the map's variance says it knows nothing where the points fall, there is no estimate.
    class Unknown:
        def query(self, p):
            d, g, _ = room.query(p)
            return d, g, np.ones(len(p))

    prior = np.array([3.0, 2.0, 0.4])
    pose, _, info = localize(Unknown(), (ANGLES, room.scan(prior, ANGLES)), prior)
    assert info["status"] == "no_data"
    np.testing.assert_array_equal(pose, prior)


def test_divergence_and_iteration_limit_are_reported(room):
    # Moving beyond max_correction is "diverged" (prior returned); one iteration is "max_iter".
    truth = np.array([3.0, 2.0, 0.4])
    scan = (ANGLES, room.scan(truth, ANGLES))
    pose, _, info = localize(room, scan, truth + PERTURB, max_correction=(0.05, 0.05))
    assert info["status"] == "diverged"
    np.testing.assert_array_equal(pose, truth + PERTURB)
    pose, cov, info = localize(room, scan, truth + PERTURB, max_iterations=1)
    assert info["status"] == "max_iter" and info["iterations"] == 1 and np.isfinite(cov).all()


def test_empty_map_raises(room):
    # A map without data is an error, whether or not the scan has valid beams.
    for r in (room.scan(np.array([3.0, 2.0, 0.4]), ANGLES), np.full(ANGLES.shape, np.inf)):
        with pytest.raises(ValueError, match="map"):
            localize(EmptyMap(), (ANGLES, r), np.array([3.0, 2.0, 0.4]))
    with pytest.raises(ValueError, match="map"):
        localize(DiscreteSDF2D(), (ANGLES, r), np.array([3.0, 2.0, 0.4]))


@pytest.mark.parametrize("pose", [(np.nan, 0.0, 0.0), (0.0, np.inf, 0.0), (0.0, 0.0)])
def test_bad_initial_pose_raises(room, pose):
    # A non-finite or malformed initial pose raises ValueError naming it.
    with pytest.raises(ValueError, match="initial_pose"):
        localize(room, (ANGLES, np.ones_like(ANGLES)), np.array(pose))


def test_bad_scan_and_map_raise(room):
    # Mismatched lengths, negative ranges, a 3D map for a 2D scan, or a non-map name the argument.
    prior = np.array([3.0, 2.0, 0.4])
    with pytest.raises(ValueError, match="ranges"):
        localize(room, (ANGLES, np.ones(5)), prior)
    with pytest.raises(ValueError, match="ranges"):
        localize(room, (ANGLES, -np.ones_like(ANGLES)), prior)
    with pytest.raises(ValueError, match="map"):
        localize(RoomSDF3D(), (ANGLES, np.ones_like(ANGLES)), prior)
    with pytest.raises(TypeError, match="map"):
        localize(object(), (ANGLES, np.ones_like(ANGLES)), prior)
    with pytest.raises(ValueError, match="robust"):
        localize(room, (ANGLES, np.ones_like(ANGLES)), prior, robust="cauchy")
    with pytest.raises(ValueError, match="K"):
        localize(RoomSDF3D(), (np.ones((4, 4)), np.eye(3) * -1), np.eye(4))


class _QueryOnly:
    """A GPIS map seen only through its query (register_sdf's Python loop)."""

    def __init__(self, m):
        self.m = m

    def query(self, points):
        return self.m.query(points)


# the compiled ICP-G loop of a planar GPIS map (GPISMap2D._register_native) gives the same bits
# as register_sdf's Python loop on the same map, converged, backtracked, diverged or stopped
@pytest.mark.parametrize("kw,status", [({}, "ok"), ({"robust": "tukey"}, "ok"),
                                       ({"max_iterations": 1}, "max_iter"),
                                       ({"max_correction": (0.01, 0.01)}, "diverged"),
                                       ({"max_variance": 1e-9}, "no_data")])
def test_compiled_icp_matches_python_loop(room, kw, status):
    from polar_sim.gpis import GPISMap2D

    ang = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 270)
    m = GPISMap2D()
    for k in range(8):
        pose = np.array([2.5 + 0.3 * k, 1.9 + 0.1 * k, 0.7 + 0.05 * k])
        m.update(ang, room.scan(pose, ang), pose)
    truth = np.array([3.4, 2.2, 0.85])
    scan = (ang, room.scan(truth, ang))
    start = truth + [0.05, -0.04, 0.03]
    a = localize(m, scan, start, **kw)
    b = localize(_QueryOnly(m), scan, start, **kw)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert a[2].keys() == b[2].keys()
    for k in a[2]:
        assert a[2][k] == b[2][k] or (np.isnan(a[2][k]) and np.isnan(b[2][k])), k
    assert a[2]["status"] == status
