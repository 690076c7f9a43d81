"""GroundVO: self-supervised ground segmentation and monocular visual odometry with scale from the
ground (spec ``ground.md``; B. Lee, K. Daniilidis, D. D. Lee, ICRA 2015).

Per image: track features over three frames (KLT), solve the nonholonomic image kinematics for the
rotation rates and the scaled inverse depths d̄ = V/Z (arrow-structured LS + IRLS), fit a ground model
to the points below the horizon with RANSAC whose draws are weighted by the learned ground
probability, read the speed from the ground model and the camera height (V = a'6 h), filter speed
and yaw rate, train the colour classifier on the inliers, and integrate the pose.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import numpy as np

from polar_sim._validation import as_image, as_int, as_intrinsics, as_positive_float, as_rng, check_choice
from polar_sim.ground import frontend
from polar_sim.ground._checks import as_time, as_unit_interval
from polar_sim.ground.calibration import PlattCalibrator
from polar_sim.ground.classifier import GroundColourModel, window_index
from polar_sim.ground.depth import fuse, propagate
from polar_sim.ground.filters import KF1D
from polar_sim.ground.image import grey, hsv216, reduce2x
from polar_sim.ground.integration import motion_step
from polar_sim.ground.models import GROUND_MODELS, default_iterations, fit_ground
from polar_sim.ground.motion import estimate_motion
from polar_sim.params import Parameterised

__all__ = ["GroundVO", "GroundEstimate", "STATUSES", "STAGES"]

logger = logging.getLogger(__name__)

#: Values of ``GroundEstimate.status``.
STATUSES = ("init", "ok", "static", "no_features", "few_triplets", "no_ground")

#: Stage parameters: each is "fixed" (the spec with its fixes, the default) or "published" (the published
#: code's behaviour there, spec §10). ``GroundVO.published()`` sets all of them, with the other parameters
#: of the published code.
STAGES = ("hue_wrap", "ransac_draw", "track_gates", "filters", "depth_fusion", "ground_labels", "pose_steps")

_MODEL_ALIASES = {"2p": "2param", "3p": "3param", "6p": "6param", "3p_code": "3param"}
_F_REF = 359.428  # focal length (px) of the processed KITTI images the pixel thresholds were tuned on
_H_REF = 1.68  # camera height (m) the inverse-depth variances were tuned on
_H_RANGE = (1e-3, 1e4)  # camera heights (m) accepted


@dataclass(frozen=True)
class GroundEstimate:
    """Result of :meth:`GroundVO.process` for one image.

    Attributes
    ----------
    t : float
        Timestamp of this image, s.
    index : int
        Index of this image (0 for the first).
    speed, yaw_rate : float
        Filtered forward speed (m/s) and yaw rate (rad/s, about camera +y, > 0 turns right). They
        describe the middle frame ``index - 1`` (central-difference flow).
    speed_raw : float
        Raw RANSAC scale V of this frame, m/s (NaN when no ground model was fitted).
    yaw_rate_raw : float
        Measured (unfiltered) yaw rate, rad/s (NaN when motion was not solved).
    rates_raw : ndarray of shape (3,)
        Measured (Ωx, Ωy, Ωz), rad/s (NaN when motion was not solved).
    pose : ndarray of shape (4, 4)
        Camera ``index`` in the first camera's frame, OpenCV axes (a KITTI pose). At index 1 it is
        provisional (see ``diagnostics["pose_provisional"]``); :meth:`GroundVO.trajectory` has the
        final poses.
    ground_prob : ndarray of shape (H, W), float32
        Learned P(ground | colour) of this image, input resolution.
    candidates : ndarray of shape (m, 2)
        Ground candidates (pixel column, row of the input image, 0-based) at the middle frame
        ``index - 1``.
    candidate_dbar : ndarray of shape (m,)
        Their scaled inverse depths V/Z, 1/s.
    candidate_uv : ndarray of shape (m, 2)
        Their normalised image coordinates (u, v) in the level frame (the RANSAC data with
        ``candidate_dbar`` and h: ``models.fit_ground(u, v, dbar, h, ...)`` re-runs the fit offline).
    candidate_prob : ndarray of shape (m,)
        The learned P(ground) at the candidates (map of the previous image) that weighted this frame's
        RANSAC draws as ``candidate_prob ** weight_exponent``; NaN before the classifier's first update.
    inlier_mask : ndarray of shape (m,), bool
        RANSAC inliers among the candidates.
    status : str
        One of ``STATUSES``.
    diagnostics : dict
        Counts and flags of this frame: n_features, n_tracked, n_triplets, n_motion_points,
        n_candidates, n_inliers, static, ransac_iterations, irls_iterations, weighted, status,
        pose_provisional, middle_index.
    """

    t: float
    index: int
    speed: float
    yaw_rate: float
    speed_raw: float
    yaw_rate_raw: float
    rates_raw: np.ndarray
    pose: np.ndarray
    ground_prob: np.ndarray
    candidates: np.ndarray
    candidate_dbar: np.ndarray
    candidate_uv: np.ndarray
    candidate_prob: np.ndarray
    inlier_mask: np.ndarray
    status: str
    diagnostics: dict = field(default_factory=dict)

    @property
    def inliers(self):
        """Ground inliers (n, 2): pixel column, row of the input image at the middle frame."""
        return self.candidates[self.inlier_mask]


class GroundVO(Parameterised):
    """Online self-supervised ground segmentation and monocular VO for a ground vehicle.

    The module contract (:class:`polar_sim.params.Parameterised`): the constructor stores its
    parameters, ``get_params()``/``set_params()``, learned state in ``_``-suffixed attributes created
    by the first :meth:`process`, :meth:`reset`. The published code's behaviour is the preset
    :meth:`published` (parameters, among them the ``STAGES`` switches below).

    Parameters
    ----------
    K : array_like of shape (3, 3)
        Pinhole intrinsics of the input images (px), square pixels assumed, no distortion.
    camera_height : float
        Height h of the optical centre above the ground, along camera +y, m.
    model : {"6param", "2param", "plane3", "3param"}, default="6param"
        Ground model (spec §4.2): second-order surface (ridge-regularised), level ground
        d̄ = a + (V/h) v, general plane, or the published code's 3-parameter model (B13).
    sampling : {"weighted", "uniform"}, default="weighted"
        RANSAC draws in proportion to the learned ground probability, or uniformly.
    compat : {"fixed", "code"}, default="fixed"
        Shortcut kept for existing callers: "code" resolves every parameter left at its default to the
        published code's value and sets every stage below to "published"; ``GroundVO.published()`` is
        the same behaviour spelled out as parameters (bit-identical).
    hue_wrap, ransac_draw, track_gates, filters, depth_fusion, ground_labels, pose_steps : \
{"fixed", "published"}, default="fixed"
        Per stage, the spec's (fixed) behaviour or the published code's (spec §10): ``hue_wrap`` the
        HSV hue wrap (B7: negative hues +5/6); ``ransac_draw`` the cumulative draw with redraws and raw
        P_G weights in the 6param LS; ``track_gates`` the straightness gate without angle wrap and the
        per-axis static test; ``filters`` the code's adaptive speed noise, resets of the filters to
        their process noise when static, and a zero yaw measurement when motion is not solved (B10);
        ``depth_fusion`` B5 (the raw measurement propagated, the raw RANSAC V, new tracks fused
        against 0, the new-track variance 2 (1.68/h)²); ``ground_labels`` B8 (non-ground = tracks
        with a negative ground count, frame-k labels), a ground pseudo-count 0.5 and a map border of
        0.5; ``pose_steps`` semi-implicit integration and no revision of the first step (B27).
    seed : int, numpy.random.Generator or None, default=0
        RANSAC randomness. An int (or a Generator) makes every output bit-identical across runs and
        processes; None draws fresh OS entropy, so two runs differ (issue 17: the former default).
    n_iter : int, optional
        RANSAC iterations (default 6param 55 [99 under "code"], 2param 16, plane3/3param 69).
    lam : float, default=0.1
        Ridge weight of the 6param hypotheses and final fit.
    sigma : float, optional
        RANSAC inlier threshold in normalised units (default 0.002 for 6param, 0.005 otherwise).
    weight_exponent : float, optional
        RANSAC weight P_G^p (default 1, the text; 2 under "code", B11).
    downsample : {2, 1}, default=2
        One 2x pyramid reduction before processing (spec §2.1), or none.
    max_features : int, default=400
        Tracked features kept per frame.
    klt_window, klt_levels : int, default=11, 3
        Lucas–Kanade window (px) and pyramid levels.
    fb_max : float, default=0.5
        Forward–backward tracking consistency limit, processed px.
    irls_iter : int, optional
        IRLS iterations (default 10; "code": none, B1).
    n_global : {3, 1}, default=3
        Global unknowns of the kinematics: (Ωx, Ωy, Ωz) as the code (B4), or the yaw rate only (text).
    ridge : float, default=1.0
        Ridge on the pitch and roll rates Ωx, Ωz.
    estimate_foe : bool, default=False
        Also estimate the focus of expansion (Gauss–Newton, n_g = 5).
    exact_flow : bool, default=True
        Correct the centred flow for the exact motion between the three frames (not in the spec, and
        off under "code"): removes the O((V dt/Z)²) bias of the differential model on near points.
    ground_warp : bool, default=True
        Also track points below the horizon in the previous image warped by the predicted ground
        homography (from the filtered V, ω and h), keeping the better-matching track: removes most of
        the KLT error on strongly foreshortened near ground.
    min_triplets, min_inliers : int, default=30, 10
        Minimum three-frame tracks to solve motion; minimum ground inliers to accept the scale.
    speed_prior, speed_prior_var : float, default=0.0, 25.0
        Prior of the speed filter, m/s and (m/s)² (never ground truth, B21). "code" uses P0 = 2 q.
    speed_q, speed_r : float, default=0.15, 3.0
        Speed filter process and nominal measurement noise, (m/s)² (rescale with V_typ², §9.3).
    yaw_prior, yaw_prior_var, yaw_q, yaw_r : float, default=0.0, 4.0, 2.0, 5.0
        Yaw-rate filter prior, process and measurement noise (rad/s, (rad/s)²).
    depth_q, depth_r, depth_p_reset : float, optional
        Inverse-depth propagation noise, measurement noise and reset variance ((1/m)²); default the
        spec's 0.02, 0.6, 0.95 scaled by (1.68 / h)².
    alpha : float, default=0.7
        Colour histogram decay.
    ground_prior : float, default=0.2
        Class prior P(ground).
    ng_from_outliers : bool, optional
        Train non-ground also on lower-half points that are clear RANSAC outliers (default True;
        "code": False, B9): a residual above ``ng_outlier_sigma`` times the inlier threshold (and,
        with ``ng_outlier_history``, on a track that has never been a ground inlier).
    ng_outlier_sigma : float, default=3
        How clear an outlier must be, in multiples of the RANSAC inlier threshold.
    ng_outlier_history : bool, default=False
        Only tracks never counted as ground inliers become non-ground outliers. On a weakly
        textured ground the few ground tracks are noisy and often outliers for a frame; labelled
        non-ground, they teach the classifier the ground's colour as non-ground. On the dev route
        ``dev_uniform``, ``ng_outlier_sigma=6, ng_outlier_history=True`` lifts the mean IoU from 0.65
        to 0.75, but it is not the default: it breaks the dev ordering of weighted and uniform RANSAC
        in ΔV_mean for the 2-parameter model (``benchmarks/RESULTS.md``).
    horizon_row : float, optional
        Image row (input px) below which points are ground candidates (default: below the horizon of the
        level frame, i.e. the principal row for a level camera).
    camera_pitch : float, default=0.0
        Known downward pitch of the camera relative to the vehicle (rad, > 0 looks down). Feature rays are
        de-rotated into the level vehicle-aligned frame before the kinematics (spec §9.2); poses stay
        camera poses.
    integration : {"planar", "3d"}, default="planar"
        Planar unicycle integration, or 3-D with the measured pitch/roll rates (non-flat terrain).
    calibration : {"platt", "none"}, optional
        Calibration of the output ``ground_prob`` (default "platt"; "none" under "code"): the log-odds
        of the posterior, averaged over ``calib_window`` px, mapped by σ(a z + b) with (a, b) learned
        online from the module's own labels (:mod:`polar_sim.ground.calibration`). RANSAC keeps
        weighting its draws by the uncalibrated single-pixel posterior of the spec.
    calib_window : int, default=7
        Side (processed px, odd) of the window the log-odds are averaged over before calibration.
    calib_decay, calib_prior_weight : float, default=0.99, 5
        The calibrator's per-update decay of old self-labels (0..1) and the weight (samples) of its
        prior toward the identity map (:class:`~polar_sim.ground.calibration.PlattCalibrator`). Chosen
        on dev routes only (``benchmarks/bench_ground_calibration.py``; 0.85 and 50 before).
    train_depth : float, optional
        Ground inliers farther than this (m, flat-ground depth h / v in the level frame) do not train
        the ground colour (default 30; "off" and under "code": no limit): near the horizon any point
        fits the ground model within the RANSAC noise, sky edges and far obstacles included.
    decay_samples : float, optional
        Evidence-weighted histogram decay (default 450 window pixels, 50 points; "off" and under
        "code": the spec's decay by α per update): an update with fewer samples forgets less
        (:class:`~polar_sim.ground.classifier.GroundColourModel`).
    """

    def __init__(self, K, camera_height, *, model="6param", sampling="weighted", compat="fixed", seed=0,
                 n_iter=None, lam=0.1, sigma=None, weight_exponent=None, downsample=2, max_features=400,
                 klt_window=11, klt_levels=3, fb_max=0.5, irls_iter=None, n_global=3, ridge=1.0,
                 estimate_foe=False, exact_flow=True, ground_warp=True, min_triplets=30, min_inliers=10,
                 speed_prior=0.0, speed_prior_var=25.0, speed_q=0.15, speed_r=3.0, yaw_prior=0.0,
                 yaw_prior_var=4.0, yaw_q=2.0, yaw_r=5.0, depth_q=None, depth_r=None, depth_p_reset=None,
                 alpha=0.7, ground_prior=0.2, ng_from_outliers=None, ng_outlier_sigma=3.0,
                 ng_outlier_history=False, horizon_row=None, camera_pitch=0.0,
                 integration="planar", calibration=None, calib_window=7, calib_decay=0.99, calib_prior_weight=5.0,
                 train_depth=None, decay_samples=None,
                 hue_wrap="fixed", ransac_draw="fixed", track_gates="fixed", filters="fixed", depth_fusion="fixed",
                 ground_labels="fixed", pose_steps="fixed"):
        self.K = K
        self.camera_height = camera_height
        self.model = model
        self.sampling = sampling
        self.compat = compat
        self.seed = seed
        self.n_iter = n_iter
        self.lam = lam
        self.sigma = sigma
        self.weight_exponent = weight_exponent
        self.downsample = downsample
        self.max_features = max_features
        self.klt_window = klt_window
        self.klt_levels = klt_levels
        self.fb_max = fb_max
        self.irls_iter = irls_iter
        self.n_global = n_global
        self.ridge = ridge
        self.estimate_foe = estimate_foe
        self.exact_flow = exact_flow
        self.ground_warp = ground_warp
        self.min_triplets = min_triplets
        self.min_inliers = min_inliers
        self.speed_prior = speed_prior
        self.speed_prior_var = speed_prior_var
        self.speed_q = speed_q
        self.speed_r = speed_r
        self.yaw_prior = yaw_prior
        self.yaw_prior_var = yaw_prior_var
        self.yaw_q = yaw_q
        self.yaw_r = yaw_r
        self.depth_q = depth_q
        self.depth_r = depth_r
        self.depth_p_reset = depth_p_reset
        self.alpha = alpha
        self.ground_prior = ground_prior
        self.ng_from_outliers = ng_from_outliers
        self.ng_outlier_sigma = ng_outlier_sigma
        self.ng_outlier_history = ng_outlier_history
        self.horizon_row = horizon_row
        self.camera_pitch = camera_pitch
        self.integration = integration
        self.calibration = calibration
        self.calib_window = calib_window
        self.calib_decay = calib_decay
        self.calib_prior_weight = calib_prior_weight
        self.train_depth = train_depth
        self.decay_samples = decay_samples
        self.hue_wrap = hue_wrap
        self.ransac_draw = ransac_draw
        self.track_gates = track_gates
        self.filters = filters
        self.depth_fusion = depth_fusion
        self.ground_labels = ground_labels
        self.pose_steps = pose_steps
        # Fail early on the arguments the issue names; everything else is checked in _config().
        self._config()

    # ------------------------------------------------------------------------------------------------
    # configuration and state

    #: The published code's parameters (spec §10; ``published()`` adds the two that depend on others:
    #: 99 RANSAC iterations for the 6param model (B18) and the speed filter's initial variance 2 q).
    PUBLISHED = dict(weight_exponent=2.0, irls_iter=0, n_global=3, estimate_foe=False, exact_flow=False,
                     ng_from_outliers=False, calibration="none", train_depth="off", decay_samples="off",
                     **{k: "published" for k in STAGES})

    @classmethod
    def published(cls, K, camera_height, **overrides):
        """A GroundVO with the published code's behaviour, as parameters (bit-identical to
        ``compat="code"``); ``overrides`` change any of them."""
        kw = {**cls.PUBLISHED, **overrides}
        model = _MODEL_ALIASES.get(kw.get("model", "6param"), kw.get("model", "6param"))
        kw.setdefault("n_iter", default_iterations(model, "code") if model in GROUND_MODELS else None)
        kw.setdefault("speed_prior_var", 2 * kw.get("speed_q", 0.15))
        return super().published(K, camera_height, **kw)

    def _check_params(self):
        return self._config()

    def _config(self):
        """Validated, resolved parameters (a dict); raises ValueError/TypeError on a bad parameter."""
        c = {}
        c["K"] = as_intrinsics(self.K, "K")
        c["h"] = as_positive_float(self.camera_height, "camera_height")
        if not _H_RANGE[0] <= c["h"] <= _H_RANGE[1]:
            # The noise defaults scale with (1.68 / h)^2: outside this range they over- or underflow.
            raise ValueError(f"camera_height: expected {_H_RANGE[0]:g} to {_H_RANGE[1]:g} m, got {self.camera_height!r}")
        if not isinstance(self.model, str):
            raise TypeError(f"model: expected one of {', '.join(GROUND_MODELS)}, got {type(self.model).__name__}")
        model = _MODEL_ALIASES.get(self.model, self.model)
        c["model"] = check_choice(model, GROUND_MODELS, "model")
        c["sampling"] = check_choice(self.sampling, ("weighted", "uniform"), "sampling")
        c["compat"] = check_choice(self.compat, ("fixed", "code"), "compat")
        as_rng(self.seed, "seed")  # type check only; the generator is made in _build
        code = c["compat"] == "code"
        for name in STAGES:  # compat="code" is every stage published
            c[name] = "published" if code else check_choice(getattr(self, name), ("fixed", "published"), name)
        c["n_iter"] = (default_iterations(c["model"], c["compat"]) if self.n_iter is None
                       else as_int(self.n_iter, "n_iter", minimum=1))
        c["lam"] = as_positive_float(self.lam, "lam", allow_zero=True)
        c["sigma"] = None if self.sigma is None else as_positive_float(self.sigma, "sigma")
        c["p"] = (2.0 if code else 1.0) if self.weight_exponent is None else as_positive_float(
            self.weight_exponent, "weight_exponent", allow_zero=True)
        c["ds"] = check_choice(self.downsample, (1, 2), "downsample")
        c["max_features"] = as_int(self.max_features, "max_features", minimum=10)
        c["win"] = as_int(self.klt_window, "klt_window", minimum=3)
        c["levels"] = as_int(self.klt_levels, "klt_levels", minimum=0)
        c["fb_max"] = as_positive_float(self.fb_max, "fb_max")
        c["irls_iter"] = as_int(10 if self.irls_iter is None else self.irls_iter, "irls_iter", minimum=0)
        if code:
            c["irls_iter"] = 0  # B1: the published IRLS is inert
        c["n_global"] = 3 if code else check_choice(self.n_global, (1, 3), "n_global")  # B1 under "code"
        c["ridge"] = as_positive_float(self.ridge, "ridge", allow_zero=True)
        c["foe"] = bool(self.estimate_foe) and not code
        c["exact_flow"] = bool(self.exact_flow) and not code
        c["ground_warp"] = bool(self.ground_warp)
        c["min_triplets"] = as_int(self.min_triplets, "min_triplets", minimum=10)
        c["min_inliers"] = as_int(self.min_inliers, "min_inliers", minimum=2)
        for name in ("speed_prior", "yaw_prior"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not np.isfinite(v):
                raise ValueError(f"{name}: expected a finite number, got {v!r}")
            c[name] = float(v)
        for name in ("speed_prior_var", "speed_q", "speed_r", "yaw_prior_var", "yaw_q", "yaw_r"):
            c[name] = as_positive_float(getattr(self, name), name)
        if code:
            c["speed_prior_var"] = 2 * c["speed_q"]  # the code's P0 = 2 q
        hs = (_H_REF / c["h"]) ** 2
        c["depth_q"] = 0.02 * hs if self.depth_q is None else as_positive_float(self.depth_q, "depth_q")
        c["depth_r"] = 0.6 * hs if self.depth_r is None else as_positive_float(self.depth_r, "depth_r")
        c["depth_p_reset"] = 0.95 * hs if self.depth_p_reset is None else as_positive_float(
            self.depth_p_reset, "depth_p_reset")
        c["depth_p_new"] = 2.0 * hs
        c["depth_usable"] = 5.0 * hs
        c["alpha"] = as_unit_interval(self.alpha, "alpha")
        c["ground_prior"] = as_unit_interval(self.ground_prior, "ground_prior", open_low=True, open_high=True)
        c["ng_outliers"] = (not code) if self.ng_from_outliers is None else bool(self.ng_from_outliers)
        c["ng_outlier_sigma"] = as_positive_float(self.ng_outlier_sigma, "ng_outlier_sigma")
        if not isinstance(self.ng_outlier_history, (bool, np.bool_)):
            raise ValueError(f"ng_outlier_history: expected True or False, got {self.ng_outlier_history!r}")
        c["ng_outlier_history"] = bool(self.ng_outlier_history)
        if self.horizon_row is not None:
            c["horizon_row"] = float(as_positive_float(self.horizon_row, "horizon_row", allow_zero=True))
        else:
            c["horizon_row"] = None
        pitch = self.camera_pitch
        if isinstance(pitch, bool) or not isinstance(pitch, (int, float, np.floating, np.integer)) \
                or not np.isfinite(pitch) or abs(pitch) >= np.pi / 2:
            raise ValueError(f"camera_pitch: expected a finite angle in (-pi/2, pi/2) rad, got {pitch!r}")
        c["pitch"] = float(pitch)
        c["integration"] = check_choice(self.integration, ("planar", "3d"), "integration")
        c["calibration"] = ("none" if code else "platt") if self.calibration is None else check_choice(
            self.calibration, ("platt", "none"), "calibration")
        c["calib_window"] = as_int(self.calib_window, "calib_window", minimum=1)
        c["calib_decay"] = as_unit_interval(self.calib_decay, "calib_decay")
        c["calib_prior_weight"] = as_positive_float(self.calib_prior_weight, "calib_prior_weight", allow_zero=True)
        # None picks the default of the mode; under "code" the published behaviour (no limit, per-update decay).
        # None: the mode's default; "off": the spec's behaviour (no depth limit; decay by alpha per update).
        for name, default in (("train_depth", 30.0), ("decay_samples", 450.0)):
            v = getattr(self, name)
            if v is None:
                c[name] = None if code else default
            elif isinstance(v, str):
                check_choice(v, ("off",), name)
                c[name] = None
            else:
                c[name] = as_positive_float(v, name)
        if c["calib_window"] % 2 == 0:
            raise ValueError(f"calib_window: expected an odd window side, got {self.calib_window!r}")
        return c

    def _build(self, shape):
        c = self.cfg_ = self._config()
        ds = c["ds"]
        K = c["K"]
        self.image_shape_ = tuple(shape[:2])
        # Processed-image intrinsics: output pixel i sits on input pixel ds*i (0-based centres).
        self.fx_, self.fy_ = K[0, 0] / ds, K[1, 1] / ds
        self.cx_, self.cy_ = K[0, 2] / ds, K[1, 2] / ds
        hr = c["horizon_row"]
        self.horizon_ = None if hr is None else hr / ds
        cp, sp = np.cos(c["pitch"]), np.sin(c["pitch"])
        # Rotation camera -> level frame: the optical axis of a camera pitched down by θ is (0, sin θ, cos θ).
        self.R_lc_ = np.array([[1.0, 0.0, 0.0], [0.0, cp, sp], [0.0, -sp, cp]])
        self.Kp_ = np.array([[self.fx_, 0.0, self.cx_], [0.0, self.fy_, self.cy_], [0.0, 0.0, 1.0]])
        # Pixel thresholds of the spec were tuned on 621-px KITTI images (f = 359.4 px); flow scales with f.
        self.pixel_scale_ = self.fx_ / _F_REF
        hp, wp = (shape[0] + ds - 1) // ds, (shape[1] + ds - 1) // ds
        self.cell_ = int(max(6, round(np.sqrt(hp * wp / c["max_features"]))))
        pub_f = c["filters"] == "published"
        self.speed_filter_ = KF1D(c["speed_prior"], c["speed_prior_var"],
                                  c["speed_q"], c["speed_r"], adaptive="code" if pub_f else "innovation")
        self.yaw_filter_ = KF1D(c["yaw_prior"], c["yaw_prior_var"], c["yaw_q"], c["yaw_r"])
        self.classifier_ = GroundColourModel(alpha=c["alpha"], prior=c["ground_prior"],
                                             pseudo_ground=0.5 if c["ground_labels"] == "published" else 1.0, pseudo_nonground=1.0,
                                             decay_samples=c["decay_samples"])
        self.rng_ = as_rng(self.seed, "seed")
        # Tracks (processed px): positions at frames k-2, k-1, k (NaN = not tracked then) and state.
        self.tracks_ = _empty_tracks()
        self.poses_ = [np.eye(4)]
        self.times_ = []
        self.n_frames_ = 0
        self.prev_grey_ = None
        self.prev_labels_ = None
        self.prev_prob_ = None
        self.prev_score_ = None
        self.calibrator_ = PlattCalibrator(decay=c["calib_decay"], prior_weight=c["calib_prior_weight"])
        self.rates_ = np.zeros(3)

    def reset(self):
        """Forget everything learned; the next image starts a new sequence."""
        for k in [k for k in vars(self) if k.endswith("_")]:
            delattr(self, k)
        return self

    def trajectory(self):
        """Poses of all processed images, (n, 4, 4): camera k in the first camera's frame (KITTI)."""
        if not hasattr(self, "poses_"):
            return np.zeros((0, 4, 4))
        return np.array(self.poses_)

    def timestamps(self):
        """Timestamps (n,) of all processed images, s."""
        return np.array(getattr(self, "times_", []), dtype=np.float64)

    # ------------------------------------------------------------------------------------------------

    def process(self, rgb, t):
        """Process one image.

        Parameters
        ----------
        rgb : ndarray of shape (H, W, 3), uint8
            RGB image; every image of a sequence has the size of the first.
        t : float
            Timestamp, s, strictly increasing.

        Returns
        -------
        GroundEstimate
        """
        # Validate everything before touching the state: a rejected input leaves the estimator as it was.
        rgb = as_image(rgb, "rgb", channels=3, dtype=np.uint8)
        t = as_time(t, "t")
        if rgb.shape[0] < 16 or rgb.shape[1] < 16:
            raise ValueError(f"rgb: expected an image of at least 16x16 pixels, got {rgb.shape[:2]}")
        built = hasattr(self, "cfg_")
        if built:
            if tuple(rgb.shape[:2]) != self.image_shape_:
                raise ValueError(f"rgb: expected image size {self.image_shape_} like the first image, "
                                 f"got {tuple(rgb.shape[:2])}")
            if self.times_ and not t > self.times_[-1]:
                raise ValueError(f"t: timestamps must increase strictly; got {t!r} after {self.times_[-1]!r}")
        else:
            self._build(rgb.shape)  # re-validates the parameters (they may have been set since construction)
        return self._step(rgb, t)

    def _step(self, rgb, t):
        c = self.cfg_
        pub = {k: c[k] == "published" for k in STAGES}
        ds = c["ds"]
        small = reduce2x(rgb) if ds == 2 else rgb
        g = grey(small)
        labels = hsv216(small, "code" if pub["hue_wrap"] else "fixed")
        k = self.n_frames_
        vf, yf = self.speed_filter_, self.yaw_filter_
        ps = self.pixel_scale_
        trk = self.tracks_
        diag = dict(n_features=0, n_tracked=0, n_triplets=0, n_motion_points=0, n_candidates=0, n_inliers=0,
                    static=False, ransac_iterations=0, irls_iterations=0, weighted=False,
                    pose_provisional=False, middle_index=k - 1)
        status = "init"
        speed_raw = yaw_raw = np.nan
        rates_raw = np.full(3, np.nan)
        cand_xy = np.zeros((0, 2))
        cand_dbar = np.zeros(0)
        cand_uv = np.zeros((0, 2))
        cand_prob = np.zeros(0)
        inl_mask = np.zeros(0, dtype=bool)
        dt = t - self.times_[-1] if k > 0 else 0.0
        motion_done = False

        if k > 0 and len(trk["xy"]):
            # Inverse depths refer to frame k-2 (middle of the last triplet); predict them to frame k-1.
            if k >= 2 and trk["has"].any():
                u_prev = self._level(trk["xy"][:, 1])[0]
                h_ = trk["has"] & np.isfinite(u_prev)
                base = trk["dmeas"] if pub["depth_fusion"] else trk["d"]  # B5: the code propagates the raw measurement
                d1, P1 = propagate(base[h_], trk["P"][h_], u_prev[h_], vf.x, yf.x, self.dt_prev_, c["depth_q"])
                trk["d"][h_], trk["P"][h_] = d1, P1
            # KLT with the motion-predicted position as the initial guess (the fix of B6: depth-aware).
            x_prev = trk["xy"][:, 2]
            u, v = self._level(x_prev)
            usable = trk["has"] & (trk["P"] < 1.0 * (_H_REF / c["h"]) ** 2) & np.isfinite(trk["d"])
            dpred = np.where(usable, trk["d"], np.maximum(v, 0.0) / c["h"])
            udot = -(1 + u * u) * yf.x + u * vf.x * dpred
            vdot = -u * v * yf.x + v * vf.x * dpred
            guess = self._image(u + dt * udot, v + dt * vdot)
            guess[~np.isfinite(guess).all(axis=1)] = x_prev[~np.isfinite(guess).all(axis=1)]
            gh, gw = g.shape
            guess[:, 0] = np.clip(guess[:, 0], 0, gw - 1)
            guess[:, 1] = np.clip(guess[:, 1], 0, gh - 1)
            x_new, ok, err = frontend.track(self.prev_grey_, g, x_prev, guess, win=c["win"], levels=c["levels"],
                                            fb_max=c["fb_max"], return_err=True)
            if c["ground_warp"] and vf.x > 0:
                # Ground-stabilised tracking of points below the horizon: keep whichever of the plain and the
                # homography-warped track matches its patch better.
                low = np.flatnonzero(self._below(x_prev))
                if len(low):
                    M = self.Kp_ @ self.R_lc_.T
                    Hg = M @ frontend.ground_homography(np.eye(3), vf.x, yf.x, dt, c["h"]) @ np.linalg.inv(M)
                    qw, okw, errw = frontend.track_ground_warped(self.prev_grey_, g, x_prev[low], Hg, win=c["win"],
                                                                 levels=c["levels"], fb_max=c["fb_max"])
                    better = okw & (~ok[low] | (errw < err[low]))
                    x_new[low[better]] = qw[better]
                    ok[low[better]] = True
            diag["n_tracked"] = int(ok.sum())
            disp = x_new[ok] - x_prev[ok]
            _select(trk, ok)
            trk["xy"] = np.concatenate([trk["xy"][:, 1:], x_new[ok][:, None, :]], axis=1)
            trk["age"] += 1
            tri = np.isfinite(trk["xy"][:, 0, 0])
            if tri.any():
                xy = trk["xy"]
                gate = frontend.straightness_gate(xy[tri, 0], xy[tri, 1], xy[tri, 2], min_flow=2.0 * ps,
                                                  wrap=not pub["track_gates"])
                keep = np.ones(len(xy), dtype=bool)
                keep[np.flatnonzero(tri)[~gate]] = False  # gated tracks lose their state
                _select(trk, keep)
                tri = tri[keep]
            diag["n_triplets"] = int(tri.sum())

            if k >= 2 and diag["n_tracked"] == 0:
                status = "no_features"
            elif k >= 2:
                static = diag["n_tracked"] >= 10 and frontend.is_static(disp, thr1=1.0 * ps, thr2=2.0 * ps,
                                                                       per_axis=pub["track_gates"])
                diag["static"] = bool(static)
                if static:
                    status = "static"
                    vf.reset(0.0, c["speed_q"] if pub["filters"] else c["speed_prior_var"])
                    yf.reset(0.0, c["yaw_q"] if pub["filters"] else c["yaw_prior_var"])
                    trk["has"][:] = False
                    rates_raw = np.zeros(3)
                else:
                    status, motion_done, out = self._motion_and_ground(trk, tri, t, diag, labels)
                    if out is not None:
                        speed_raw, yaw_raw, rates_raw, cand_xy, cand_dbar, inl_mask, cand_uv, cand_prob = out

        if k >= 2 and status == "init":
            # Nothing tracked into this frame (black or textureless image); refined below.
            status = "no_features"
        if k >= 2 and not motion_done and status != "static":
            # Coast on the filters (the fix of B10: no zero yaw-rate measurement).
            vf.predict()
            yf.predict()
            if pub["filters"]:
                yf.update(0.0)  # B10: the published code feeds ω = 0 when motion was not solved
            trk["has"][:] = False
        if not motion_done:
            self.rates_ = np.zeros(3)

        # Pose of this image (one per image; spec §6.1 with the B27 fix).
        if k > 0:
            if k == 2 and not pub["pose_steps"]:
                # The step 0 -> 1 reuses the frame-1 estimate, available only now.
                self.poses_[1] = self._step_pose(np.eye(4), self.times_[1] - self.times_[0])
            self.poses_.append(self._step_pose(self.poses_[-1], dt))
            diag["pose_provisional"] = (k == 1 and not pub["pose_steps"])

        # Classifier map of this image (used to weight RANSAC at the next image).
        prob = self.classifier_.predict(labels)
        if pub["ground_labels"]:
            # The published map is not computed at the borders (1 px top/left, 2 px bottom/right).
            prob[:1, :] = prob[:, :1] = 0.5
            prob[-2:, :] = prob[:, -2:] = 0.5
        self.prev_prob_ = prob
        if c["calibration"] == "platt":
            score = self.classifier_.log_odds_table()[labels]
            if c["calib_window"] > 1:
                score = cv2.blur(score, (c["calib_window"], c["calib_window"]), borderType=cv2.BORDER_REPLICATE)
            self.prev_score_ = score
            prob = self.calibrator_.transform(score)

        # Replenish features in free cells.
        existing = trk["xy"][:, 2] if len(trk["xy"]) else np.zeros((0, 2))
        new = frontend.detect_new(g, existing, max_new=c["max_features"] - len(existing), cell=self.cell_)
        if len(new):
            _append(trk, new, c["depth_p_new"] if pub["depth_fusion"] else c["depth_p_reset"])
        diag["n_features"] = int(len(trk["xy"]))
        if status == "no_features" and len(new) > 0:
            status = "few_triplets"  # nothing was tracked in, but this image has features to track on
        diag["status"] = status
        if status != "ok":
            logger.debug("frame %d (t=%.3f s): %s", k, t, status)

        self.prev_grey_ = g
        self.prev_labels_ = labels
        self.dt_prev_ = dt
        self.times_.append(t)
        self.n_frames_ = k + 1

        H, W = self.image_shape_
        if ds == 2:
            prob_out = cv2.resize(prob, (W, H), interpolation=cv2.INTER_LINEAR)
        else:
            prob_out = prob.copy()
        return GroundEstimate(t=t, index=k, speed=vf.x, yaw_rate=yf.x, speed_raw=float(speed_raw),
                              yaw_rate_raw=float(yaw_raw), rates_raw=rates_raw, pose=self.poses_[-1].copy(),
                              ground_prob=prob_out, candidates=cand_xy * ds, candidate_dbar=cand_dbar,
                              candidate_uv=cand_uv, candidate_prob=cand_prob,
                              inlier_mask=inl_mask, status=status, diagnostics=diag)

    def _motion_and_ground(self, trk, tri, t, diag, labels):
        """Steps 8–10 of spec §1 on the triplets; returns (status, filters_done, outputs or None)."""
        c = self.cfg_
        fusion_pub, labels_pub = c["depth_fusion"] == "published", c["ground_labels"] == "published"
        vf, yf = self.speed_filter_, self.yaw_filter_
        ps = self.pixel_scale_
        idx = np.flatnonzero(tri)
        xy = trk["xy"][idx]
        x0, x1, x2 = xy[:, 0], xy[:, 1], xy[:, 2]
        span = t - self.times_[-2]  # t_k - t_{k-2}
        u, v = self._level(x1)
        # Points near the principal axes of the (level) image carry no depth in one component (spec §3.1).
        sel = (np.abs(u * self.fx_) > 3.0 * ps) & (np.abs(v * self.fy_) > 3.0 * ps)
        diag["n_motion_points"] = int(sel.sum())
        if len(idx) < c["min_triplets"] or sel.sum() < 10:
            return "few_triplets", False, None
        idx, x0, x1, x2, u, v = idx[sel], x0[sel], x1[sel], x2[sel], u[sel], v[sel]
        u0, v0 = self._level(x0)
        u2, v2 = self._level(x2)
        udot = (u2 - u0) / span
        vdot = (v2 - v0) / span
        halves = (self.times_[-1] - self.times_[-2], t - self.times_[-1])
        m = estimate_motion(u, v, udot, vdot, n_global=c["n_global"], ridge=c["ridge"], irls_iter=c["irls_iter"],
                            estimate_foe=c["foe"], span=halves if c["exact_flow"] else None,
                            compat="fixed")
        diag["irls_iterations"] = int(m.iterations)
        rates_raw = m.rates.copy()
        yaw_raw = float(m.rates[1])

        # Ground candidates: valid d̄ strictly below the horizon row (spec §4.1).
        below = self._below(x1)
        trk["gnd"][idx[~below]] -= 1
        cand = m.valid & below
        ci = np.flatnonzero(cand)
        diag["n_candidates"] = int(len(ci))
        weights = None
        prob_c = np.full(len(ci), np.nan)
        if self.classifier_.n_updates > 0 and len(ci):
            pr = self.prev_prob_
            r = np.clip(np.rint(x1[ci, 1]).astype(np.intp), 0, pr.shape[0] - 1)
            q = np.clip(np.rint(x1[ci, 0]).astype(np.intp), 0, pr.shape[1] - 1)
            prob_c = pr[r, q].astype(np.float64)
            if c["sampling"] == "weighted":
                weights = prob_c ** c["p"]
                diag["weighted"] = True
        fit = fit_ground(u[ci], v[ci], m.dbar[ci], c["h"], model=c["model"], weights=weights, n_iter=c["n_iter"],
                         rng=self.rng_, lam=c["lam"], sigma=c["sigma"],
                         compat="code" if c["ransac_draw"] == "published" else "fixed")
        diag["ransac_iterations"] = int(fit.iterations)
        n_inl = int(fit.inliers.sum())
        diag["n_inliers"] = n_inl
        speed_raw = fit.speed if fit.ok else np.nan

        vf.predict()
        yf.predict()
        if fit.ok and n_inl >= c["min_inliers"]:
            vf.update(fit.speed)
            yf.update(yaw_raw)
            self.rates_ = np.array([rates_raw[0], yf.x, rates_raw[2]])
            # Metric inverse depths of every valid triplet, fused with their predictions (spec §3.4).
            vi = np.flatnonzero(m.valid)
            V = fit.speed if fusion_pub else vf.x  # B5: the code divides by the raw RANSAC V
            if V > 0:
                ti = idx[vi]
                d_m = m.dbar[vi] / V
                if fusion_pub:
                    usable = trk["P"][ti] < c["depth_usable"]
                    prior = np.where(trk["has"][ti], trk["d"][ti], 0.0)  # B5: new tracks fuse against 0
                else:
                    usable = trk["has"][ti] & (trk["P"][ti] < c["depth_usable"])
                    prior = trk["d"][ti]
                d_f, P_f = fuse(prior, trk["P"][ti], d_m, usable, c["depth_r"], c["depth_p_reset"])
                trk["dmeas"][ti] = d_m
                trk["d"][ti] = d_f
                trk["P"][ti] = P_f
                trk["has"][ti] = True
            # Ground counters and the self-supervised classifier update (spec §4.8, §5.3).
            inl_tracks = idx[ci[fit.inliers]]
            trk["gnd"][inl_tracks] += 1
            g_xy = x1[ci[fit.inliers]]
            if c["train_depth"] is not None:
                # Far inliers are no evidence of ground: within the RANSAC noise a point at the horizon fits
                # the ground model whatever it is (sky edges, far obstacles). Learn ground only nearer than
                # train_depth (metres, flat-ground depth h / v of the level frame).
                g_xy = g_xy[v[ci[fit.inliers]] * c["train_depth"] > c["h"]]
            if labels_pub:
                ng = (trk["gnd"] < 0) & trk["has"]
                ng_xy = trk["xy"][ng, 1]
                lab = labels  # B8: frame-k labels sampled at frame-(k-1) positions
            else:
                ng_sel = m.valid & ~below
                if c["ng_outliers"]:
                    clear = np.zeros(len(u), dtype=bool)
                    clear[ci] = fit.residuals > c["ng_outlier_sigma"] * fit.sigma
                    if c["ng_outlier_history"]:
                        clear[ci] &= trk["gnd"][idx[ci]] <= 0
                    ng_sel |= clear
                ng_xy = x1[ng_sel]
                lab = self.prev_labels_
            if c["calibration"] == "platt" and self.prev_score_ is not None:
                # Out-of-sample self-labels: the map of image k-1 was made before learning from them.
                sh = self.prev_score_.shape
                gi, ni = window_index(sh, g_xy, 1), window_index(sh, ng_xy, 1)
                sc = self.prev_score_.ravel()
                self.calibrator_.update(np.r_[sc[gi], sc[ni]], np.r_[np.ones(len(gi), bool), np.zeros(len(ni), bool)])
            self.classifier_.update(lab, g_xy, ng_xy)
            status = "ok"
        else:
            yf.update(yaw_raw)
            self.rates_ = np.array([rates_raw[0], yf.x, rates_raw[2]])
            status = "no_ground"
        out = (speed_raw, yaw_raw, rates_raw, x1[ci], m.dbar[ci], fit.inliers.copy(),
               np.stack([u[ci], v[ci]], axis=1), prob_c)
        return status, True, out

    def _level(self, xy):
        """Normalised coordinates (u, v) in the level frame of processed-image pixels (n, 2)."""
        r = np.stack([(xy[:, 0] - self.cx_) / self.fx_, (xy[:, 1] - self.cy_) / self.fy_, np.ones(len(xy))], axis=1)
        if self.cfg_["pitch"] != 0.0:
            r = r @ self.R_lc_.T
            with np.errstate(divide="ignore", invalid="ignore"):
                return r[:, 0] / r[:, 2], r[:, 1] / r[:, 2]
        return r[:, 0], r[:, 1]

    def _image(self, u, v):
        """Processed-image pixels (n, 2) of level-frame normalised coordinates."""
        r = np.stack([u, v, np.ones(len(u))], axis=1)
        if self.cfg_["pitch"] != 0.0:
            r = r @ self.R_lc_
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.stack([self.fx_ * r[:, 0] / r[:, 2] + self.cx_, self.fy_ * r[:, 1] / r[:, 2] + self.cy_], axis=1)

    def _below(self, xy):
        """Ground-candidate side of the horizon: below ``horizon_row``, or v > 0 in the level frame."""
        if self.horizon_ is not None:
            return xy[:, 1] > self.horizon_
        return self._level(xy)[1] > 0

    def _step_pose(self, T, dt):
        """Compose one integration step of length dt with the filtered speed and yaw rate."""
        c = self.cfg_
        rates = self.rates_.copy() if c["integration"] == "3d" else np.zeros(3)
        rates[1] = self.yaw_filter_.x
        step = motion_step(self.speed_filter_.x, rates, dt, c["integration"], semi_implicit=c["pose_steps"] == "published")
        return T @ self._to_camera(step)

    def _to_camera(self, step):
        """A motion step of the level frame expressed for the (pitched) camera frame."""
        if self.cfg_["pitch"] == 0.0:
            return step
        M = np.eye(4)
        M[:3, :3] = self.R_lc_
        return np.linalg.inv(M) @ step @ M


def _empty_tracks():
    return dict(xy=np.zeros((0, 3, 2)), d=np.zeros(0), dmeas=np.zeros(0), P=np.zeros(0),
                has=np.zeros(0, dtype=bool), gnd=np.zeros(0, dtype=np.int64), age=np.zeros(0, dtype=np.int64))


def _select(trk, mask):
    for key in trk:
        trk[key] = trk[key][mask]


def _append(trk, xy, p_new):
    n = len(xy)
    hist = np.full((n, 3, 2), np.nan)
    hist[:, 2] = xy
    trk["xy"] = np.concatenate([trk["xy"], hist])
    trk["d"] = np.concatenate([trk["d"], np.zeros(n)])
    trk["dmeas"] = np.concatenate([trk["dmeas"], np.zeros(n)])
    trk["P"] = np.concatenate([trk["P"], np.full(n, p_new)])
    trk["has"] = np.concatenate([trk["has"], np.zeros(n, dtype=bool)])
    trk["gnd"] = np.concatenate([trk["gnd"], np.zeros(n, dtype=np.int64)])
    trk["age"] = np.concatenate([trk["age"], np.zeros(n, dtype=np.int64)])
