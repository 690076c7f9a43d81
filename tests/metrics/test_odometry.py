import numpy as np
import pytest

from polar_sim import metrics
from polar_sim.metrics.odometry import (kitti_segment_errors, read_kitti, read_tum, scaled_lengths, write_kitti,
                                        write_tum)


def _planar(n, speed, yaw_bias=0.0, dt=0.1):
    """Spec §6.1 planar integration (semi-implicit Euler) of constant speed with a yaw-rate bias."""
    T = np.tile(np.eye(4), (n, 1, 1))
    psi = x = z = 0.0
    for k in range(1, n):
        psi += yaw_bias * dt
        x += dt * speed * np.sin(psi)
        z += dt * speed * np.cos(psi)
        c, s = np.cos(psi), np.sin(psi)
        T[k, :3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
        T[k, 0, 3], T[k, 2, 3] = x, z
    return T


@pytest.fixture(scope="module")
def straight():
    return _planar(3000, 10.0)


def test_kitti_identical_poses_give_zero(straight):
    # T5: identical trajectories -> 0 % and 0 deg/m.
    assert metrics.kitti_errors(straight, straight) == (0.0, 0.0)


def test_kitti_speed_scale_error(straight):
    # T5: speed x 1.05 on a straight 10 m/s route of 3000 frames -> t = 5.02 %, r = 0 (the 0.02 % comes
    # from the devkit's end frame, the first whose path length *exceeds* start + L, i.e. L + 1 m here).
    t, r = metrics.kitti_errors(straight, _planar(3000, 10.5))
    assert round(t, 2) == 5.02 and r == 0.0
    # Hand computation: each record has t_err = 0.05 (L + 1) / L; the mean over the records.
    recs = kitti_segment_errors(straight, _planar(3000, 10.5))
    expect = np.mean([0.05 * (L + 1) / L for L in recs["length"]]) * 100
    assert t == pytest.approx(expect, rel=1e-5)


def test_kitti_yaw_bias(straight):
    # T5: a yaw-rate bias of 0.001 rad/s -> r = 0.00575 deg/m (= bias / V) and t = 2.16 %.
    t, r = metrics.kitti_errors(straight, _planar(3000, 10.0, yaw_bias=0.001))
    assert round(r, 5) == 0.00575 and round(t, 2) == 2.16


def test_kitti_segments_follow_the_devkit(straight):
    # Start frames every 10 images, 8 lengths, end frame = first with s_b > s_a + L, speed L / (0.1 (b-a+1)).
    recs = kitti_segment_errors(straight, straight)
    assert set(np.unique(recs["first"]) % 10) == {0}
    r100 = recs[(recs["first"] == 0) & (recs["length"] == 100)][0]
    assert r100["speed"] == pytest.approx(100 / (0.1 * 102))
    assert len(recs[recs["first"] == 0]) == 8
    assert recs[recs["length"] == 800]["first"].max() == 2190  # last start with s_b > s_a + 800 inside 3000 frames
    assert recs[recs["length"] == 100]["first"].max() == 2890
    assert np.isnan(metrics.kitti_errors(straight[:50], straight[:50])[0])


def test_kitti_pooled_weighs_segments(straight):
    # The pooled score is the mean over all records of all sequences, not the mean of the sequence means.
    a = (straight, _planar(3000, 10.5))
    b = (straight[:1200], straight[:1200])
    t, _ = metrics.kitti_errors_pooled([a, b])
    na = len(kitti_segment_errors(*a))
    nb = len(kitti_segment_errors(*b))
    assert t == pytest.approx(metrics.kitti_errors(*a)[0] * na / (na + nb), rel=1e-5)


def test_scaled_lengths_for_short_routes(straight):
    # Short routes get L_j = j L_max / 8 with L_max = 90 % of the route, rounded down to 10 m.
    L = scaled_lengths(straight[:301])
    assert L[-1] == 270.0 and len(L) == 8 and L[0] == pytest.approx(33.75)
    t, r = metrics.kitti_errors(straight[:301], _planar(301, 10.5), lengths=L)
    assert 5.0 < t < 5.2 and r == 0.0


def test_ate_hand_cases(straight):
    # A constant 1 m offset: ATE 1 m unaligned, 0 after SE(3) alignment; a rotated copy is 0 after alignment.
    g = straight[:100]
    e = g.copy()
    e[:, 0, 3] += 1.0
    assert metrics.ate(g, e, align="none") == pytest.approx(1.0)
    assert metrics.ate(g, e) == pytest.approx(0.0, abs=1e-9)
    R = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    rot = g.copy()
    rot[:, :3, :3] = R @ g[:, :3, :3]
    rot[:, :3, 3] = g[:, :3, 3] @ R.T
    assert metrics.ate(g, rot) == pytest.approx(0.0, abs=1e-9)
    # Scale 2: SE(3) cannot fix it, Sim(3) can.
    s = g.copy()
    s[:, :3, 3] *= 2
    assert metrics.ate(g, s, align="sim3") == pytest.approx(0.0, abs=1e-9) and metrics.ate(g, s) > 1.0


def test_rpe_hand_cases(straight):
    # Speed x 1.05 at 1 m per frame: every 1-frame translation error is 0.05 m, no rotation error.
    out = metrics.rpe(straight[:200], _planar(200, 10.5), delta=1)
    assert out.trans_rmse == pytest.approx(0.05) and out.rot_rmse == pytest.approx(0.0, abs=1e-6)
    # A yaw-rate bias of 0.01 rad/s: each 10-frame rotation error is 0.01 rad = 0.573 deg.
    out = metrics.rpe(straight[:200], _planar(200, 10.0, yaw_bias=0.01), delta=10)
    assert out.rot_mean == pytest.approx(np.degrees(0.01), rel=1e-6) and out.delta == 10


def test_kitti_and_tum_round_trip(tmp_path, straight):
    # Writing then reading KITTI and TUM files gives the same poses (and timestamps).
    P = _planar(50, 7.0, yaw_bias=0.2)
    write_kitti(tmp_path / "p.txt", P)
    np.testing.assert_allclose(read_kitti(tmp_path / "p.txt"), P, atol=1e-15)
    t = np.arange(50) * 0.1 + 1e9
    write_tum(tmp_path / "p.tum", t, P)
    t2, P2 = read_tum(tmp_path / "p.tum")
    np.testing.assert_array_equal(t2, t)
    np.testing.assert_allclose(P2, P, atol=1e-12)
    line = (tmp_path / "p.txt").read_text().splitlines()[0].split()
    assert len(line) == 12


def test_bad_input():
    # Mismatched lengths, wrong shapes, NaN or non-rigid poses raise ValueError naming the argument.
    g = np.tile(np.eye(4), (5, 1, 1))
    with pytest.raises(ValueError, match="est_poses"):
        metrics.kitti_errors(g, g[:4])
    with pytest.raises(ValueError, match="gt_poses"):
        metrics.ate(g[:, :3], g)
    bad = g.copy()
    bad[2, 0, 0] = np.nan
    with pytest.raises(ValueError, match="est_poses"):
        metrics.rpe(g, bad)
    bad = g.copy()
    bad[2, :3, :3] *= 2
    with pytest.raises(ValueError, match="est_poses"):
        metrics.ate(g, bad)
    with pytest.raises(ValueError, match="delta"):
        metrics.rpe(g, g, delta=0)
