"""ObjectTracker end to end on synthetic RGB-D: accuracy under touch, lost/recover, bad input, determinism."""

import numpy as np
import pytest

from polar_sim import metrics
from polar_sim.tracking import ObjectTracker
from polar_sim.tracking.synthetic import make_sequence

N_FRAMES = 30


@pytest.fixture(scope="module")
def mug():
    seq = make_sequence(N_FRAMES, "mug")
    P, N = seq.model(3000)
    frames = [seq.frame(i) for i in range(N_FRAMES)]
    return seq, P, N, frames


def _track(seq, P, N, frames, **kw):
    # kw: set_params names (a stage config's fields as stage__field)
    kw.setdefault("model_normals", N)
    tr = ObjectTracker(P, seq.K, seq.poses[0]).set_params(**kw)
    return tr, [tr.process(f["rgb"], f["depth"]) for f in frames]


@pytest.mark.parametrize("appearance", ["ww", "h"])
def test_tracks_mug_held_by_hand(mug, appearance):
    # a moving, hand-held mug: every frame within ADD < 0.1 d, IoU > 0.5, few hand pixels as target
    seq, P, N, frames = mug
    _, res = _track(seq, P, N, frames, appearance=appearance)
    d = metrics.object_diameter(P)
    add = metrics.add(P, np.stack([f["pose"] for f in frames]), np.stack([r.pose for r in res]))
    assert metrics.add_success(add, d, 0.1) == 1.0
    assert np.max(add) < 0.01
    ious = metrics.iou(np.stack([r.mask for r in res]), np.stack([f["mask"] for f in frames]))
    assert metrics.iou_success(ious, 0.5) == 1.0
    hand = metrics.occluder_as_target(np.stack([r.mask for r in res]), np.stack([f["hand"] for f in frames]))
    assert hand <= 0.05
    assert all(r.accepted and not r.lost for r in res[1:])


def test_result_fields(mug):
    # the result carries the contract's fields with the right shapes and types
    seq, P, N, frames = mug
    tr = ObjectTracker(P, seq.K, seq.poses[0], model_normals=N, debug_maps=True)
    r = tr.process(frames[0]["rgb"], frames[0]["depth"])
    H, W = seq.shape
    assert r.pose.shape == (4, 4) and r.covariance.shape == (6, 6)
    assert r.mask.shape == (H, W) and r.mask.dtype == bool
    assert r.prob.shape == (H, W) and 0 <= r.prob.min() and r.prob.max() <= 1
    assert r.labels.dtype == np.int8 and set(np.unique(r.labels)) <= {-1, 0, 1}
    assert r.attention.shape == (H, W) and r.silhouette.shape == (H, W)
    assert isinstance(r.lost, bool) and isinstance(r.accepted, bool) and r.time_s > 0
    assert r.n_points > 0 and 0 <= r.fitness <= 1 and np.isfinite(r.inlier_rmse)
    assert tr.n_frames_ == 1 and np.array_equal(tr.pose_, r.pose)


def test_hand_pixels_are_labelled_background(mug):
    # labels O: the touching hand's pixels come out 0 (or undecided), almost never 1
    seq, P, N, frames = mug
    _, res = _track(seq, P, N, frames[:10])
    hand = np.stack([f["hand"] for f in frames[:10]])
    O = np.stack([r.labels for r in res])
    assert (O[hand] == 1).mean() < 0.02
    assert (O[hand] == 0).mean() > 0.8


@pytest.fixture(scope="module")
def moving_mug():
    """The hand-held mug at twice the speed: by frame 30 it has slid about 7 cm and turned."""
    seq = make_sequence(N_FRAMES, "mug", speed=2.0)
    P, N = seq.model(3000)
    return seq, P, N, [seq.frame(i) for i in range(N_FRAMES)]


@pytest.mark.parametrize("kw", [dict(appearance="none"), dict(motion__filter="none"),
                                dict(motion__filter="alpha-beta"), dict(attention__spatial_prior=True),
                                dict(registration__correspondence="kdtree"), dict(registration__hold_unobserved=False),
                                dict(calibrate=False), dict(appearance="Su"), dict(appearance="wu"),
                                dict(appearance="SW"), dict(appearance="h")])
def test_variants_and_ablations_track_a_moving_object(moving_mug, kw):
    # each switch keeps ADD < 0.1 d on every frame of an object that moves well beyond that bound: a
    # tracker that held the initial pose would fail by frame 30 (checked on the truth itself)
    seq, P, N, frames = moving_mug
    d = metrics.object_diameter(P)
    G = np.stack([f["pose"] for f in frames])
    assert metrics.add(P, G[0], G[-1]) > 3 * 0.1 * d  # holding the first pose fails the bound
    _, res = _track(seq, P, N, frames, **kw)
    add = metrics.add(P, G, np.stack([r.pose for r in res]))
    assert np.all(add < 0.1 * d), (kw, add.max() / d)


def test_static_revolved_object_does_not_spin():
    # a cylinder at rest: its rotation about the axis is seen by nothing, so the estimate must not turn
    # (issue 13 item 5); without holding the unobserved direction the same tracker spins by tens of degrees
    seq = make_sequence(60, "cylinder", speed=0.0, hand=False)
    P, N = seq.model(3000)
    frames = [seq.frame(i) for i in range(60)]
    drift = {}
    for hold in (True, False):
        _, res = _track(seq, P, N, frames, registration__hold_unobserved=hold)
        drift[hold] = np.rad2deg(metrics.rotation_drift(seq.poses, np.stack([r.pose for r in res]))).max()
        if hold:
            assert all(r.n_unobserved == 1 for r in res)
    assert drift[True] < 1.0 and drift[False] > 5.0


def test_symmetry_directions_from_the_model_alone():
    # a revolved model maps onto itself turned about its axis (found to within a degree), a box about none
    from polar_sim.tracking.icp import symmetry_directions
    from polar_sim.tracking.model import ShapeModel

    for obj, k in (("cylinder", 1), ("box", 0), ("mug", 0)):
        P, N = make_sequence(2, obj, speed=0.0, hand=False).model(3000)
        U = symmetry_directions(ShapeModel(P, N))
        assert U.shape == (6, k), obj
        if k:
            _, axes = np.linalg.eigh(np.cov(P.T))
            # the synthetic cylinder stands on z in its own frame; the held direction is a pure rotation
            assert abs(U[2, 0]) > np.cos(np.deg2rad(1.0)) and np.allclose(U[3:, 0], 0.0), U[:, 0]


def test_static_revolved_object_touched_by_a_moving_hand_does_not_spin():
    # issue 13 item 5 under touch: a cylinder at rest while the hand's fingers slide 40 deg round it, in
    # contact. The hand's points pull a geometric registration along the free axis (without holding it
    # the estimate turns with the fingers: about 40 deg before issue 35, 16 deg with the rest-gated dead
    # zone; either is over 10x the bound); held, it stays within 1 degree of the truth
    from polar_sim.geometry import make_pose, so3_exp

    n = 40
    seq = make_sequence(n, "cylinder", speed=0.0, hand=True, noise=False)
    for i in range(n):
        turn = make_pose(so3_exp([0.0, 0.0, np.deg2rad(40.0) * i / (n - 1)]), None)
        seq.hand_poses[i] = seq.poses[i] @ turn @ np.linalg.inv(seq.poses[i]) @ seq.hand_poses[i]
    P, N = seq.model(3000)
    frames = [seq.frame(i) for i in range(n)]
    assert frames[-1]["hand"].sum() > 500 and not np.array_equal(frames[0]["hand"], frames[-1]["hand"])
    drift = {}
    for hold in (True, False):
        _, res = _track(seq, P, N, frames, registration__hold_unobserved=hold)
        drift[hold] = np.rad2deg(metrics.rotation_drift(seq.poses, np.stack([r.pose for r in res]))).max()
        assert not any(r.lost for r in res)
        assert all(r.n_unobserved >= 1 for r in res[1:]) == hold
    assert drift[True] < 1.0 and drift[False] > 10.0, drift


def test_static_box_has_no_unobserved_direction():
    # a box at rest, two faces and their edges in view: every direction is observed, nothing is held
    seq = make_sequence(20, "box", speed=0.0, hand=False)
    P, N = seq.model(3000)
    _, res = _track(seq, P, N, [seq.frame(i) for i in range(20)])
    assert all(r.n_unobserved == 0 for r in res)
    assert np.rad2deg(metrics.rotation_drift(seq.poses[:20], np.stack([r.pose for r in res]))).max() < 1.0


def test_prob_is_calibrated_by_the_tracker_own_labels(mug):
    # P(target) in the ROI, pooled over frames 10-29, is closer to calibrated (ECE against the true visible
    # mask) than the raw prediction map, and the raw map is kept beside it
    seq, P, N, frames = mug
    _, res = _track(seq, P, N, frames)
    roi = np.zeros((len(res),) + seq.shape, bool)
    for k, r in enumerate(res):
        x0, y0, x1, y1 = r.roi
        roi[k, y0:y1, x0:x1] = True
    truth = np.stack([f["mask"] for f in frames])
    cal = np.stack([r.prob for r in res])
    raw = np.stack([r.prob_raw for r in res])
    e_cal = metrics.expected_calibration_error(cal[10:], truth[10:], valid=roi[10:])
    e_raw = metrics.expected_calibration_error(raw[10:], truth[10:], valid=roi[10:])
    assert e_cal < e_raw and e_cal < 0.05, (e_cal, e_raw)


def test_plain_icp_baseline_runs(mug):
    # the plain-ICP baseline (all ROI points, no label weighting) runs and returns valid poses;
    # under touch and on a table it is expected to drift - that is what the variants are scored against
    seq, P, N, frames = mug
    _, res = _track(seq, P, N, frames[:8], registration__method="plain")
    assert all(np.isfinite(r.pose).all() and r.mask.shape == seq.shape for r in res)


def test_lost_when_out_of_view_then_recovers():
    # the object leaves the view: no exception, frames marked lost, coasting, then recovery
    hidden = set(range(8, 13))
    seq = make_sequence(22, "mug", hidden=hidden)
    P, N = seq.model(3000)
    tr = ObjectTracker(P, seq.K, seq.poses[0], model_normals=N)
    res = [tr.process(f["rgb"], f["depth"]) for f in map(seq.frame, range(22))]
    assert all(res[i].lost and not res[i].accepted for i in hidden)
    assert not any(res[i].mask.any() for i in hidden)
    add = metrics.add(P, seq.poses[16:], np.stack([r.pose for r in res[16:]]))
    assert np.all(add < 0.1 * metrics.object_diameter(P))
    assert not res[-1].lost and res[-1].accepted


def test_lost_when_fully_occluded_then_recovers():
    # a board hides the object for a few frames: lost without exception, then tracked again
    occ = set(range(8, 12))
    seq = make_sequence(20, "box", occluded=occ)
    P, N = seq.model(3000)
    tr = ObjectTracker(P, seq.K, seq.poses[0], model_normals=N, appearance="h")
    res = [tr.process(f["rgb"], f["depth"]) for f in map(seq.frame, range(20))]
    assert all(res[i].lost for i in occ)
    add = metrics.add(P, seq.poses[15:], np.stack([r.pose for r in res[15:]]))
    assert np.all(add < 0.1 * metrics.object_diameter(P))


def _behind_board(n, obj, *, board_dx, **kw):
    """A synthetic sequence of ``obj`` (``make_sequence(n, obj, **kw)``) and the same sequence with a
    30 cm board in front of it, at 0.6 of its distance from the camera and ``board_dx`` m to the side."""
    import trimesh

    from polar_sim.geometry import make_pose
    from polar_sim.tracking.synthetic import OCCLUDER, Part

    seq = make_sequence(n, obj, **kw)
    occ = make_sequence(n, obj, **kw)
    board = Part.from_trimesh(trimesh.creation.box([0.3, 0.3, 0.01]), (128, 128, 128), OCCLUDER)
    occ.extras = [(board, make_pose(None, 0.6 * seq.poses[0][:3, 3] + [board_dx, 0.0, 0.0]))]
    return seq, occ


def _spy_deadzones(monkeypatch):
    """The tangential dead zone of every ICP call the tracker makes, appended to the returned list."""
    from polar_sim.tracking import tracker as tracker_mod

    used = []
    icp = tracker_mod.weighted_icp

    def spy(*a, **kw):
        used.append(kw["tangential_deadzone"])
        return icp(*a, **kw)

    monkeypatch.setattr(tracker_mod, "weighted_icp", spy)
    return used


def test_mostly_hidden_object_is_tracked_not_lost():
    # a board in front hides all but about 12 % of a static mug from frame 10 on. Its visible part
    # still fits, so with guard.coverage="visible" (the default) the tracker keeps it: never lost, the
    # mask covers the visible part (IoU > 0.5 against the true visible mask) and the pose holds.
    # Counting the hidden pixels as expected (guard.coverage="silhouette", the rule before) declares it lost
    n = 25
    seq, occ = _behind_board(n, "mug", speed=0.0, hand=False, shape=(240, 320), board_dx=-0.12)
    frames = [seq.frame(i) if i < 10 else occ.frame(i) for i in range(n)]
    seen = [f["mask"].sum() / frames[0]["mask"].sum() for f in frames[10:]]
    assert 0.05 < min(seen) and max(seen) < 0.2, seen
    P, N = seq.model(3000)
    lost = {}
    for cov in ("visible", "silhouette"):
        _, res = _track(seq, P, N, frames, guard__coverage=cov)
        lost[cov] = sum(r.lost for r in res[10:])
        if cov == "visible":
            assert all(metrics.iou(r.mask, f["mask"]) > 0.5 for r, f in zip(res, frames))
            add = metrics.add(P, seq.poses, np.stack([r.pose for r in res]))
            assert np.all(add < 0.1 * metrics.object_diameter(P))
    assert lost == {"visible": 0, "silhouette": n - 10}, lost


def test_still_object_almost_all_hidden_is_held_still():
    # issue 35 item 3: a mug at rest, held by the hand, with a board in front that hides all but about
    # 3 % of it from frame 10 on. Its pose must not move: the largest rotation drift against the exact
    # truth stays under 2 deg, the track is never lost and ADD stays < 0.1 d. Without the tangential
    # term's dead zone the sampling gaps of the model pull the few visible points' weak directions and
    # the estimate turns by about 5 deg (so the test can fail)
    n = 25
    seq, occ = _behind_board(n, "mug", speed=0.0, hand=True, board_dx=-0.10)
    frames = [seq.frame(i) if i < 10 else occ.frame(i) for i in range(n)]
    seen = [f["mask"].sum() / frames[0]["mask"].sum() for f in frames[10:]]
    assert 0.01 < min(seen) and max(seen) < 0.05, seen
    P, N = seq.model(3000)
    drift = {}
    for dz in (None, 0.0):
        kw = {} if dz is None else {"registration__tangential_deadzone": dz}
        _, res = _track(seq, P, N, frames, **kw)
        E = np.stack([r.pose for r in res])
        drift[dz] = np.rad2deg(metrics.rotation_drift(seq.poses, E)).max()
        if dz is None:
            assert not any(r.lost for r in res)
            assert np.all(metrics.add(P, seq.poses, E) < 0.1 * metrics.object_diameter(P))
    assert drift[None] <= 2.0 < drift[0.0], drift


def test_dead_zone_scales_with_the_hidden_fraction(monkeypatch):
    # the ICP's dead zone is the configured one times the fraction of the predicted silhouette seen
    # behind something: ~0 for a mug with nothing in front (edge pixels only), ~1 behind a board that
    # leaves 3 % of it visible (the exact visible mask of the synthetic frames says how much)
    used = _spy_deadzones(monkeypatch)
    seq, occ = _behind_board(6, "mug", speed=0.0, hand=False, board_dx=-0.10)
    frames = [seq.frame(i) for i in range(3)] + [occ.frame(i) for i in range(3, 6)]
    hidden = 1.0 - np.array([f["mask"].sum() for f in frames]) / frames[0]["mask"].sum()
    assert hidden[:3].max() < 1e-9 and hidden[3:].min() > 0.9, hidden
    P, N = seq.model(3000)
    # the rest gate is opened wide: this test is about the hidden fraction alone (the board's sudden
    # arrival gives the filter a small velocity, which the default gate reads as motion)
    _track(seq, P, N, frames, registration__tangential_deadzone=2.0, registration__deadzone_rest_speed=10.0)
    assert len(used) >= 6
    assert max(used[:3]) < 0.02 and min(used[-3:]) > 0.9 * 2.0, used


def test_hidden_pushed_object_keeps_its_tangential_pull(monkeypatch):
    # issue 35 item 3, second pass: a mug pushed at up to 5 mm per frame (more than one model spacing)
    # while a board hides 50-85 % of it and the hand is in front of it. The hidden fraction alone would
    # turn the tangential dead zone on (over half of it behind the board), and the pose would lag the slide
    # by up to the dead zone. Gated on the filter's velocity, the dead zone is off on every frame behind
    # the board (the truth moves there by > 2 x deadzone_rest_speed spacings per frame), and the track is
    # as good as without a dead zone: rotation error within 0.5 deg of it on every frame of the
    # sequence, ADD < 0.1 d, never lost. The ungated dead zone misses that bound (by about 1.4 deg)
    from polar_sim.geometry import inv_pose, se3_log
    used = _spy_deadzones(monkeypatch)
    n, start = 40, 10
    seq, occ = _behind_board(n, "mug", speed=3.0, hand=True, board_dx=-0.10)
    frames = [seq.frame(i) if i < start else occ.frame(i) for i in range(n)]
    seen = np.array([f["mask"].sum() for f in frames[start:]]) / frames[0]["mask"].sum()
    assert 0.1 < seen.min() and seen.max() < 0.55, seen
    P, N = seq.model(3000)
    d = metrics.object_diameter(P)
    err, dz_used = {}, {}
    for name, kw in {"gated": {}, "none": {"registration__tangential_deadzone": 0.0},
                     "ungated": {"registration__deadzone_rest_speed": 10.0}}.items():
        used.clear()
        tr = ObjectTracker(P, seq.K, seq.poses[0], model_normals=N).set_params(**kw)
        res, per_frame = [], []
        for f in frames:
            k = len(used)
            res.append(tr.process(f["rgb"], f["depth"]))
            per_frame.append(max(used[k:], default=0.0))
        E = np.stack([r.pose for r in res])
        err[name] = np.rad2deg(metrics.rotation_drift(seq.poses, E))
        dz_used[name] = np.array(per_frame)
        if name == "gated":
            assert not any(r.lost for r in res)
            assert np.all(metrics.add(P, seq.poses, E) < 0.1 * d)
            limit = tr.registration.deadzone_rest_speed * tr.model_.spacing
    # the truth's surface motion per frame, as the gate measures it (translation + rotation at d / 2)
    xi = np.array([se3_log(inv_pose(seq.poses[i - 1]) @ seq.poses[i]) for i in range(1, n)])
    step = np.linalg.norm(xi[:, 3:], axis=1) + 0.5 * d * np.linalg.norm(xi[:, :3], axis=1)
    assert step[start - 1:].min() > 2.0 * limit, (step, limit)  # it moves fast behind the board
    assert dz_used["ungated"][start:].min() > 0.5 * 1.5, dz_used["ungated"]  # half the default dead zone
    assert np.all(dz_used["gated"][start:] == 0.0), dz_used["gated"]
    assert np.all(err["gated"] <= err["none"] + 0.5), (err["gated"].max(), err["none"].max())
    assert not np.all(err["ungated"] <= err["none"] + 0.5), (err["ungated"].max(), err["none"].max())


def test_first_frame_predicts_no_motion():
    # the first frame is at the time of initial_pose: no interval is predicted over before it, so its
    # registration moves the pose but gives the filter no velocity (with 1/fps predicted, the pose and
    # velocity errors are correlated and the first registration error becomes a rate that rings)
    seq = make_sequence(3, "mug", speed=0.0, hand=False)
    f = seq.frame(0)
    P, N = seq.model(2000)
    for motion in ("ekf", "alpha-beta"):
        tr = ObjectTracker(P, seq.K, seq.poses[0], model_normals=N).set_params(motion__filter=motion)
        r = tr.process(f["rgb"], f["depth"], t=5.0)
        assert not np.array_equal(r.pose, seq.poses[0])  # the registration did move the pose
        assert np.array_equal(tr.filter_.xi, np.zeros(6)), (motion, tr.filter_.xi)


def test_deterministic(mug):
    # same inputs, same outputs, bit for bit; reset() replays like a fresh tracker
    seq, P, N, frames = mug
    a, ra = _track(seq, P, N, frames[:6])
    b, rb = _track(seq, P, N, frames[:6])
    a.reset()
    rc = [a.process(f["rgb"], f["depth"]) for f in frames[:6]]
    for x, y, z in zip(ra, rb, rc):
        for k in ("pose", "mask", "prob", "labels", "covariance"):
            assert np.array_equal(getattr(x, k), getattr(y, k))
            assert np.array_equal(getattr(x, k), getattr(z, k))


def _bad_inputs(seq, P):
    return [
        dict(model_points=np.zeros((0, 3))),
        dict(model_points=np.where(np.arange(len(P))[:, None] == 3, np.nan, P)),
        dict(model_points=P[:, :2]),
        dict(K=np.eye(4)),
        dict(K=np.ones((2, 3))),
        dict(initial_pose=np.eye(4) * 2),
        dict(initial_pose=np.eye(3)),
        dict(model_normals=np.zeros_like(P)),
        dict(appearance="xx"),
        dict(motion="kalman"),
        dict(registration={"method": "plain"}),
        dict(fps=0.0),
        dict(calibrate="yes"),
        dict(random_state=-1),
    ]


@pytest.mark.parametrize("i", range(14))
def test_bad_construction_raises(mug, i):
    # bad model points, normals, K, initial pose or parameters raise ValueError (TypeError for a wrong
    # kind of value, such as a stage given as a string or a dict) at construction
    seq, P, N, _ = mug
    args = dict(model_points=P, K=seq.K, initial_pose=seq.poses[0])
    args.update(_bad_inputs(seq, P)[i])
    mp, K, T0 = args.pop("model_points"), args.pop("K"), args.pop("initial_pose")
    with pytest.raises((ValueError, TypeError), match=next(iter(_bad_inputs(seq, P)[i]))):
        ObjectTracker(mp, K, T0, **args)


def test_bad_frames_raise_and_leave_tracker_unchanged(mug):
    # mismatched shapes, all-invalid depth, negative depth, wrong dtype raise; state is untouched
    seq, P, N, frames = mug
    rgb, depth = frames[0]["rgb"], frames[0]["depth"]
    tr = ObjectTracker(P, seq.K, seq.poses[0], model_normals=N)
    ref = ObjectTracker(P, seq.K, seq.poses[0], model_normals=N)
    bad = [
        (rgb, depth[:-1]),
        (rgb[:, :-1], depth),
        (rgb, np.full_like(depth, np.nan)),
        (rgb, np.zeros_like(depth)),
        (rgb, -np.ones_like(depth)),
        (rgb.astype(np.float32), depth),
        (rgb[..., :2], depth),
    ]
    for r, d in bad:
        with pytest.raises(ValueError):
            tr.process(r, d)
    assert not hasattr(tr, "pose_")
    a = tr.process(rgb, depth)
    b = ref.process(rgb, depth)
    assert np.array_equal(a.pose, b.pose) and np.array_equal(a.prob, b.prob)
    with pytest.raises(ValueError):
        tr.process(rgb[:100], depth[:100])  # the image size is fixed by the first frame
    with pytest.raises(ValueError):
        tr.process(rgb, depth, t=float("nan"))


def test_prediction_outside_the_image_coasts(mug):
    # a pose that projects nowhere in the image: lost, empty outputs, no exception
    seq, P, N, frames = mug
    T0 = seq.poses[0].copy()
    T0[0, 3] += 3.0
    tr = ObjectTracker(P, seq.K, T0, model_normals=N)
    r = tr.process(frames[0]["rgb"], frames[0]["depth"])
    assert r.lost and not r.accepted and not r.mask.any() and not r.prob.any()
    assert np.allclose(r.pose, T0)


def test_copy_continues_identically(mug):
    # a deep copy of a tracker resumes exactly where the original is
    import copy

    seq, P, N, frames = mug
    a, _ = _track(seq, P, N, frames[:4])
    b = copy.deepcopy(a)
    ra = [a.process(f["rgb"], f["depth"]) for f in frames[4:7]]
    rb = [b.process(f["rgb"], f["depth"]) for f in frames[4:7]]
    for x, y in zip(ra, rb):
        assert np.array_equal(x.pose, y.pose) and np.array_equal(x.labels, y.labels)


def test_accepts_strided_views(mug):
    # channel-reversed (BGR->RGB) views and float64 depth are accepted and give the same result
    seq, P, N, frames = mug
    f = frames[0]
    bgr = np.ascontiguousarray(f["rgb"][..., ::-1])
    a = ObjectTracker(P, seq.K, seq.poses[0], model_normals=N).process(bgr[..., ::-1], f["depth"].astype(float))
    b = ObjectTracker(P, seq.K, seq.poses[0], model_normals=N).process(f["rgb"], f["depth"])
    assert np.array_equal(a.pose, b.pose) and np.array_equal(a.mask, b.mask)


def test_sparse_faces_of_a_non_uniform_model_are_segmented():
    # a box model with 2700 points on its two small faces and 300 on the four large ones (9x sparser): the
    # mask still recalls >= 78 % of the true visible pixels at >= 95 % precision (issue 13 item 4: with one
    # global point spacing the sparse faces fell out of the silhouette and the labels, recall 0.65)
    import trimesh

    seq = make_sequence(20, "box", hand=False)
    frames = [seq.frame(i) for i in range(20)]
    mesh = seq.target.mesh
    small = np.abs(mesh.face_normals[:, 0]) > 0.9

    def sample(faces, n, seed):
        sub = mesh.submesh([np.flatnonzero(faces)], append=True)
        p, f = trimesh.sample.sample_surface(sub, n, seed=seed)
        return np.asarray(p), sub.face_normals[f]

    (P1, N1), (P2, N2) = sample(small, 2700, 0), sample(~small, 300, 1)
    _, res = _track(seq, np.vstack([P1, P2]), None, frames, model_normals=np.vstack([N1, N2]))
    prec, rec = metrics.precision_recall(np.stack([r.mask for r in res]), np.stack([f["mask"] for f in frames]))
    assert rec >= 0.78 and prec >= 0.95, (prec, rec)


def test_sudden_turn_measured_cleanly_is_fused_not_coasted():
    # issue 35 item 3, the lost push: a box slides at 1 mm per frame, so the motion prior grows confident
    # of a slow slide, then turns 12 deg per frame for three frames (5 mm per frame) and stops. The
    # registration of the turn is clean (fitness 1), but it lies past the Mahalanobis gate. A confident fit
    # (guard.confident_fitness) passes the widened gate: never lost, within 2 mm (ADD) of the truth on
    # every frame. The single gate coasts through the turn and the track lands more than 0.1 d off
    from polar_sim.geometry import inv_pose, make_pose, so3_exp

    n_slide, n_turn, n_rest = 20, 3, 5
    seq = make_sequence(n_slide + n_turn + n_rest, "box", hand=False, speed=0.0)
    T0 = make_pose(so3_exp([0.0, 0.0, np.deg2rad(35)]), None) @ seq.T_world_cam @ seq.poses[0]  # two faces seen
    c0 = T0[:3, 3].copy()
    x = np.concatenate([np.arange(n_slide), n_slide - 1 + 5 * np.arange(1, n_turn + 1),
                        np.full(n_rest, n_slide - 1 + 5 * n_turn)]) * 0.001
    yaw = np.deg2rad(12.0) * np.concatenate([np.zeros(n_slide), np.arange(1, n_turn + 1), np.full(n_rest, n_turn)])
    T_cw = inv_pose(seq.T_world_cam)
    seq.poses = np.array([T_cw @ make_pose(so3_exp([0.0, 0.0, a]), c0 + [xi, 0.0, 0.0]) @ make_pose(None, -c0) @ T0
                          for xi, a in zip(x, yaw)])
    frames = [seq.frame(i) for i in range(len(seq))]
    P, N = seq.model(3000)
    d = metrics.object_diameter(P)
    add, lost = {}, {}
    for name, kw in {"confident": {}, "single gate": {"guard__confident_fitness": None}}.items():
        _, res = _track(seq, P, N, frames, **kw)
        add[name] = metrics.add(P, seq.poses, np.stack([r.pose for r in res]))
        lost[name] = [i for i, r in enumerate(res) if r.lost]
    assert lost["confident"] == [] and add["confident"].max() < 0.002, (lost, add["confident"].max())
    assert n_slide in lost["single gate"] and add["single gate"].max() > 0.1 * d, (lost, add["single gate"].max())
