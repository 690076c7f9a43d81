"""Dense ground alignment (polar_sim.ground.dense) against exact synthetic truth: the warp model, the
recovered motion on textured, faint and periodic grounds, the aliasing flag, the ground self-labels,
the fusion rule, and GroundVO with the dense stage on a ground with almost no corners."""

import functools

import cv2
import numpy as np
import pytest

from polar_sim.ground import DenseConfig, GroundVO
from polar_sim.ground import dense
from polar_sim.ground.camera import LevelCamera
from polar_sim.ground.synthetic import GROUND_KINDS, make_sequence
from polar_sim.metrics.ground import labels_at

W, H, V, YAW, DT = 640, 480, 5.0, 0.1, 0.1
S_TRUE, A_TRUE = V * DT, YAW * DT  # arc length (m) and yaw change (rad) between consecutive frames


@pytest.fixture(scope="module")
def pairs():
    """Two consecutive frames of each synthetic ground (camera 1 m up, 5 m/s, 0.1 rad/s, 10 Hz)."""
    out = {}
    for kind in GROUND_KINDS:
        seq = make_sequence(2, width=W, height=H, speed=V, yaw_rate=YAW, dt=DT, ground=kind, seed=1)
        out[kind] = seq
    return out


def _region(cam, max_depth=15.0):
    yy, xx = np.mgrid[0:H, 0:W]
    v = (yy - cam.cy) / cam.fy
    return (v > 0) & (v * max_depth >= 1.0) & (yy >= 4) & (yy < H - 4) & (xx >= 4) & (xx < W - 4)


def _grey(seq, i):
    return cv2.cvtColor(seq["rgb"][i], cv2.COLOR_RGB2GRAY)


def _pyr(seq, i, levels=2):
    return dense.Pyramid(_grey(seq, i), levels, 1.0)


def _ground(seq, cam, max_depth=15.0):
    """The alignment region of frame 0 on its true ground (the fit alone, without the segmentation)."""
    return _region(cam, max_depth) & (cv2.erode(seq["ground_mask"][0].astype(np.uint8), np.ones((5, 5), np.uint8)) > 0)


# The homography model maps ground points of frame 0 onto their exact projection in frame 1 (truth:
# the rendered depth and the true poses), to round-off.
def test_the_warp_is_the_exact_ground_motion(pairs):
    seq = pairs["noise"]
    K, cam = seq["K"], LevelCamera(seq["K"], 1, 0.0, None)
    ys, xs = np.nonzero(seq["ground_mask"][0])
    xs, ys = xs[::50].astype(float), ys[::50].astype(float)
    Z = seq["depth"][0][ys.astype(int), xs.astype(int)].astype(float)
    X0 = np.stack([(xs - K[0, 2]) / K[0, 0] * Z, (ys - K[1, 2]) / K[1, 1] * Z, Z], axis=1)
    T = np.linalg.inv(seq["poses"][1]) @ seq["poses"][0]
    X1 = X0 @ T[:3, :3].T + T[:3, 3]
    x1 = np.stack([K[0, 0] * X1[:, 0] / X1[:, 2] + K[0, 2], K[1, 1] * X1[:, 1] / X1[:, 2] + K[1, 2]], axis=1)
    got = dense._Warp(cam, 1.0).points(np.c_[xs, ys, np.ones(len(xs))], (S_TRUE, A_TRUE))
    assert np.abs(got - x1).max() < 1e-3  # px; the depth image is float32


# From a prediction 30 % off, the fit recovers the true arc length within 0.5 % and the yaw change within
# 3 % on the textured, the faint (one colour, +-2.5 grey levels of grain, image noise 1) and the tiled
# ground, in the side-slope model (the default) and the pitch model (the pitch change and the side slope
# are unknowns, 0 here). On the painted stripes (one thin line every 2.56 m, a few in the near ground)
# the cost has side minima beyond 10 %: from 5 and 10 % off, within 1.5 % (the renderer's mip blur
# changes a thin line's profile with distance). On the faint ground the side slope, barely seen, costs
# the yaw change a little: within 3.5 % there (2.3 of the fit's standard deviations; the pitch model's
# 2.4 % is 2.0).
@pytest.mark.parametrize("model", ["side_slope", "pitch"])
@pytest.mark.parametrize("kind", ["noise", "faint", "checker", "stripes"])
def test_align_recovers_the_known_motion(pairs, kind, model):
    seq = pairs[kind]
    cam = LevelCamera(seq["K"], 1, 0.0, None)
    offs, tol = ((-0.1, -0.05, 0.05, 0.1), 0.015) if kind == "stripes" else ((-0.3, 0.3), 0.005)
    for d in offs:
        fit = dense.align_ground(_pyr(seq, 0), _pyr(seq, 1), cam, 1.0, S_TRUE * (1 + d), A_TRUE * (1 - d),
                                 mask=_ground(seq, cam), model=model)
        assert fit.ok and fit.n_pixels >= 500
        assert abs(fit.s - S_TRUE) < tol * S_TRUE, (d, fit.s)
        assert abs(fit.a - A_TRUE) < (0.035 if (kind, model) == ("faint", "side_slope") else 0.03) * A_TRUE, (d, fit.a)
        assert np.abs(fit.params[2:]).max() < 2e-3  # no pitch change, no side slope on the synthetic path
        # the reported uncertainty is a real (positive definite) covariance
        assert np.all(np.linalg.eigvalsh(fit.cov) > 0)


# A chassis leaning in a turn (the camera rolled 1 degree about its optical axis, as the rover's is by
# 0.5-1.2 degrees in the simulated routes' turns) tilts the ground across the image. The pitch model has
# a level ground and takes the tilt for yaw: its yaw change is off by more than 5 % (many of its own
# standard deviations). The side-slope and surface models fit the tilt: the yaw change within 1 %, the
# arc length within 0.5 %, and the side slope within 10 % of the exact -tan(roll).
def test_side_slope_models_take_the_lean_of_the_chassis():
    roll = np.radians(1.0)
    seq = make_sequence(2, width=W, height=H, speed=V, yaw_rate=YAW, dt=DT, ground="noise", seed=1, roll=roll)
    cam = LevelCamera(seq["K"], 1, 0.0, None)
    fits = {m: dense.align_ground(_pyr(seq, 0), _pyr(seq, 1), cam, 1.0, S_TRUE * 1.1, A_TRUE * 0.9,
                                  mask=_ground(seq, cam), model=m) for m in ("pitch", "side_slope", "surface")}
    assert all(f.ok and f.model == m for m, f in fits.items())
    assert abs(fits["pitch"].a - A_TRUE) > 0.05 * A_TRUE
    assert abs(fits["pitch"].a - A_TRUE) > 5 * np.sqrt(fits["pitch"].cov[1, 1])
    for m in ("side_slope", "surface"):
        assert abs(fits[m].a - A_TRUE) < 0.01 * A_TRUE, m
        assert abs(fits[m].s - S_TRUE) < 0.005 * S_TRUE, m
        assert fits[m].params[-1] == pytest.approx(-np.tan(roll), rel=0.1), m
    assert len(fits["side_slope"].params) == 4  # (s, a, pitch change, side slope)


# Tiles repeat every 1.28 m along the path: searched over +-1.5 m, the shift back by one period fits about
# as well as the solution (320x240, where the tiles' far rows blur into each other), and the fit says so;
# the non-repeating grounds are not flagged over the same range.
def test_the_aliasing_flag():
    flags = {}
    for kind in ("noise", "faint", "checker"):
        seq = make_sequence(2, width=320, height=240, speed=V, yaw_rate=YAW, dt=DT, ground=kind, seed=1)
        cam = LevelCamera(seq["K"], 1, 0.0, None)
        yy, xx = np.mgrid[0:240, 0:320]
        v = (yy - cam.cy) / cam.fy
        region = (v > 0) & (v * 15.0 >= 1.0) & (yy >= 4) & (yy < 236) & (xx >= 4) & (xx < 316)
        region &= cv2.erode(seq["ground_mask"][0].astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        p0, p1 = (dense.Pyramid(_grey(seq, i), 2, 1.0) for i in (0, 1))
        fit = dense.align_ground(p0, p1, cam, 1.0, S_TRUE, A_TRUE, mask=region, alias_range=1.5)
        flags[kind] = fit.aliased
        assert abs(fit.s - S_TRUE) < 0.02 * S_TRUE  # the solution itself is the right one
    assert flags == {"noise": False, "faint": False, "checker": True}


# Images without texture in the region give no fit, not a wrong one.
def test_no_texture_no_fit():
    img = dense.Pyramid(np.full((H, W), 120, np.uint8), 2, 1.0)
    cam = LevelCamera(make_sequence(1, width=W, height=H)["K"], 1, 0.0, None)
    fit = dense.align_ground(img, img, cam, 1.0, 0.4, 0.0, mask=_region(cam))
    assert not fit.ok and fit.s == 0.4 and not np.isfinite(fit.cov).any()


# The self-labels of a converged fit lie on the true ground (exact mask of the first frame), on the
# textured and on the faint ground.
@pytest.mark.parametrize("kind", ["noise", "faint"])
def test_ground_evidence_labels_lie_on_ground(pairs, kind):
    seq = pairs[kind]
    cam = LevelCamera(seq["K"], 1, 0.0, None)
    region = _region(cam, max_depth=30.0)
    fit = dense.align_ground(_pyr(seq, 0), _pyr(seq, 1), cam, 1.0, S_TRUE, A_TRUE, mask=region)
    ev = dense.ground_evidence(_pyr(seq, 0), _pyr(seq, 1), cam, 1.0, fit, region)
    pts = dense.label_points(ev, DenseConfig().label_evidence, 300)
    assert len(pts) >= 50
    assert labels_at(seq["ground_mask"][0], pts).mean() >= 0.9
    assert (ev[~region] == 0).all()


# On painted bands over almost untextured asphalt, the evidence lies only along the bands' edges; the
# support carries the labels over the ground between them: the labels lie on the true ground (>= 95 %;
# the rest at the walls' feet, whose parallax is the ground's within the window) and the paint gets its
# share of them (paint pixels are 10-20 % of the region; the labels' share is at least half of the
# paint's share of the true ground in the region), where the evidence alone gives it (almost) none.
def test_support_labels_cover_paint_and_asphalt(pairs):
    seq = pairs["painted"]
    cam = LevelCamera(seq["K"], 1, 0.0, None)
    region = _region(cam)
    p0, p1 = _pyr(seq, 0), _pyr(seq, 1)
    fit = dense.align_ground(p0, p1, cam, 1.0, S_TRUE, A_TRUE, mask=region)
    thr = DenseConfig().label_evidence
    ev, support = dense.ground_evidence(p0, p1, cam, 1.0, fit, region, support_threshold=thr)
    assert not support[~region].any()
    paint = _grey(seq, 0) > 140
    truth = seq["ground_mask"][0] & region
    share = paint[truth].mean()
    assert 0.05 < share < 0.3
    pts = dense.label_points(support.view(np.uint8), 0, 300)
    assert len(pts) == 300
    assert labels_at(seq["ground_mask"][0], pts).mean() >= 0.95
    assert labels_at(paint, pts).mean() >= 0.5 * share
    assert support[truth].mean() >= 0.8  # most of the near ground, not only its texture
    assert (ev[support] > -thr).all()


# GroundVO on the painted ground: settled P(ground) against the exact ground mask (IoU >= 0.85).
def test_groundvo_labels_the_painted_ground():
    from polar_sim.metrics.ground import classifier_iou

    seq = make_sequence(24, width=W, height=H, speed=6.0, yaw_rate=0.08, dt=DT, ground="painted", seed=2)
    vo = GroundVO(seq["K"], 1.0, downsample=1, seed=0)
    es = [vo.process(r, t) for r, t in zip(seq["rgb"], seq["times"])]
    assert np.median([classifier_iou(e.ground_prob, m) for e, m in zip(es[12:], seq["ground_mask"][12:])]) >= 0.85
    assert all(e.diagnostics["calibration_fallback"] is None for e in es[12:])


@functools.cache
def _yaw_run(kind, roll_deg):
    """GroundVO with its defaults over 50 frames of the synthetic corridor (exact unicycle poses, 6 m/s,
    0.08 rad/s): the diagnostics of the frames whose yaw rate was fused, and the rotation angle error
    (deg) between frames 10 and 49 (23.4 m)."""
    seq = make_sequence(50, width=W, height=H, speed=6.0, yaw_rate=0.08, dt=DT, ground=kind, seed=2,
                        roll=np.radians(roll_deg))
    vo = GroundVO(seq["K"], 1.0, downsample=1, seed=0)
    es = [vo.process(r, t) for r, t in zip(seq["rgb"], seq["times"])]
    d = [dict(e.diagnostics, yaw_tracks=e.yaw_rate_raw) for e in es[4:] if "yaw_measured" in e.diagnostics]
    P, T = vo.trajectory(), seq["poses"]
    Re, Rt = P[10][:3, :3].T @ P[-1][:3, :3], T[10][:3, :3].T @ T[-1][:3, :3]

    def angle(R):
        return np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))

    # With a roll the angles are compared: the planar integration turns about the camera's own y axis,
    # 1 degree off the vertical, which no yaw rate can correct.
    return d, abs(angle(Re) - angle(Rt)) if roll_deg else angle(Re.T @ Rt)


def _within_3sd(d, z, var):
    return np.mean(np.abs(np.array([x[z] for x in d]) - 0.08) / np.sqrt([x[var] for x in d]) <= 3.0)


# The yaw rate fused from the tracks and the dense fit, on the textured and the tiled ground, and on the
# textured ground seen by a camera rolled 1 degree (a chassis leaning in the turn): each source's error
# stays within 3 of its predicted standard deviations on >= 90 % of the frames (the variances the
# fusion weighs by are honest, not only their ratio), and the heading drift between frames 10 and 49 is
# within the 0.01 deg/m. (The dense and the fused sources on the tiles: the next test.)
@pytest.mark.parametrize("kind, roll_deg", [("noise", 0.0), ("checker", 0.0), ("noise", 1.0)])
def test_fused_yaw_on_textured_and_tiled_ground(kind, roll_deg):
    d, deg = _yaw_run(kind, roll_deg)
    assert len(d) >= 40
    sources = [("yaw_tracks", "yaw_tracks_var")]
    if kind != "checker":
        sources += [("yaw_dense", "yaw_dense_var"), ("yaw_measured", "yaw_measured_var")]
    for z, var in sources:
        assert _within_3sd(d, z, var) >= 0.9, z
    assert deg / (6.0 * DT * 39) <= 0.01


# The dense and the fused yaw rates' predicted standard deviations on the synthetic tiles. Known miss
# (benchmarks/RESULTS.md, issue 35, tenth and eleventh sessions): the tiles pull the dense yaw change by
# about 1 % (both warp models); with the side slope (the default) 85 % of the frames lie within 3
# standard deviations (the pitch model: 91 %), and the fused yaw rate, which inherits the pull, 89 %
# (93 % before the sky labels moved P(ground), and with it the weights of both sources, a little).
@pytest.mark.xfail(strict=True, reason="dense and fused yaw on the synthetic tiles: 85 % and 89 % within 3 SD")
@pytest.mark.parametrize("source", ["yaw_dense", "yaw_measured"])
def test_dense_yaw_variance_holds_on_tiles(source):
    d, _ = _yaw_run("checker", 0.0)
    assert _within_3sd(d, source, source + "_var") >= 0.9


def test_label_points_spreads_a_fixed_number():
    ev = np.zeros((40, 60), np.float32)
    ev[20:, :30] = 10.0
    pts = dense.label_points(ev, 5.0, 7, step=4)
    assert len(pts) == 7 and (pts[:, 1] >= 20).all() and (pts[:, 0] < 30).all()
    assert len(dense.label_points(ev, 5.0, 1000, step=4)) == 5 * 8  # every grid point over the threshold
    assert len(dense.label_points(ev, 20.0, 10)) == 0


# Inverse-variance fusion, and the gate: two measurements too far apart for their variances are not
# averaged; the more certain one is kept.
def test_fuse_measurements():
    z, v = dense.fuse_measurements(1.0, 1.0, 3.0, 1.0, 3.0)
    assert z == pytest.approx(2.0) and v == pytest.approx(0.5)
    z, v = dense.fuse_measurements(1.0, 1.0, 2.0, 3.0, 3.0)
    assert z == pytest.approx(1.25) and v == pytest.approx(0.75)
    assert dense.fuse_measurements(1.0, 0.01, 5.0, 0.04, 3.0) == (1.0, 0.01)
    assert dense.fuse_measurements(1.0, 0.04, 5.0, 0.01, 3.0) == (5.0, 0.01)
    assert dense.fuse_measurements(1.0, np.inf, 5.0, 0.01, 3.0) == (5.0, 0.01)


# On the faint ground (almost no corners) GroundVO's measured speed stays within 3 % of the truth once
# the filter has started, and P(ground) separates ground from walls and sky (IoU >= 0.85).
def test_groundvo_measures_the_speed_on_a_faint_ground():
    from polar_sim.metrics.ground import classifier_iou

    seq = make_sequence(24, width=W, height=H, speed=6.0, yaw_rate=0.08, dt=DT, ground="faint", seed=2)
    vo = GroundVO(seq["K"], 1.0, downsample=1, seed=0)
    es = [vo.process(r, t) for r, t in zip(seq["rgb"], seq["times"])]
    meas = np.array([e.speed_measured for e in es[6:]])
    assert np.isfinite(meas).all() and np.all(np.abs(meas - 6.0) < 0.03 * 6.0)
    assert abs(es[-1].speed - 6.0) < 0.03 * 6.0
    assert np.median([classifier_iou(e.ground_prob, m) for e, m in zip(es[12:], seq["ground_mask"][12:])]) >= 0.85
    assert all(e.diagnostics["dense_ok"] for e in es[1:])


# The published method has no dense stage: it never calls the alignment.
def test_published_never_runs_the_dense_fit(monkeypatch, corridor):
    import polar_sim.ground.vo as vo_mod

    def boom(*a, **k):
        raise AssertionError("align_ground called")

    monkeypatch.setattr(vo_mod, "align_ground", boom)
    vo = GroundVO.published(corridor["K"], corridor["camera_height"])
    es = [vo.process(corridor["rgb"][i], corridor["times"][i]) for i in range(5)]
    assert "dense_ok" not in es[-1].diagnostics and np.isnan(es[-1].speed_dense)
    vo2 = GroundVO(corridor["K"], corridor["camera_height"])  # the default runs it from the second image on
    vo2.process(corridor["rgb"][0], 0.0)
    with pytest.raises(AssertionError, match="align_ground"):
        vo2.process(corridor["rgb"][1], corridor["times"][1])


def _surface_reference(cam, h, shape_c, p, slip, xy):
    """Where pixels ``xy`` (m, 2) of the first image of a ground y = h + c1 z + c2 z² + c3 x (level frame,
    y down) appear in the second, built from the geometry alone: each ray's nearest positive root of the
    surface (numpy.roots), the camera's unicycle step integrated numerically (scipy.integrate.quad) and
    turned by arctan(-slip a), and the second camera's orientation R_y(a) R_x(b) (scipy Rotation)."""
    from scipy.integrate import quad
    from scipy.spatial.transform import Rotation

    s, a, b = p[:3]
    c1, c2, c3 = shape_c
    fx = quad(lambda t: np.sin(a * t), 0, 1, epsabs=1e-14)[0] * s  # heading θ(t) = a t along the arc
    fz = quad(lambda t: np.cos(a * t), 0, 1, epsabs=1e-14)[0] * s
    d = Rotation.from_euler("y", np.arctan(-slip * a)).apply([fx, 0.0, fz])
    C = Rotation.from_euler("y", a).as_matrix() @ Rotation.from_euler("x", b).as_matrix()
    out = np.full((len(xy), 2), np.nan)
    for i, (x, y) in enumerate(xy):
        ray = cam.R_lc @ np.linalg.solve(cam.K, [x, y, 1.0])
        u, v = ray[0] / ray[2], ray[1] / ray[2]
        # Z v = h + c1 Z + c2 Z² + c3 u Z
        roots = np.roots([c2, c1 + c3 * u - v, h]) if c2 else np.array([h / (v - c1 - c3 * u)])
        roots = np.real(roots[np.isreal(roots) & (np.real(roots) > 0)])
        if len(roots) == 0:
            continue
        Z = roots.min()
        X2 = C.T @ (np.array([u, v, 1.0]) * Z - d)
        q = cam.K @ cam.R_lc.T @ X2
        out[i] = q[:2] / q[2]
    return out


# The surface warp (side slope, or slope, curvature and side slope) against the geometry built
# independently (above), with and without the camera's sideways slip, to round-off; rays that miss a
# ground falling away ahead are NaN in both. Its Jacobian against central differences of that reference.
@pytest.mark.parametrize("shape, coef", [((2,), (0.0, 0.0, -0.03)), ((0, 1, 2), (0.04, 0.003, 0.02)),
                                         ((0, 1, 2), (0.02, 0.02, 0.0))])
@pytest.mark.parametrize("slip", [0.0, -1.0])
def test_surface_warp_is_the_exact_ground_motion(shape, coef, slip):
    cam = LevelCamera(np.array([[320.0, 0.0, 320.0], [0.0, 320.0, 240.0], [0.0, 0.0, 1.0]]), 2, 0.05, None)
    warp = dense._SurfaceWarp(cam, 1.2, shape, slip=slip)
    rng = np.random.default_rng(3)
    xy = np.c_[rng.uniform(0, 320, 60), rng.uniform(125, 240, 60)]
    p = np.r_[0.6, 0.04, -0.01, [coef[i] for i in shape]]
    got, J = warp.points(np.c_[xy, np.ones(len(xy))], p, jacobian=True)
    want = _surface_reference(cam, 1.2, coef, p, slip, xy)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    if coef[1] > 0.01:
        assert np.isnan(want).any()  # a ground falling away ahead: the rays near the horizon miss it
    assert np.nanmax(np.abs(got - want)) < 1e-8  # px
    full = np.array(coef, dtype=float)
    for i in range(len(p)):
        e = (1e-5, 1e-6, 1e-6)[i] if i < 3 else 1e-6
        hi, lo = p.copy(), p.copy()
        hi[i] += e
        lo[i] -= e
        ch, cl = full.copy(), full.copy()
        if i >= 3:
            ch[shape[i - 3]], cl[shape[i - 3]] = hi[i], lo[i]
        ref = (_surface_reference(cam, 1.2, ch, hi, slip, xy) - _surface_reference(cam, 1.2, cl, lo, slip, xy)) / (2 * e)
        ok = np.isfinite(ref).all(axis=1) & np.isfinite(J[i]).all(axis=1)
        assert ok.sum() >= 30
        assert np.abs(J[i][ok] - ref[ok]).max() < 1e-3 * max(1.0, np.abs(ref[ok]).max()), i


# The template pixels: the strongest gradient of each block x block cell of the mask (the first in
# row order on a tie), above the threshold, then an even subset: against a loop over the cells.
@pytest.mark.parametrize("block", [1, 2, 3])
def test_select_pixels_picks_each_cells_strongest(block):
    rng = np.random.default_rng(block)
    img = np.round(rng.normal(0, 3, (37, 53))).astype(np.float32)  # rounded: many ties
    grad = dense._gradients(img)
    mask = rng.random(img.shape) < 0.7
    mask[:9] = False
    want = []
    r0 = 9 - 9 % block
    for top in range(r0, 37 - (37 - r0) % block, block):
        for left in range(0, 53 - 53 % block, block):
            best, at = -1.0, None
            for y in range(top, top + block):
                for x in range(left, left + block):
                    g2 = float(grad[0][y, x]) ** 2 + float(grad[1][y, x]) ** 2 if mask[y, x] else 0.0
                    if g2 > best + 1e-9 * best:
                        best, at = g2, (x, y)
            if best > 0.5 ** 2:
                want.append(at)
    got = dense.select_pixels(grad, mask, block=block, max_pixels=10_000, min_gradient=0.5)
    assert np.array_equal(got, np.array(want, dtype=float))
    few = dense.select_pixels(grad, mask, block=block, max_pixels=7, min_gradient=0.5)
    assert np.array_equal(few, got[np.linspace(0, len(got) - 1, 7).astype(int)])
    assert dense.select_pixels(grad, np.zeros_like(mask), block=block, max_pixels=10, min_gradient=0.5).shape == (0, 2)


# One Gauss–Newton step against the normal equations written out: Tukey weights of the robust scale,
# the Jacobian's NaN entries as 0, the prior's diagonal, the solve, and the median pixel motion.
def test_gauss_newton_step_is_the_normal_equations():
    rng = np.random.default_rng(4)
    k, m = 4, 500
    r = rng.standard_t(3, m) * 2.0
    gx, gy = rng.normal(0, 5, m), rng.normal(0, 5, m)
    r[:7] = np.nan
    gx[7:9] = np.nan
    Jp = rng.normal(0, 30, (k, m, 2))
    Jp[2, 20:25, 1] = np.nan
    w0 = rng.uniform(0.2, 1.0, m)
    p = rng.normal(0, 0.1, k)
    prior_var = np.array([np.inf, np.inf, np.inf, 0.03 ** 2])
    ok, H, step, sigma, n, moved = dense._gn_iteration(r, gx, gy, Jp, w0, np.nan, 0.3, 100, prior_var, p)
    good = np.isfinite(r) & np.isfinite(gx) & np.isfinite(gy)
    s = max(1.4826 * np.median(np.abs(r[good])), 0.3)
    assert sigma == pytest.approx(s, rel=1e-12)
    u = r[good] / (4.685 * s)
    w = w0[good] * np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
    Jg = np.nan_to_num(Jp[:, good])
    J = (gx[good] * Jg[..., 0] + gy[good] * Jg[..., 1]).T
    P = s * s / prior_var
    H_want = (J * w[:, None]).T @ J + np.diag(P)
    g_want = (J * w[:, None]).T @ r[good] + P * p
    step_want = -np.linalg.solve(H_want, g_want)
    assert ok and n == np.count_nonzero(w)
    np.testing.assert_allclose(H, H_want, rtol=1e-10)
    np.testing.assert_allclose(step, step_want, rtol=1e-8, atol=1e-14)
    assert moved == pytest.approx(np.median(np.abs(np.tensordot(step, Jg, axes=1)).sum(axis=1)), rel=1e-10)
    # too few pixels inside, or weighted: no step
    assert not dense._gn_iteration(r, gx, gy, Jp, w0, np.nan, 0.3, 600, prior_var, p)[0]
    assert not dense._gn_iteration(r, gx, gy, Jp, np.zeros(m), 1.0, 0.3, 100, prior_var, p)[0]
