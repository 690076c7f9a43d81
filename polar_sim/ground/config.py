"""Stage settings of :class:`polar_sim.ground.GroundVO`: one frozen dataclass per pipeline stage.

Each config checks every field in ``__post_init__`` (type, range, finiteness, and an upper bound on
every size, so nothing is allocated from an absurd value) and raises ``ValueError``/``TypeError``
naming the field. ``GroundVO`` stores them as its parameters ``tracking``, ``motion``, ``ground``,
``filters``, ``classifier``, ``calibration`` and ``dense``; ``get_params(deep=True)`` / ``set_params`` reach a
field as ``stage__field`` (``vo.set_params(tracking__max_features=600)``). The stage switches
``track_gates``, ``depth_fusion``, ``ransac_draw``, ``rules``, ``pose_steps``, ``hue_wrap`` and
``ground_labels`` choose per stage between the spec with its fixes (``"fixed"``) and the published
code's behaviour (``"published"``, spec §10); each config's ``published()`` is its part of
``GroundVO.published()``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from polar_sim._validation import as_bool, as_float, as_int, as_positive_float, check_choice
from polar_sim.ground._checks import as_unit_interval
from polar_sim.ground.models import default_iterations

__all__ = ["TrackingConfig", "MotionConfig", "GroundModelConfig", "FilterConfig", "ClassifierConfig",
           "CalibrationConfig", "DenseConfig", "SWITCH", "MAX_FEATURES", "MAX_RANSAC_ITER"]

#: Values of every stage switch.
SWITCH = ("fixed", "published")
#: Upper bounds of the sizes (tracks kept per frame; RANSAC iterations): beyond them a frame's
#: arrays (tracks x iterations in RANSAC) outgrow memory and time.
MAX_FEATURES = 100_000
MAX_RANSAC_ITER = 100_000


def _optional(value, check, name):
    return None if value is None else check(value, name)


class _Stage:
    """Shared behaviour of the stage configs: ``published()`` and a compact ``replace``."""

    #: Field values of the published code's behaviour in this stage.
    _PUBLISHED: dict = {}

    @classmethod
    def published(cls, **overrides):
        """This stage with the published code's values (spec §10), then ``overrides``."""
        return cls(**{**cls._PUBLISHED, **overrides})

    def replace(self, **changes):
        """A copy with ``changes`` (validated like a new config)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class TrackingConfig(_Stage):
    """Front end (spec §2, KLT instead of the published matcher).

    Parameters
    ----------
    max_features : int, default=400
        Tracked features kept per frame (10 to 100,000).
    klt_window : int, default=11
        Lucas–Kanade window side, processed px (3 to 99).
    klt_levels : int, default=3
        Lucas–Kanade pyramid levels (0 to 8).
    fb_max : float, default=0.5
        Forward–backward consistency limit, processed px.
    ground_warp : bool, default=True
        Also track points below the horizon in the previous image warped by the predicted ground
        homography, keeping the better-matching track (removes most KLT error on near ground).
    track_gates : {"fixed", "published"}, default="fixed"
        "published": the straightness gate without angle wrap (B15) and the per-axis static test (B28).
    """

    max_features: int = 400
    klt_window: int = 11
    klt_levels: int = 3
    fb_max: float = 0.5
    ground_warp: bool = True
    track_gates: str = "fixed"

    _PUBLISHED = dict(track_gates="published")

    def __post_init__(self):
        as_int(self.max_features, "max_features", minimum=10, maximum=MAX_FEATURES)
        as_int(self.klt_window, "klt_window", minimum=3, maximum=99)
        as_int(self.klt_levels, "klt_levels", minimum=0, maximum=8)
        as_positive_float(self.fb_max, "fb_max")
        as_bool(self.ground_warp, "ground_warp")
        check_choice(self.track_gates, SWITCH, "track_gates")


@dataclass(frozen=True)
class MotionConfig(_Stage):
    """Image kinematics and per-track inverse depth (spec §3).

    Parameters
    ----------
    min_triplets : int, default=30
        Three-frame tracks needed to solve the motion (10 to 100,000).
    irls_iter : int, default=10
        L1 IRLS iterations (0 to 1,000; the published IRLS is inert: 0, B1).
    n_global : {3, 1}, default=3
        Global unknowns: (Ωx, Ωy, Ωz) as the code (B4), or the yaw rate only (the text).
    ridge : float, default=1.0
        Ridge on the pitch and roll rates Ωx, Ωz.
    estimate_foe : bool, default=False
        Also estimate the focus of expansion (Gauss–Newton, n_g = 5).
    exact_flow : bool, default=True
        Correct the centred flow for the exact motion between the three frames (not in the spec):
        removes the O((V dt/Z)²) bias of the differential model on near points.
    slip : float, default=0.0
        The camera's sideways velocity per unit forward speed and yaw rate, s (not in the spec): the
        focus of expansion sits at t1 = -slip x ω in the flow model and the dense fit's step turns by
        arctan(-slip x yaw change / dt) (:func:`~polar_sim.ground.motion.estimate_motion`). A constant of
        the robot, like the camera height: 0 is a camera that moves along its optical axis (the spec's
        model); a camera L m ahead of a car's rear axle has -L / V; the simulated rover's tyres creep
        outward in turns (:data:`polar_sim.sim.recorders.rover_sequences.ROVER_SLIP`, 0.01 s, which the
        rover experiments and environment pass).
    depth_q, depth_r, depth_p_reset : float or None, default=None
        Inverse-depth propagation noise, measurement noise and reset variance ((1/m)²); None: the
        spec's 0.02, 0.6, 0.95 scaled by (1.68 / h)².
    depth_fusion : {"fixed", "published"}, default="fixed"
        "published": B5 (the raw measurement propagated, the raw RANSAC V, new tracks fused against 0,
        the new-track variance 2 (1.68/h)²).
    """

    min_triplets: int = 30
    irls_iter: int = 10
    n_global: int = 3
    ridge: float = 1.0
    estimate_foe: bool = False
    exact_flow: bool = True
    slip: float = 0.0
    depth_q: float | None = None
    depth_r: float | None = None
    depth_p_reset: float | None = None
    depth_fusion: str = "fixed"

    _PUBLISHED = dict(irls_iter=0, n_global=3, estimate_foe=False, exact_flow=False, slip=0.0, depth_fusion="published")

    def __post_init__(self):
        as_int(self.min_triplets, "min_triplets", minimum=10, maximum=MAX_FEATURES)
        as_int(self.irls_iter, "irls_iter", minimum=0, maximum=1000)
        check_choice(self.n_global, (1, 3), "n_global")
        as_positive_float(self.ridge, "ridge", allow_zero=True)
        as_bool(self.estimate_foe, "estimate_foe")
        as_bool(self.exact_flow, "exact_flow")
        as_float(self.slip, "slip", minimum=-1.0, maximum=1.0)
        for name in ("depth_q", "depth_r", "depth_p_reset"):
            _optional(getattr(self, name), as_positive_float, name)
        check_choice(self.depth_fusion, SWITCH, "depth_fusion")


@dataclass(frozen=True)
class GroundModelConfig(_Stage):
    """Ground candidates and the (weighted) RANSAC fit of the ground model (spec §4.1–4.6).

    Parameters
    ----------
    n_iter : int or None, default=None
        RANSAC iterations (1 to 100,000); None: the model's default (6param 55, 2param 16,
        plane3/3param 69). The published code runs 99 for 6param (B18).
    lam : float, default=0.1
        Ridge weight of the 6param hypotheses and final fit.
    sigma : float or None, default=None
        Inlier threshold in normalised units; None: 0.002 for 6param, 0.005 otherwise.
    weight_exponent : float, default=1.0
        RANSAC draw weight P_G^p (the text; the code's p = 2, B11).
    min_inliers : int, default=10
        Ground inliers needed to accept a scale and train the classifier (2 to 100,000).
    horizon_row : float or None, default=None
        Input-image row below which points are ground candidates; None: below the horizon of the
        level frame (the principal row for a level camera).
    ransac_draw : {"fixed", "published"}, default="fixed"
        "published": the cumulative draw with redraws and raw P_G weights in the 6param LS.
    var_scale : float, default=10.0
        Factor on the fit's speed variance (from the final least squares on the inliers, which ignores
        the RANSAC selection and the model's own error) before it is fused with the dense speed.
    """

    n_iter: int | None = None
    lam: float = 0.1
    sigma: float | None = None
    weight_exponent: float = 1.0
    min_inliers: int = 10
    horizon_row: float | None = None
    ransac_draw: str = "fixed"
    var_scale: float = 10.0

    _PUBLISHED = dict(weight_exponent=2.0, ransac_draw="published")

    def __post_init__(self):
        _optional(self.n_iter, lambda v, n: as_int(v, n, minimum=1, maximum=MAX_RANSAC_ITER), "n_iter")
        as_positive_float(self.lam, "lam", allow_zero=True)
        _optional(self.sigma, as_positive_float, "sigma")
        as_positive_float(self.weight_exponent, "weight_exponent", allow_zero=True)
        as_int(self.min_inliers, "min_inliers", minimum=2, maximum=MAX_FEATURES)
        _optional(self.horizon_row, lambda v, n: as_positive_float(v, n, allow_zero=True), "horizon_row")
        check_choice(self.ransac_draw, SWITCH, "ransac_draw")
        as_positive_float(self.var_scale, "var_scale")

    @classmethod
    def published(cls, model="6param", **overrides):
        """The published RANSAC for ``model``: its iteration count (99 for 6param, B18), P_G² draws."""
        overrides.setdefault("n_iter", default_iterations(model, "code"))
        return super().published(**overrides)

    def iterations(self, model):
        """RANSAC iterations for ``model``: ``n_iter``, or the model's default."""
        return default_iterations(model) if self.n_iter is None else self.n_iter


@dataclass(frozen=True)
class FilterConfig(_Stage):
    """The speed and yaw-rate filters (spec §4.7) and the pose steps they integrate (§6.1).

    Parameters
    ----------
    speed_prior, speed_prior_var : float, default=0.0, 25.0
        Prior of the speed filter, m/s and (m/s)² (never ground truth, B21).
    speed_q, speed_r : float, default=0.15, 3.0
        Speed filter process and nominal measurement noise, (m/s)² (rescale with V_typ², §9.3).
    yaw_prior, yaw_prior_var, yaw_q, yaw_r : float, default=0.0, 4.0, 2.0, 5.0
        Yaw-rate filter prior, prior variance, process and measurement noise (rad/s, (rad/s)²).
    rules : {"fixed", "published"}, default="fixed"
        "published": the code's adaptive speed noise, resets of the filters to their process noise
        when static, and a zero yaw measurement when the motion was not solved (B10).
    pose_steps : {"fixed", "published"}, default="fixed"
        "published": semi-implicit integration and no revision of the first step (B27).
    """

    speed_prior: float = 0.0
    speed_prior_var: float = 25.0
    speed_q: float = 0.15
    speed_r: float = 3.0
    yaw_prior: float = 0.0
    yaw_prior_var: float = 4.0
    yaw_q: float = 2.0
    yaw_r: float = 5.0
    rules: str = "fixed"
    pose_steps: str = "fixed"

    _PUBLISHED = dict(rules="published", pose_steps="published")

    def __post_init__(self):
        for name in ("speed_prior", "yaw_prior"):
            as_float(getattr(self, name), name)
        for name in ("speed_prior_var", "speed_q", "speed_r", "yaw_prior_var", "yaw_q", "yaw_r"):
            as_positive_float(getattr(self, name), name)
        check_choice(self.rules, SWITCH, "rules")
        check_choice(self.pose_steps, SWITCH, "pose_steps")

    @classmethod
    def published(cls, **overrides):
        """The published filters; the speed filter starts at twice its process noise (P0 = 2 q)."""
        overrides.setdefault("speed_prior_var", 2 * overrides.get("speed_q", cls.speed_q))
        return super().published(**overrides)


@dataclass(frozen=True)
class ClassifierConfig(_Stage):
    """The self-supervised colour classifier (spec §5) and its training labels.

    Parameters
    ----------
    alpha : float, default=0.7
        Colour histogram decay (0 to 1).
    ground_prior : float, default=0.2
        Class prior P(ground), in (0, 1).
    ng_from_outliers : bool, default=True
        Train non-ground also on lower-half points that are clear RANSAC outliers (the code: no, B9).
    ng_outlier_sigma : float, default=3.0
        How clear an outlier must be, in multiples of the RANSAC inlier threshold.
    ng_outlier_history : bool, default=False
        Only tracks never counted as ground inliers become non-ground outliers (with
        ``ng_outlier_sigma=6``: the method ``w6_ng6h``, better on weakly textured ground; not the
        default, see ``benchmarks/RESULTS.md``).
    sky_labels : int, default=100
        Non-ground self-labels per image spread over the image more than ``sky_margin`` above the
        level horizon (and above ``GroundModelConfig.horizon_row``, if given), where no level ground
        can be (0: none; only tracks there label it).
    sky_margin : float, default=0.1
        How far above the level horizon the sky labels start, rad (hills and the chassis' pitch
        lift the ground above it).
    train_depth : float or None, default=30.0
        Ground inliers farther than this (m, flat-ground depth) do not train the ground colour; None:
        no limit (the spec).
    decay_samples : float or None, default=450.0
        Evidence-weighted histogram decay (window pixels): an update with fewer samples forgets less;
        None: the spec's decay by alpha per update.
    hue_wrap : {"fixed", "published"}, default="fixed"
        "published": negative hues wrap by +5/6 (B7).
    ground_labels : {"fixed", "published"}, default="fixed"
        "published": B8 (non-ground = tracks with a negative ground count, frame-k labels), a ground
        pseudo-count 0.5 and a map border of 0.5 (B12).
    """

    alpha: float = 0.7
    ground_prior: float = 0.2
    ng_from_outliers: bool = True
    ng_outlier_sigma: float = 3.0
    ng_outlier_history: bool = False
    sky_labels: int = 100
    sky_margin: float = 0.1
    train_depth: float | None = 30.0
    decay_samples: float | None = 450.0
    hue_wrap: str = "fixed"
    ground_labels: str = "fixed"

    _PUBLISHED = dict(ng_from_outliers=False, sky_labels=0, train_depth=None, decay_samples=None,
                      hue_wrap="published", ground_labels="published")

    def __post_init__(self):
        as_unit_interval(self.alpha, "alpha")
        as_unit_interval(self.ground_prior, "ground_prior", open_low=True, open_high=True)
        as_bool(self.ng_from_outliers, "ng_from_outliers")
        as_positive_float(self.ng_outlier_sigma, "ng_outlier_sigma")
        as_bool(self.ng_outlier_history, "ng_outlier_history")
        as_int(self.sky_labels, "sky_labels", minimum=0, maximum=MAX_FEATURES)
        as_positive_float(self.sky_margin, "sky_margin", allow_zero=True)
        _optional(self.train_depth, as_positive_float, "train_depth")
        _optional(self.decay_samples, as_positive_float, "decay_samples")
        check_choice(self.hue_wrap, SWITCH, "hue_wrap")
        check_choice(self.ground_labels, SWITCH, "ground_labels")


@dataclass(frozen=True)
class CalibrationConfig(_Stage):
    """Online calibration of the output ``ground_prob`` (:mod:`polar_sim.ground.calibration`).

    Parameters
    ----------
    method : {"platt", "none"}, default="platt"
        "platt": the log-odds of the posterior, averaged over ``window`` px, mapped by σ(a z + b)
        learned online from the module's own labels; "none": the Naive Bayes posterior.
    window : int, default=7
        Odd side (processed px, 1 to 99) of the window the log-odds are averaged over.
    decay : float, default=0.99
        Per-update decay of old self-labels (0 to 1).
    prior_weight : float, default=5.0
        Weight (samples) of the prior toward the identity map. Decay and weight were chosen on dev
        routes only (``benchmarks/bench_ground_calibration.py``).
    """

    method: str = "platt"
    window: int = 7
    decay: float = 0.99
    prior_weight: float = 5.0

    _PUBLISHED = dict(method="none")

    def __post_init__(self):
        check_choice(self.method, ("platt", "none"), "method")
        as_int(self.window, "window", minimum=1, maximum=99)
        if self.window % 2 == 0:
            raise ValueError(f"window: expected an odd window side, got {self.window!r}")
        as_unit_interval(self.decay, "decay")
        as_positive_float(self.prior_weight, "prior_weight", allow_zero=True)


@dataclass(frozen=True)
class DenseConfig(_Stage):
    """Dense, direct alignment of the ground between consecutive images (:mod:`polar_sim.ground.dense`),
    fused with the sparse (RANSAC) speed by their uncertainties, and its self-labels of ground pixels.
    Not in the published method (``published()``: off).

    Parameters
    ----------
    enabled : bool, default=True
        Run the dense alignment.
    model : {"side_slope", "pitch", "plane", "pitch_roll", "surface"}, default="side_slope"
        Motion fitted (:data:`polar_sim.ground.dense.WARP_MODELS`): the unicycle step (arc length, yaw
        change), the chassis' pitch change between the images (hills) and the ground's slope across the
        image (a chassis leaning in a turn, or a cambered road: a level ground takes the lean for yaw);
        "pitch" without the side slope, "plane" without the pitch change either, "pitch_roll" with the
        roll change instead of the side slope; "surface" also the ground's slope and curvature ahead.
    max_depth : float, default=15.0
        Ground pixels up to this flat-ground depth (m) are aligned: the near ground, where the plane
        holds best and the parallax is largest.
    levels : int, default=2
        Pyramid levels, coarse to fine (1 to 4).
    smoothing : float, default=1.0
        Gaussian smoothing of the images before alignment, px (0 to 10).
    block, max_pixels, min_gradient : int, int, float, default=2, 1500, 0.05
        Template pixels: the strongest gradient of every ``block`` x ``block`` cell of the ground region
        above ``min_gradient`` (grey levels per px), at most ``max_pixels`` (10 to 100,000).
    min_pixels : int, default=200
        Pixels a fit needs.
    max_iter : int, default=10
        Gauss–Newton iterations per level (1 to 100).
    residual_floor : float, default=0.3
        Lower bound of the residuals' robust scale, grey levels.
    gradient_weight : float, default=0.0
        c of the per-pixel weight c² / (c² + |∇I|²), grey levels per px: strong edges, the most
        sensitive to unmodelled appearance change, count less (0: all alike).
    prob_floor : float, default=0.25
        A template pixel's weight is prob_floor + (1 − prob_floor) P(ground) (the previous image's map).
    var_scale : float, default=2.0
        Factor on the fit's variance before fusion (its Hessian ignores that neighbouring pixels'
        errors are correlated).
    spread_scale : float, default=4.0
        The plane model's error: the speed variance gains (spread_scale x the fit's band spread)², the
        disagreement of the nearer and farther halves of the ground (a slope or crest ahead).
    alias_sigmas, alias_margin, alias_var_scale : float, default=3.0, 0.2, 100.0
        Aliasing guard: another minimum of the cost along the path, within ``alias_sigmas`` standard
        deviations of the predicted arc length (the speed filter's), whose cost is within
        ``alias_margin`` (relative) of the solution's, multiplies the fit's variance by
        ``alias_var_scale``; 0 turns the test off.
    gate : float, default=3.0
        Sparse and dense speeds (and yaw rates) that differ by more than ``gate`` standard deviations are
        not averaged: the one with the smaller variance is used alone.
    fuse_yaw : bool, default=True
        The yaw-rate measurement is the tracks' yaw rate fused with the dense fit's by their variances
        (both scaled by ``var_scale``); the tracks' variance grows by 1 + ``alias_var_scale`` x the share of
        tracks caught aliasing. False: the tracks' yaw rate alone.

    label_evidence : float, default=4.0
        Ground self-labels: pixels whose parallax fits the ground better than points at infinity by this
        much (windowed mean difference of squared residuals, grey levels²); 0 = no dense labels.
    label_region : {"support", "evidence"}, default="support"
        Where the dense ground labels are spread: over the ground the evidence is connected to through
        untextured pixels the fitted motion agrees with (:func:`polar_sim.ground.dense.ground_evidence`),
        or over the evidence alone (the textured parts of the ground).
    max_labels : int, default=300
        Dense ground labels per image (spread evenly over the label region).
    track_alias_px : float, default=1.5
        Aliasing in tracks: a point tracked both plainly and in the ground-warped image, to two positions
        farther apart than this (processed px, at the KITTI focal length), is dropped.
    periodic_ncc : float, default=0.7
        Aliasing in tracks: a new corner whose patch, compared with the patches 1 to 8 px away (at the
        KITTI focal length) along a direction, correlates less and then again above this (NCC), a
        period away, lies on a repeating texture and does not enter the motion solve
        (:func:`polar_sim.ground.frontend.periodic`); 1 turns the test off.
    """

    enabled: bool = True
    model: str = "side_slope"
    max_depth: float = 15.0
    levels: int = 2
    smoothing: float = 1.0
    block: int = 2
    max_pixels: int = 1500
    min_gradient: float = 0.05
    min_pixels: int = 200
    max_iter: int = 10
    residual_floor: float = 0.3
    gradient_weight: float = 0.0
    prob_floor: float = 0.25
    var_scale: float = 2.0
    spread_scale: float = 4.0
    alias_sigmas: float = 3.0
    alias_margin: float = 0.2
    alias_var_scale: float = 100.0
    gate: float = 3.0
    fuse_yaw: bool = True
    label_evidence: float = 4.0
    label_region: str = "support"
    max_labels: int = 300
    track_alias_px: float = 1.5
    periodic_ncc: float = 0.7

    _PUBLISHED = dict(enabled=False)

    def __post_init__(self):
        as_bool(self.enabled, "enabled")
        check_choice(self.model, ("pitch", "plane", "pitch_roll", "side_slope", "surface"), "model")
        as_positive_float(self.max_depth, "max_depth")
        as_int(self.levels, "levels", minimum=1, maximum=4)
        as_float(self.smoothing, "smoothing", minimum=0.0, maximum=10.0)
        as_int(self.block, "block", minimum=1, maximum=16)
        as_int(self.max_pixels, "max_pixels", minimum=10, maximum=MAX_FEATURES)
        as_positive_float(self.min_gradient, "min_gradient", allow_zero=True)
        as_int(self.min_pixels, "min_pixels", minimum=3, maximum=MAX_FEATURES)
        as_int(self.max_iter, "max_iter", minimum=1, maximum=100)
        as_positive_float(self.residual_floor, "residual_floor")
        as_positive_float(self.gradient_weight, "gradient_weight", allow_zero=True)
        as_unit_interval(self.prob_floor, "prob_floor")
        as_positive_float(self.var_scale, "var_scale")
        as_positive_float(self.spread_scale, "spread_scale", allow_zero=True)
        as_positive_float(self.alias_sigmas, "alias_sigmas", allow_zero=True)
        as_positive_float(self.alias_margin, "alias_margin", allow_zero=True)
        as_float(self.alias_var_scale, "alias_var_scale", minimum=1.0)
        as_positive_float(self.gate, "gate")
        as_bool(self.fuse_yaw, "fuse_yaw")
        as_positive_float(self.label_evidence, "label_evidence", allow_zero=True)
        check_choice(self.label_region, ("support", "evidence"), "label_region")
        as_int(self.max_labels, "max_labels", minimum=0, maximum=MAX_FEATURES)
        as_positive_float(self.track_alias_px, "track_alias_px")
        as_float(self.periodic_ncc, "periodic_ncc", minimum=-1.0, maximum=1.0)
