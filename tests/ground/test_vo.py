import copy

import numpy as np
import pytest

from ground_helpers import DT, HEIGHT, SPEED, YAW_RATE, run
from polar_sim.ground import STATUSES, FilterConfig, GroundModelConfig, GroundVO, MotionConfig, TrackingConfig


def _vo(seq, **kw):
    return GroundVO(seq["K"], seq["camera_height"], seed=0, **kw)


@pytest.fixture(scope="module")
def default_run(corridor):
    vo = _vo(corridor)
    return vo, run(vo, corridor)


def test_end_to_end_recovers_speed_and_yaw_rate(corridor, default_run):
    # GroundVO on the rendered corridor (h = 1 m, V = 5 m/s, ω = 0.1 rad/s) recovers V and ω.
    # Bound: the raw per-frame estimates scatter with sample std s (KLT noise, measured here); their mean
    # over n frames must lie within 3 s/√n of the truth plus a 2 % allowance for the residual tracking bias
    # (sub-pixel KLT error on strongly foreshortened near ground, measured 0.5–1 % on this scene).
    vo, es = default_run
    assert [e.status for e in es[:2]] == ["init", "init"]
    assert all(e.status == "ok" for e in es[2:])
    raw_v = np.array([e.speed_raw for e in es[2:]])
    raw_w = np.array([e.yaw_rate_raw for e in es[2:]])
    n = len(raw_v)
    assert abs(raw_v.mean() - SPEED) < 3 * raw_v.std() / np.sqrt(n) + 0.02 * SPEED
    assert abs(raw_w.mean() - YAW_RATE) < 3 * raw_w.std() / np.sqrt(n) + 0.02 * YAW_RATE
    # The filtered values settle within 5 % (speed) and 3 % (yaw rate) once started from the prior (0, 0).
    assert all(abs(e.speed - SPEED) < 0.05 * SPEED for e in es[8:])
    assert all(abs(e.yaw_rate - YAW_RATE) < 0.03 * YAW_RATE for e in es[8:])


def test_end_to_end_pose_follows_the_true_path(corridor, default_run):
    # One pose per image, the first the identity; the final position within 5 % of the distance driven.
    vo, es = default_run
    traj = vo.trajectory()
    assert traj.shape == (20, 4, 4) and np.array_equal(traj[0], np.eye(4))
    np.testing.assert_allclose(traj[-1], es[-1].pose)
    gt = corridor["poses"]
    dist = SPEED * DT * 19
    assert np.linalg.norm(traj[-1][:3, 3] - gt[-1][:3, 3]) < 0.05 * dist
    # Planar integration: no height, rotation about y only.
    assert np.allclose(traj[:, 1, 3], 0) and np.allclose(traj[:, 1, :3], [0, 1, 0])
    assert es[1].diagnostics["pose_provisional"] and not es[2].diagnostics["pose_provisional"]


def test_ground_probability_learns_the_ground(corridor, default_run):
    # After a few frames the colour classifier separates ground from walls and sky (IoU > 0.85).
    from polar_sim.metrics.ground import classifier_auc, classifier_iou

    vo, es = default_run
    e = es[-1]
    assert e.ground_prob.shape == (480, 640) and e.ground_prob.dtype == np.float32
    mask = corridor["ground_mask"][-1]
    assert classifier_iou(e.ground_prob, mask) > 0.85
    assert classifier_auc(e.ground_prob, mask) > 0.95
    # Inliers are candidates, in input pixel coordinates, below the principal row, mostly on true ground.
    assert e.inliers.shape[1] == 2 and len(e.inliers) >= 10
    assert np.all(e.candidates[:, 1] > corridor["K"][1, 2])
    prev_mask = corridor["ground_mask"][e.diagnostics["middle_index"]]
    r, c = np.rint(e.inliers[:, 1]).astype(int), np.rint(e.inliers[:, 0]).astype(int)
    # (far non-ground points just below the horizon have d̄ ≈ 0 and fit any ground model: precision < 1)
    assert prev_mask[r, c].mean() > 0.7
    assert e.diagnostics["weighted"] and e.diagnostics["ransac_iterations"] == 55


@pytest.mark.parametrize("kw", [dict(model="2param", sampling="uniform"), dict(model="plane3"),
                                dict(model="3param"), dict(published=True), dict(integration="3d"),
                                dict(downsample=1, tracking=TrackingConfig(max_features=300)),
                                dict(motion=MotionConfig(estimate_foe=True)),
                                dict(motion=MotionConfig(n_global=1, exact_flow=False),
                                     tracking=TrackingConfig(ground_warp=False))])
def test_variants_run_and_estimate_speed(corridor, kw):
    # Every model, the published behaviour, 3-D integration, full resolution and the FOE variant track the speed.
    kw = dict(kw)
    make = GroundVO.published if kw.pop("published", False) else GroundVO
    es = run(make(corridor["K"], corridor["camera_height"], seed=0, **kw), corridor, range(12))
    raw = np.array([e.speed_raw for e in es[2:]])
    assert np.nanmedian(raw) == pytest.approx(SPEED, rel=0.1)
    assert all(e.status in STATUSES for e in es)


def test_same_seed_same_result_and_copy_continues(corridor):
    # Same seed -> bit-identical estimates; a deep copy of an estimator continues exactly like the original.
    a, b = _vo(corridor), _vo(corridor)
    ea = run(a, corridor, range(6))
    eb = run(b, corridor, range(4))
    c = copy.deepcopy(b)
    eb += run(c, corridor, range(4, 6))
    for x, y in zip(ea, eb):
        assert x.speed == y.speed and x.yaw_rate == y.yaw_rate and np.array_equal(x.pose, y.pose)
        assert np.array_equal(x.inlier_mask, y.inlier_mask) and np.array_equal(x.ground_prob, y.ground_prob)


def test_bad_input_raises_and_leaves_the_estimator_unchanged(corridor):
    # Wrong shape/dtype, another image size, non-increasing or NaN time: ValueError/TypeError, state intact.
    ref = run(_vo(corridor), corridor, range(6))
    vo = _vo(corridor)
    run(vo, corridor, range(3))
    img, t = corridor["rgb"][3], corridor["times"][3]
    bad = [(img.astype(np.float32), t), (img[..., 0], t), (img[:, :, :2], t), (img[:240], t),
           (img, corridor["times"][2]), (img, corridor["times"][1]), (img, float("nan")), ("x", t),
           (img, "0.3")]
    for im, tt in bad:
        with pytest.raises((ValueError, TypeError)):
            vo.process(im, tt)
    out = run(vo, corridor, range(3, 6))
    for x, y in zip(ref[3:], out):
        assert x.speed == y.speed and np.array_equal(x.pose, y.pose)


@pytest.mark.parametrize("kw,match", [(dict(K=np.eye(2)), "K"), (dict(K=np.full((3, 3), np.nan)), "K"),
                                      (dict(camera_height=0.0), "camera_height"),
                                      (dict(camera_height=-1.0), "camera_height"),
                                      (dict(model="9param"), "model"), (dict(sampling="greedy"), "sampling"),
                                      (dict(downsample=3), "downsample"), (dict(integration="2d"), "integration")])
def test_bad_parameters_raise_value_error(corridor, kw, match):
    # K not 3x3, non-positive camera height, unknown choices: ValueError naming the argument.
    args = dict(K=corridor["K"], camera_height=1.0)
    args.update(kw)
    K, h = args.pop("K"), args.pop("camera_height")
    with pytest.raises(ValueError, match=match):
        GroundVO(K, h, **args)


def test_black_frame_coasts_and_recovers(corridor):
    # A black image does not raise: status "no_features", filters coast, tracking restarts afterwards.
    vo = _vo(corridor)
    es = run(vo, corridor, range(8))
    v_before, w_before = es[-1].speed, es[-1].yaw_rate
    e = vo.process(np.zeros_like(corridor["rgb"][0]), corridor["times"][8])
    assert e.status == "no_features" and e.diagnostics["n_tracked"] == 0
    assert e.speed == v_before and e.yaw_rate == w_before
    assert np.isnan(e.speed_raw) and len(e.candidates) == 0
    after = run(vo, corridor, range(9, 14))
    assert after[0].status == "few_triplets" and after[-1].status == "ok"
    assert len(vo.trajectory()) == 14


def test_static_scene_zeroes_the_speed(corridor):
    # The same image again and again: the static test fires, speed and yaw rate are reset to 0.
    vo = _vo(corridor)
    run(vo, corridor, range(6))
    for i in range(3):
        e = vo.process(corridor["rgb"][5], corridor["times"][5] + (i + 1) * DT)
    assert e.status == "static" and e.diagnostics["static"]
    assert e.speed == 0.0 and e.yaw_rate == 0.0
    T = vo.trajectory()
    np.testing.assert_allclose(T[-1], T[-2])


def test_no_ground_candidates_coasts(corridor):
    # With the horizon set below the image no point is a ground candidate: status "no_ground", no raise.
    vo = _vo(corridor, ground=GroundModelConfig(horizon_row=479.5), filters=FilterConfig(speed_prior=4.0))
    es = run(vo, corridor, range(6))
    assert all(e.status == "no_ground" for e in es[2:])
    assert all(e.speed == 4.0 for e in es) and all(e.diagnostics["n_inliers"] == 0 for e in es)
    assert np.isfinite(es[-1].yaw_rate_raw)


def test_reset_forgets_state(corridor):
    # reset() removes the learned state; the next image starts a new sequence at the identity.
    vo = _vo(corridor)
    run(vo, corridor, range(4))
    vo.reset()
    assert not [k for k in vars(vo) if k.endswith("_")]
    e = vo.process(corridor["rgb"][0], 0.0)
    assert e.index == 0 and np.array_equal(e.pose, np.eye(4))


def test_pitched_camera_with_known_pitch():
    # A camera pitched 10° down: with camera_pitch the rays are de-rotated and V, ω, pose are recovered;
    # the poses stay camera poses (the integrated camera rotation includes the pitch conjugation).
    from polar_sim.ground.synthetic import make_sequence

    pitch = np.radians(10.0)
    seq = make_sequence(12, width=320, height=240, speed=SPEED, yaw_rate=YAW_RATE, dt=DT, camera_height=HEIGHT,
                        pitch=pitch, seed=4)
    vo = GroundVO(seq["K"], HEIGHT, camera_pitch=pitch, downsample=1, seed=0)
    es = run(vo, seq)
    raw = np.array([e.speed_raw for e in es[2:]])
    assert np.median(raw) == pytest.approx(SPEED, rel=0.02)
    assert np.median([e.yaw_rate_raw for e in es[2:]]) == pytest.approx(YAW_RATE, rel=0.03)
    T, G = vo.trajectory()[-1], seq["poses"][-1]
    # Heading: the rotation angle between estimated and true final camera orientation is small.
    ang = np.arccos(np.clip((np.trace(T[:3, :3].T @ G[:3, :3]) - 1) / 2, -1, 1))
    assert ang < 0.02
    with pytest.raises(ValueError, match="camera_pitch"):
        GroundVO(seq["K"], HEIGHT, camera_pitch=2.0)


def test_offline_refit_reproduces_the_online_ransac(corridor):
    # The exposed RANSAC data (level-frame u, v, d̄, P_G at the candidates) re-run offline with the same
    # generator state give the online result exactly: the experiments re-fit the same candidate sets.
    from polar_sim.ground import fit_ground

    vo = _vo(corridor)
    es = run(vo, corridor, range(5))
    state = vo.rng_.bit_generator.state
    e = vo.process(corridor["rgb"][5], corridor["times"][5])
    assert e.status == "ok" and np.all(e.candidate_prob > 0)
    rng = np.random.default_rng()
    rng.bit_generator.state = state
    u, v = e.candidate_uv.T
    fit = fit_ground(u, v, e.candidate_dbar, HEIGHT, model="6param", weights=e.candidate_prob, rng=rng)
    assert fit.speed == e.speed_raw and np.array_equal(fit.inliers, e.inlier_mask)
    assert np.isnan(es[2].candidate_prob).all()  # before the first classifier update
