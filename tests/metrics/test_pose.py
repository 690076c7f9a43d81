"""Pose metrics against hand-computed cases: ADD, ADD-S, 5cm/5deg, AUC, BOP VSD/MSSD/MSPD."""

import numpy as np
import pytest

from polar_sim import metrics
from polar_sim.geometry import make_pose, so3_exp

CUBE = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) * 0.1


def _ring(n=360, r=0.05):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([r * np.cos(a), r * np.sin(a), np.zeros(n)], 1)


def test_add_of_pure_translation():
    # ADD of a 1 cm translation is exactly 10 mm, and ADD(GT, GT) = 0
    T = make_pose(so3_exp([0.1, 0.2, 0.3]), [0, 0, 1.0])
    T2 = T.copy()
    T2[:3, 3] += [0.01, 0, 0]
    assert metrics.add(CUBE, T, T2) == pytest.approx(0.01, abs=1e-12)
    assert metrics.add(CUBE, T, T) == 0.0


def test_add_of_rotation_about_origin():
    # rotating points at radius r by angle a moves each by the chord 2 r sin(a/2)
    P = _ring()
    Tr = make_pose(so3_exp([0, 0, np.pi / 3]), None)
    assert metrics.add(P, np.eye(4), Tr) == pytest.approx(2 * 0.05 * np.sin(np.pi / 6))


def test_adds_symmetric_object():
    # for a ring, a rotation by one sample step about its axis gives ADD-S = 0 while ADD > 0
    P = _ring()
    Tr = make_pose(so3_exp([0, 0, 2 * np.pi / 360 * 7]), None)
    assert metrics.adds(P, np.eye(4), Tr) == pytest.approx(0.0, abs=1e-12)
    assert metrics.add(P, np.eye(4), Tr) > 0.005
    # a translation along the axis is seen fully by ADD-S
    assert metrics.adds(P, np.eye(4), make_pose(None, [0, 0, 0.02])) == pytest.approx(0.02)


def test_stacks_give_per_frame_errors():
    # (n, 4, 4) stacks give (n,) errors
    G = np.stack([np.eye(4)] * 3)
    E = G.copy()
    E[:, 0, 3] = [0.0, 0.01, 0.02]
    assert np.allclose(metrics.add(CUBE, G, E), [0, 0.01, 0.02])
    assert np.allclose(metrics.translation_error(G, E), [0, 0.01, 0.02])


def test_rotation_error_and_5cm5deg():
    # 4 deg and 4 cm succeed, 6 deg or 6 cm fail
    G = np.stack([np.eye(4)] * 3)
    E = np.stack([make_pose(so3_exp([0, 0, np.deg2rad(4)]), [0.04, 0, 0]),
                  make_pose(so3_exp([0, 0, np.deg2rad(6)]), [0.0, 0, 0]),
                  make_pose(None, [0, 0.06, 0])])
    assert metrics.rotation_error(G[0], E[0]) == pytest.approx(np.deg2rad(4))
    assert metrics.success_5cm5deg(G, E) == pytest.approx(1 / 3)


def test_diameter():
    # the diameter of a 10 cm cube is its space diagonal
    assert metrics.object_diameter(CUBE) == pytest.approx(0.1 * np.sqrt(3))


def test_success_rates_and_auc():
    # success below k d, the success curve and the YCB AUC (closed form checked by integration)
    e = np.array([0.0, 0.005, 0.02, 0.05, 0.2])
    assert metrics.add_success(e, 0.1, 0.1) == pytest.approx(0.4)
    assert metrics.success_rate(e, 0.02) == pytest.approx(0.6)
    assert np.allclose(metrics.success_curve(e, [0, 0.01, 0.1]), [0.2, 0.4, 0.8])
    th = np.linspace(0, 0.1, 100001)
    numeric = np.trapezoid(metrics.success_curve(e, th), th) / 0.1
    assert metrics.pose_auc(e, 0.1) == pytest.approx(numeric, abs=1e-4)
    assert metrics.pose_auc([0.0], 0.1) == 1.0 and metrics.pose_auc([0.5], 0.1) == 0.0


def test_frames_until_loss():
    # the first run of `patience` bad frames marks the loss
    e = np.array([0, 0, 1, 0, 1, 1, 1, 0], float)
    assert metrics.frames_until_loss(e, 0.5, patience=3) == 4
    assert metrics.frames_until_loss(e, 0.5, patience=4) == len(e)


def test_mssd_and_symmetries():
    # MSSD is the max point displacement; a listed symmetry removes the error it explains
    P = CUBE - 0.05
    Tr = make_pose(so3_exp([0, 0, np.pi / 2]), None)
    assert metrics.mssd(P, np.eye(4), make_pose(None, [0.01, 0, 0])) == pytest.approx(0.01)
    # corners at radius 0.05 sqrt(2) from the axis, turned 90 deg: chord sqrt(2) r = 0.1
    assert metrics.mssd(P, np.eye(4), Tr) == pytest.approx(0.1)
    assert metrics.mssd(P, np.eye(4), Tr, symmetries=np.stack([np.eye(4), Tr])) == pytest.approx(0.0, abs=1e-12)


def test_mspd_of_lateral_shift():
    # a lateral shift dx at depth z moves every projection by f dx / z pixels
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    G = make_pose(None, [0, 0, 1.0])
    E = make_pose(None, [0.01, 0, 1.0])
    assert metrics.mspd(CUBE, K, G, E) == pytest.approx(5.0, rel=1e-9)
    assert metrics.ar_mspd([5.0], 640) == pytest.approx(0.9)  # below 10, 15, ..., 50 px: 9 of 10


def test_vsd_cases():
    # identical renderings: 0; a depth offset beyond every tau: 1; half the object shifted: 0.5
    K = np.array([[500.0, 0, 31.5], [0, 500.0, 23.5], [0, 0, 1]])
    d = np.zeros((48, 64))
    d[10:30, 10:50] = 1.0
    assert np.allclose(metrics.vsd(d, d, d, K, 0.1), 0.0)
    far = np.where(d > 0, 1.06, 0.0)  # 6 cm behind: more than the largest tau (0.5 d = 5 cm)
    assert np.allclose(metrics.vsd(far, d, d, K, 0.1), 1.0)
    half = d.copy()
    half[10:30, 30:50] = 1.2
    e = metrics.vsd(half, d, d, K, 0.1, taus=[0.2])
    # estimate's right half is 20 cm behind the test depth: not visible, counted as mismatch
    assert e[0] == pytest.approx(0.5, abs=0.02)


def test_render_depth_and_vsd_of_points():
    # the point-splat renderer gives the plane's depth and VSD of the true pose is 0
    K = np.array([[300.0, 0, 79.5], [0, 300.0, 59.5], [0, 0, 1]])
    g = np.stack(np.meshgrid(np.linspace(-0.05, 0.05, 60), np.linspace(-0.05, 0.05, 60)), -1).reshape(-1, 2)
    P = np.concatenate([g, np.zeros((len(g), 1))], 1)
    T = make_pose(None, [0, 0, 0.5])
    D = metrics.render_depth(P, K, T, (120, 160))
    assert np.allclose(D[D > 0], 0.5, atol=1e-6) and (D > 0).sum() > 0.8 * (0.1 * 300 / 0.5) ** 2
    assert np.allclose(metrics.vsd(D, D, D, K, 0.14), 0.0)
    assert metrics.ar_vsd(np.zeros((3, 10))) == 1.0


def test_ar_mssd():
    # recall averaged over the 10 thresholds 0.05 d ... 0.5 d
    assert metrics.ar_mssd([0.012], 0.1) == pytest.approx(0.8)


@pytest.mark.parametrize("call", [
    lambda: metrics.add(np.zeros((0, 3)), np.eye(4), np.eye(4)),
    lambda: metrics.add(CUBE, np.eye(4) * 2, np.eye(4)),
    lambda: metrics.add(CUBE, np.stack([np.eye(4)] * 2), np.stack([np.eye(4)] * 3)),
    lambda: metrics.adds(CUBE[:, :2], np.eye(4), np.eye(4)),
    lambda: metrics.add_success([0.1, np.nan], 0.1),
    lambda: metrics.add_success([0.1], -1.0),
    lambda: metrics.pose_auc([]),
    lambda: metrics.vsd(np.zeros((4, 4)), np.zeros((4, 5)), np.zeros((4, 4)), np.eye(3), 0.1),
    lambda: metrics.mspd(CUBE, np.eye(4), np.eye(4), np.eye(4)),
])
def test_bad_input_raises(call):
    # malformed points, poses, errors or images raise ValueError
    with pytest.raises(ValueError):
        call()


def _turning(angles_deg, axis=(0, 0, 1), t=(0, 0, 0.8)):
    return np.stack([make_pose(so3_exp(np.deg2rad(a) * np.asarray(axis, float)), t) for a in angles_deg])


def test_rotation_drift_of_object_at_rest():
    # the true pose is still; the estimate turns 0.1 deg per frame about z: drift = 0.1 k deg exactly,
    # whatever the true orientation
    G = np.stack([make_pose(so3_exp([0.3, -0.2, 0.5]), [0.1, 0, 0.7])] * 50)
    E = G @ _turning(0.1 * np.arange(50), t=(0, 0, 0))
    assert np.allclose(np.rad2deg(metrics.rotation_drift(G, E)), 0.1 * np.arange(50), atol=1e-9)
    assert np.allclose(np.rad2deg(metrics.rotation_drift(G, E, start=10)), 0.1 * np.arange(40), atol=1e-9)


def test_rotation_drift_follows_true_motion():
    # an estimate that turns exactly as the object does has no drift; a constant offset has none either
    G = _turning(np.linspace(0, 40, 30), axis=(1, 0, 0))
    off = make_pose(so3_exp([0, 0.2, 0]), [0.01, 0, 0])
    assert np.allclose(metrics.rotation_drift(G, G @ off), 0.0, atol=1e-7)
    assert metrics.rotation_drift(G, np.stack([G[0]] * 30))[-1] == pytest.approx(np.deg2rad(40))


def test_static_segments_and_drift():
    # 100 frames at rest, 20 frames turning 2 deg each, 81 frames at rest (the last turning frame
    # reaches the final angle): two runs; the estimate spins
    # 0.05 deg per frame throughout, so each run's drift is 0.05 deg times its (horizon-capped) length
    ang = np.concatenate([np.zeros(100), 2.0 * np.arange(1, 21), np.full(80, 40.0)])
    G = _turning(ang)
    E = G @ _turning(0.05 * np.arange(200), t=(0, 0, 0))
    assert metrics.static_segments(G) == [(0, 100), (119, 200)]
    d = metrics.static_rotation_drift(G, E, horizon=60)
    assert d.segments == [(0, 100), (119, 200)] and list(d.frames) == [60, 60]
    assert np.allclose(np.rad2deg(d.drift), 0.05 * 59) and d.max_drift == pytest.approx(np.deg2rad(0.05 * 59))
    assert np.isnan(metrics.static_rotation_drift(_turning(np.arange(50) * 3.0), _turning(np.arange(50) * 3.0)).max_drift)


def test_pose_frame_errors_match_the_single_metrics():
    # the per-frame bundle equals the separate metrics
    K = np.array([[500.0, 0, 160], [0, 500, 120], [0, 0, 1]])
    G = _turning(np.arange(5) * 3.0)
    E = G.copy()
    E[:, 0, 3] += 0.01
    out = metrics.pose_frame_errors(CUBE, K, G, E)
    assert np.allclose(out["add"], 0.01) and np.allclose(out["trans"], 0.01) and np.allclose(out["rot"], 0, atol=1e-6)
    assert np.allclose(out["mssd"], 0.01) and np.allclose(out["adds"], metrics.adds(CUBE, G, E))
