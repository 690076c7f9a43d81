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

from polar_sim._validation import as_image, as_intrinsics, as_positive_float, as_rng, check_choice
from polar_sim.ground import frontend, tracks
from polar_sim.ground._checks import as_time
from polar_sim.ground.calibration import PlattCalibrator
from polar_sim.ground.camera import LevelCamera
from polar_sim.ground.classifier import GroundColourModel, window_index
from polar_sim.ground.config import (CalibrationConfig, ClassifierConfig, DenseConfig, FilterConfig,
                                     GroundModelConfig, MotionConfig, TrackingConfig)
from polar_sim.ground.dense import Pyramid, align_ground, fuse_measurements, ground_evidence, label_points
from polar_sim.ground.depth import fuse, propagate
from polar_sim.ground.estimate import STATUSES, GroundEstimate
from polar_sim.ground.filters import KF1D
from polar_sim.ground.image import grey, hsv216, reduce2x
from polar_sim.ground.integration import motion_step
from polar_sim.ground.models import GROUND_MODELS, fit_ground
from polar_sim.ground.motion import estimate_motion
from polar_sim.params import Parameterised, Tags, check_fields, replace_fields, split_nested

__all__ = ["GroundVO", "GroundEstimate", "STATUSES", "STAGE_CONFIGS"]

logger = logging.getLogger(__name__)

#: GroundVO's stage-config parameters and their classes (``polar_sim.ground.config``).
STAGE_CONFIGS = {"tracking": TrackingConfig, "motion": MotionConfig, "ground": GroundModelConfig,
                 "filters": FilterConfig, "classifier": ClassifierConfig, "calibration": CalibrationConfig,
                 "dense": DenseConfig}

_MODEL_ALIASES = {"2p": "2param", "3p": "3param", "6p": "6param", "3p_code": "3param"}
_F_REF = 359.428  # focal length (px) of the processed KITTI images the pixel thresholds were tuned on
_H_REF = 1.68  # camera height (m) the inverse-depth variances were tuned on
_H_RANGE = (1e-3, 1e4)  # camera heights (m) accepted
_MAX_RANSAC_CELLS = 10**8  # RANSAC iterations x tracks: the residual matrix of one frame


def _published_stage(config, name, model, fields):
    """``config.published(**fields)`` (the dependent values follow ``fields``), errors named ``name__field``."""
    check_fields(config, name, fields)
    try:
        if name == "ground":
            return config.published(model if model in GROUND_MODELS else "6param", **fields)
        return config.published(**fields)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"{name}__{exc}") from None


@dataclass
class _Frame:
    """What the steps of one image produce: the per-frame fields of its :class:`GroundEstimate`."""

    diag: dict
    status: str = "init"
    motion_done: bool = False
    speed_raw: float = np.nan
    yaw_raw: float = np.nan
    yaw_measured: float = np.nan
    speed_dense: float = np.nan
    speed_measured: float = np.nan
    rates_raw: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    cand_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    cand_dbar: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cand_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    cand_prob: np.ndarray = field(default_factory=lambda: np.zeros(0))
    inl_mask: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))


@dataclass(frozen=True)
class _DenseSpeed:
    """The dense fit's speed (m/s) and yaw rate (rad/s) at the middle frame, their variances, and
    whether an aliased fit went into them."""

    speed: float
    speed_var: float
    yaw_rate: float
    yaw_var: float
    aliased: bool


@dataclass(frozen=True)
class _Settings:
    """The parameters of a sequence, checked and resolved at its first image (``GroundVO.cfg_``)."""

    K: np.ndarray
    h: float
    model: str
    sampling: str
    ds: int
    integration: str
    pitch: float
    tracking: TrackingConfig
    motion: MotionConfig
    ground: GroundModelConfig
    filters: FilterConfig
    classifier: ClassifierConfig
    calibration: CalibrationConfig
    dense: DenseConfig
    n_iter: int  # RANSAC iterations of the model
    p: float  # RANSAC weight exponent
    depth_q: float
    depth_r: float
    depth_p_reset: float
    depth_p_new: float  # variance of a new track under depth_fusion="published"
    depth_usable: float  # prior variance below which a track's inverse depth is fused

    def published(self, switch):
        """Whether the stage switch named ``switch`` (a config field) is "published"."""
        for cfg in (self.tracking, self.motion, self.ground, self.filters, self.classifier):
            if hasattr(cfg, switch):
                return getattr(cfg, switch) == "published"
        raise KeyError(switch)


class GroundVO(Parameterised):
    """Online self-supervised ground segmentation and monocular VO for a ground vehicle.

    The module contract (:class:`polar_sim.params.Parameterised`): the constructor stores its
    parameters; ``get_params(deep=True)`` lists them with every stage config's fields as
    ``stage__field``, which ``set_params`` also takes; learned state lives in ``_``-suffixed
    attributes created by the first :meth:`process`; :meth:`reset`. The published code's behaviour is
    the preset :meth:`published`.

    Parameters
    ----------
    K : array_like of shape (3, 3)
        Pinhole intrinsics of the input images (px), square pixels assumed, no distortion.
    camera_height : float
        Height h of the optical centre above the ground, along camera +y, m (1 mm to 10 km).
    model : {"6param", "2param", "plane3", "3param"}, default="6param"
        Ground model (spec §4.2): second-order surface (ridge-regularised), level ground
        d̄ = a + (V/h) v, general plane, or the published code's 3-parameter model (B13).
    sampling : {"weighted", "uniform"}, default="weighted"
        RANSAC draws in proportion to the learned ground probability, or uniformly.
    seed : int, numpy.random.Generator or None, default=0
        RANSAC randomness. An int (or a Generator) makes every output bit-identical across runs and
        processes; None draws fresh OS entropy, so two runs differ.
    downsample : {2, 1}, default=2
        One 2x pyramid reduction before processing (spec §2.1), or none (e.g. for 621x188 routes).
    integration : {"planar", "3d"}, default="planar"
        Planar unicycle integration, or 3-D with the measured pitch/roll rates (non-flat terrain).
    camera_pitch : float, default=0.0
        Known downward pitch of the camera relative to the vehicle (rad, > 0 looks down, |θ| < π/2).
        Feature rays are de-rotated into the level frame (spec §9.2); poses stay camera poses.
    tracking : TrackingConfig
        Front end: features, KLT, ground-warped tracking, gates.
    motion : MotionConfig
        Image kinematics (IRLS, global unknowns, exact centred flow) and per-track inverse depth.
    ground : GroundModelConfig
        Ground candidates and RANSAC (iterations, ridge, threshold, weight exponent, minimum inliers).
    filters : FilterConfig
        Speed and yaw-rate filters, and the pose steps they integrate.
    classifier : ClassifierConfig
        The colour classifier and its self-supervised training labels.
    calibration : CalibrationConfig
        Calibration of the output ``ground_prob``.
    dense : DenseConfig
        Dense alignment of the ground between images, its fusion with the RANSAC speed, its ground
        self-labels and the aliasing guards (not in the published method).
    """

    TAGS = Tags(update="process", query="trajectory", requires_update=False, random_state="seed", data="polar_sim.ground.synthetic:check_data")

    def __init__(self, K, camera_height, *, model="6param", sampling="weighted", seed=0, downsample=2,
                 integration="planar", camera_pitch=0.0, tracking=TrackingConfig(), motion=MotionConfig(),
                 ground=GroundModelConfig(), filters=FilterConfig(), classifier=ClassifierConfig(),
                 calibration=CalibrationConfig(), dense=DenseConfig()):
        self.K = K
        self.camera_height = camera_height
        self.model = model
        self.sampling = sampling
        self.seed = seed
        self.downsample = downsample
        self.integration = integration
        self.camera_pitch = camera_pitch
        self.tracking = tracking
        self.motion = motion
        self.ground = ground
        self.filters = filters
        self.classifier = classifier
        self.calibration = calibration
        self.dense = dense
        self._settings()  # fail early; _build checks again (set_params may change them)

    # ------------------------------------------------------------------------------------------------
    # configuration and state

    @classmethod
    def published(cls, K, camera_height, **overrides):
        """A GroundVO with the published code's behaviour (spec §10): every stage config's
        ``published()``, with the RANSAC iterations of the chosen model (99 for 6param, B18) and the
        speed filter's initial variance 2 q. ``overrides`` are parameters (``model="2param"``, a whole
        stage config) or stage fields (``filters__speed_q=0.5``); the dependent values follow them."""
        flat, nested = split_nested(overrides)
        unknown = sorted(set(flat) - set(cls._param_names())) + sorted(f"{s}__{f}" for s, fs in nested.items()
                                                                  if s not in STAGE_CONFIGS for f in fs)
        if unknown:
            raise ValueError(f"{unknown[0]}: unknown parameter of {cls.__name__}; valid: "
                             f"{', '.join(cls._param_names())}")
        model = flat.get("model", "6param")
        model = _MODEL_ALIASES.get(model, model) if isinstance(model, str) else model
        for name, config in STAGE_CONFIGS.items():
            fields = nested.get(name, {})
            if name in flat:  # a whole config given: the stage fields apply on top of it
                flat[name] = replace_fields(flat[name], name, fields) if fields else flat[name]
            else:
                flat[name] = _published_stage(config, name, model, fields)
        return cls(K, camera_height, **flat)

    def _check_params(self):
        return self._settings()

    def _settings(self):
        """The checked, resolved :class:`_Settings`; raises ValueError/TypeError naming a bad parameter."""
        K = as_intrinsics(self.K, "K")
        h = as_positive_float(self.camera_height, "camera_height")
        if not _H_RANGE[0] <= h <= _H_RANGE[1]:
            # The noise defaults scale with (1.68 / h)^2: outside this range they over- or underflow.
            raise ValueError(f"camera_height: expected {_H_RANGE[0]:g} to {_H_RANGE[1]:g} m, got {self.camera_height!r}")
        if not isinstance(self.model, str):
            raise TypeError(f"model: expected one of {', '.join(GROUND_MODELS)}, got {type(self.model).__name__}")
        model = check_choice(_MODEL_ALIASES.get(self.model, self.model), GROUND_MODELS, "model")
        check_choice(self.sampling, ("weighted", "uniform"), "sampling")
        as_rng(self.seed, "seed")  # type check only; the generator is made in _build
        check_choice(self.downsample, (1, 2), "downsample")
        check_choice(self.integration, ("planar", "3d"), "integration")
        pitch = self.camera_pitch
        if isinstance(pitch, bool) or not isinstance(pitch, (int, float, np.floating, np.integer)) \
                or not np.isfinite(pitch) or abs(pitch) >= np.pi / 2:
            raise ValueError(f"camera_pitch: expected a finite angle in (-pi/2, pi/2) rad, got {pitch!r}")
        for name, cls in STAGE_CONFIGS.items():
            if not isinstance(getattr(self, name), cls):
                raise TypeError(f"{name}: expected a {cls.__name__}, got {type(getattr(self, name)).__name__}")
        n_iter = self.ground.iterations(model)
        if n_iter * self.tracking.max_features > _MAX_RANSAC_CELLS:
            raise ValueError(f"ground__n_iter: {n_iter} RANSAC iterations x tracking__max_features "
                             f"{self.tracking.max_features} exceed {_MAX_RANSAC_CELLS:.0e} residuals per frame")
        m, hs = self.motion, (_H_REF / h) ** 2
        return _Settings(
            K=K, h=h, model=model, sampling=self.sampling, ds=self.downsample, integration=self.integration,
            pitch=float(pitch), tracking=self.tracking, motion=m, ground=self.ground, filters=self.filters,
            classifier=self.classifier, calibration=self.calibration, dense=self.dense, n_iter=n_iter,
            p=float(self.ground.weight_exponent),
            depth_q=0.02 * hs if m.depth_q is None else float(m.depth_q),
            depth_r=0.6 * hs if m.depth_r is None else float(m.depth_r),
            depth_p_reset=0.95 * hs if m.depth_p_reset is None else float(m.depth_p_reset),
            depth_p_new=2.0 * hs, depth_usable=5.0 * hs)

    def _build(self, shape):
        c = self.cfg_ = self._settings()
        self.image_shape_ = tuple(shape[:2])
        self.camera_ = LevelCamera(c.K, c.ds, c.pitch, c.ground.horizon_row)
        # Pixel thresholds of the spec were tuned on 621-px KITTI images (f = 359.4 px); flow scales with f.
        self.pixel_scale_ = self.camera_.fx / _F_REF
        hp, wp = (shape[0] + c.ds - 1) // c.ds, (shape[1] + c.ds - 1) // c.ds
        self.cell_ = int(max(6, round(np.sqrt(hp * wp / c.tracking.max_features))))
        f = c.filters
        self.speed_filter_ = KF1D(f.speed_prior, f.speed_prior_var, f.speed_q, f.speed_r,
                                  adaptive="code" if c.published("rules") else "innovation")
        self.yaw_filter_ = KF1D(f.yaw_prior, f.yaw_prior_var, f.yaw_q, f.yaw_r)
        cl = c.classifier
        self.classifier_ = GroundColourModel(alpha=cl.alpha, prior=cl.ground_prior,
                                             pseudo_ground=0.5 if c.published("ground_labels") else 1.0,
                                             pseudo_nonground=1.0, decay_samples=cl.decay_samples)
        self.calibrator_ = PlattCalibrator(decay=c.calibration.decay, prior_weight=c.calibration.prior_weight)
        self.rng_ = as_rng(self.seed, "seed")
        self.tracks_ = tracks.empty()
        self.poses_ = [np.eye(4)]
        self.times_ = []
        self.n_frames_ = 0
        self.prev_grey_ = self.prev_labels_ = self.prev_prob_ = self.prev_score_ = self.prev_pyr_ = None
        self.rates_ = np.zeros(3)
        self.dense_mask_ = self._dense_region((hp, wp))
        self.sky_labels_ = self._sky_points((hp, wp))
        self.dense_fits_ = (None, None)  # (fit, dt) of the image pairs (k-2, k-1) and (k-1, k)
        self.dense_labels_ = np.zeros((0, 2))  # ground self-labels of the previous image from the dense fit

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
        if hasattr(self, "cfg_"):
            if tuple(rgb.shape[:2]) != self.image_shape_:
                raise ValueError(f"rgb: expected image size {self.image_shape_} like the first image, "
                                 f"got {tuple(rgb.shape[:2])}")
            if self.times_ and not t > self.times_[-1]:
                raise ValueError(f"t: timestamps must increase strictly; got {t!r} after {self.times_[-1]!r}")
        else:
            self._build(rgb.shape)  # re-validates the parameters (they may have been set since construction)
        return self._step(rgb, t)

    def _step(self, rgb, t):
        """Spec §1 for one image: prepare, track, solve motion and scale (or coast), integrate, learn."""
        c, k = self.cfg_, self.n_frames_
        small = reduce2x(rgb) if c.ds == 2 else rgb
        g = grey(small)
        labels = hsv216(small, "code" if c.published("hue_wrap") else "fixed")
        fr = _Frame(diag=dict(n_features=0, n_tracked=0, n_triplets=0, n_motion_points=0, n_candidates=0,
                              n_inliers=0, static=False, ransac_iterations=0, irls_iterations=0, weighted=False,
                              pose_provisional=False, middle_index=k - 1))
        dt = t - self.times_[-1] if k > 0 else 0.0
        pyr = Pyramid(g, c.dense.levels, c.dense.smoothing) if c.dense.enabled else None
        if k > 0 and pyr is not None:
            self._align_dense(pyr, dt, fr.diag)
        if k > 0 and len(self.tracks_["xy"]):
            if k >= 2 and self.tracks_["has"].any():
                self._propagate_depths()
            disp = self._track(g, dt, fr.diag)
            tri = self._gate_triplets(fr.diag)
            if k >= 2:
                self._motion_or_static(fr, disp, tri, t, labels)
        if k >= 2 and fr.status == "init":
            fr.status = "no_features"  # nothing tracked into this frame (black or textureless image)
        if k >= 2 and not fr.motion_done and fr.status != "static":
            self._coast(fr)
        if not fr.motion_done:
            self.rates_ = np.zeros(3)
        self._integrate_pose(k, dt, fr.diag)
        prob = self._ground_map(labels)
        if c.calibration.method == "platt":
            fr.diag["calibration_fallback"] = self.calibrator_.fallback_
        if self._replenish(g, fr.diag) and fr.status == "no_features":
            fr.status = "few_triplets"  # nothing was tracked in, but this image has features to track on
        fr.diag["status"] = fr.status
        if fr.status != "ok":
            logger.debug("frame %d (t=%.3f s): %s", k, t, fr.status)
        self.prev_grey_, self.prev_labels_, self.dt_prev_, self.prev_pyr_ = g, labels, dt, pyr
        self.times_.append(t)
        self.n_frames_ = k + 1
        return self._estimate(fr, t, k, prob)

    def _estimate(self, fr, t, k, prob):
        """The :class:`GroundEstimate` of image k from its frame record and its ground map."""
        H, W = self.image_shape_
        ds = self.cfg_.ds
        prob_out = cv2.resize(prob, (W, H), interpolation=cv2.INTER_LINEAR) if ds == 2 else prob.copy()
        return GroundEstimate(t=t, index=k, speed=self.speed_filter_.x, yaw_rate=self.yaw_filter_.x,
                              speed_raw=float(fr.speed_raw), yaw_rate_raw=float(fr.yaw_raw), rates_raw=fr.rates_raw,
                              speed_dense=float(fr.speed_dense), speed_measured=float(fr.speed_measured),
                              pose=self.poses_[-1].copy(), ground_prob=prob_out, candidates=fr.cand_xy * ds,
                              candidate_dbar=fr.cand_dbar, candidate_uv=fr.cand_uv, candidate_prob=fr.cand_prob,
                              inlier_mask=fr.inl_mask, status=fr.status, diagnostics=fr.diag)

    # -- steps 3-6: depths, tracking, triplets, static test ------------------------------------------

    def _propagate_depths(self):
        """Inverse depths refer to frame k-2 (middle of the last triplet); predict them to frame k-1."""
        c, trk = self.cfg_, self.tracks_
        u_prev = self.camera_.level(trk["xy"][:, 1])[0]
        h_ = trk["has"] & np.isfinite(u_prev)
        base = trk["dmeas"] if c.published("depth_fusion") else trk["d"]  # B5: the code propagates the raw measurement
        trk["d"][h_], trk["P"][h_] = propagate(base[h_], trk["P"][h_], u_prev[h_], self.speed_filter_.x,
                                               self.yaw_filter_.x, self.dt_prev_, c.depth_q)

    def _track(self, g, dt, diag):
        """KLT from the previous image, started at the motion-predicted position (the fix of B6: depth
        aware); returns the frame-to-frame displacements (n, 2) of the tracked features."""
        c, trk, cam = self.cfg_, self.tracks_, self.camera_
        vx, wx, tc = self.speed_filter_.x, self.yaw_filter_.x, c.tracking
        x_prev = trk["xy"][:, 2]
        u, v = cam.level(x_prev)
        usable = trk["has"] & (trk["P"] < 1.0 * (_H_REF / c.h) ** 2) & np.isfinite(trk["d"])
        dpred = np.where(usable, trk["d"], np.maximum(v, 0.0) / c.h)
        udot = -(1 + u * u) * wx + u * vx * dpred
        vdot = -u * v * wx + v * vx * dpred
        guess = cam.image(u + dt * udot, v + dt * vdot)
        lost = ~np.isfinite(guess).all(axis=1)
        guess[lost] = x_prev[lost]
        gh, gw = g.shape
        guess[:, 0] = np.clip(guess[:, 0], 0, gw - 1)
        guess[:, 1] = np.clip(guess[:, 1], 0, gh - 1)
        kw = dict(win=tc.klt_window, levels=tc.klt_levels, fb_max=tc.fb_max)
        x_new, ok, err = frontend.track(self.prev_grey_, g, x_prev, guess, return_err=True, **kw)
        dense = self._dense_pair_motion()
        if dense is not None:
            # The ground's own arc length over this image pair warps the ground better than the filtered speed.
            # (The filtered yaw rate stays: the tracks measure it better than the near ground does.)
            vx = dense[0] / dt
        if tc.ground_warp and vx > 0:
            # Ground-stabilised tracking of points below the horizon: keep whichever of the plain and the
            # homography-warped track matches its patch better.
            low = np.flatnonzero(cam.below(x_prev))
            if len(low):
                Hg = cam.level_homography(frontend.ground_homography(np.eye(3), vx, wx, dt, c.h))
                qw, okw, errw = frontend.track_ground_warped(self.prev_grey_, g, x_prev[low], Hg, **kw)
                better = okw & (~ok[low] | (errw < err[low]))
                if c.dense.enabled:
                    # Aliasing: a repeating texture lets both tracks match, a period apart; drop the point.
                    far = np.linalg.norm(qw - x_new[low], axis=1) > c.dense.track_alias_px * self.pixel_scale_
                    alias = okw & ok[low] & far
                    ok[low[alias]] = False
                    better &= ~alias
                    diag["n_track_aliased"] = int(alias.sum())
                x_new[low[better]] = qw[better]
                ok[low[better]] = True
        diag["n_tracked"] = int(ok.sum())
        disp = x_new[ok] - x_prev[ok]
        tracks.select(trk, ok)
        trk["xy"] = np.concatenate([trk["xy"][:, 1:], x_new[ok][:, None, :]], axis=1)
        trk["age"] += 1
        return disp

    def _gate_triplets(self, diag):
        """Tracks seen in three frames that pass the straightness gate (§2.3); gated tracks are dropped.
        Returns the triplet mask (n,) over the remaining tracks."""
        trk = self.tracks_
        tri = np.isfinite(trk["xy"][:, 0, 0])
        if tri.any():
            xy = trk["xy"]
            gate = frontend.straightness_gate(xy[tri, 0], xy[tri, 1], xy[tri, 2], min_flow=2.0 * self.pixel_scale_,
                                              wrap=not self.cfg_.published("track_gates"))
            keep = np.ones(len(xy), dtype=bool)
            keep[np.flatnonzero(tri)[~gate]] = False  # gated tracks lose their state
            tracks.select(trk, keep)
            tri = tri[keep]
        diag["n_triplets"] = int(tri.sum())
        return tri

    def _motion_or_static(self, fr, disp, tri, t, labels):
        """Step 7 (static test, §2.4), else steps 8-10 on the triplets."""
        c, ps = self.cfg_, self.pixel_scale_
        if fr.diag["n_tracked"] == 0:
            fr.status = "no_features"
            return
        static = fr.diag["n_tracked"] >= 10 and frontend.is_static(disp, thr1=1.0 * ps, thr2=2.0 * ps,
                                                                   per_axis=c.published("track_gates"))
        fr.diag["static"] = bool(static)
        if not static:
            self._motion_and_ground(fr, tri, t, labels)
            return
        fr.status = "static"
        pub, f = c.published("rules"), c.filters
        self.speed_filter_.reset(0.0, f.speed_q if pub else f.speed_prior_var)
        self.yaw_filter_.reset(0.0, f.yaw_q if pub else f.yaw_prior_var)
        self.tracks_["has"][:] = False
        fr.rates_raw = np.zeros(3)

    def _coast(self, fr):
        """No motion solved: the filters coast (the fix of B10: no zero yaw-rate measurement), or follow
        the dense alignment of the ground alone."""
        self.speed_filter_.predict()
        self.yaw_filter_.predict()
        if self.cfg_.published("rules"):
            self.yaw_filter_.update(0.0)  # B10: the published code feeds ω = 0 when motion was not solved
        self.tracks_["has"][:] = False
        dense = self._dense_speed()
        if dense is not None and not dense.aliased:
            fr.speed_dense = fr.speed_measured = dense.speed
            self.speed_filter_.update(dense.speed, var=dense.speed_var)
            self.yaw_filter_.update(dense.yaw_rate)
            fr.status = "ok"

    # -- steps 8-10: motion, ground and scale, depths, classifier ------------------------------------

    def _solve_motion(self, tri, t, diag):
        """Kinematics of the triplets (§3): (MotionResult, track indices, middle positions (n, 2),
        level-frame u, v), or None with too few points."""
        c, cam, ps = self.cfg_, self.camera_, self.pixel_scale_
        idx = np.flatnonzero(tri)
        xy = self.tracks_["xy"][idx]
        x0, x1, x2 = xy[:, 0], xy[:, 1], xy[:, 2]
        span = t - self.times_[-2]  # t_k - t_{k-2}
        u, v = cam.level(x1)
        # Points near the principal axes of the (level) image carry no depth in one component (spec §3.1).
        sel = (np.abs(u * cam.fx) > 3.0 * ps) & (np.abs(v * cam.fy) > 3.0 * ps) & ~self.tracks_["periodic"][idx]
        diag["n_motion_points"] = int(sel.sum())
        if len(idx) < c.motion.min_triplets or sel.sum() < 10:
            return None
        idx, x0, x1, x2, u, v = idx[sel], x0[sel], x1[sel], x2[sel], u[sel], v[sel]
        u0, v0 = cam.level(x0)
        u2, v2 = cam.level(x2)
        halves = (self.times_[-1] - self.times_[-2], t - self.times_[-1])
        mc = c.motion
        m = estimate_motion(u, v, (u2 - u0) / span, (v2 - v0) / span, n_global=mc.n_global, ridge=mc.ridge,
                            irls_iter=mc.irls_iter, estimate_foe=mc.estimate_foe, slip=mc.slip,
                            span=halves if mc.exact_flow else None, compat="fixed")
        diag["irls_iterations"] = int(m.iterations)
        return m, idx, x1, u, v

    def _motion_and_ground(self, fr, tri, t, labels):
        """Steps 8-10 of spec §1: motion, ground model and scale, filters, depths, classifier."""
        solved = self._solve_motion(tri, t, fr.diag)
        if solved is None:
            fr.status = "few_triplets"
            return
        m, idx, x1, u, v = solved
        fr.motion_done, fr.rates_raw, fr.yaw_raw = True, m.rates.copy(), float(m.rates[1])
        fr.yaw_measured = self._measured_yaw(fr, m)
        fit, ci, below = self._fit_ground(fr, m, idx, x1, u, v)
        fr.speed_raw = fit.speed if fit.ok else np.nan
        vf, yf = self.speed_filter_, self.yaw_filter_
        vf.predict()
        yf.predict()
        accepted = fit.ok and fr.diag["n_inliers"] >= self.cfg_.ground.min_inliers
        measured = self._measured_speed(fr, fit if accepted else None)
        if measured is not None:
            vf.update(measured[0], var=measured[1])
        yf.update(fr.yaw_measured)
        self.rates_ = np.array([fr.rates_raw[0], yf.x, fr.rates_raw[2]])
        if measured is not None:
            self._fuse_depths(m, idx, fit.speed)
            self._learn_ground(m, idx, x1, v, ci, below, fit if accepted else None, labels)
        fr.status = "ok" if measured is not None else "no_ground"
        fr.cand_xy, fr.cand_dbar, fr.inl_mask = x1[ci], m.dbar[ci], fit.inliers.copy()
        fr.cand_uv = np.stack([u[ci], v[ci]], axis=1)

    def _fit_ground(self, fr, m, idx, x1, u, v):
        """Ground candidates (valid d̄ strictly below the horizon, §4.1) and the RANSAC fit of the ground
        model, draws weighted by the previous image's P(ground). Returns (GroundFit, candidate indices
        into the triplets, below-horizon mask of the triplets)."""
        c = self.cfg_
        below = self.camera_.below(x1)
        self.tracks_["gnd"][idx[~below]] -= 1
        ci = np.flatnonzero(m.valid & below)
        fr.diag["n_candidates"] = int(len(ci))
        weights = None
        fr.cand_prob = np.full(len(ci), np.nan)
        if self.classifier_.n_updates > 0 and len(ci):
            pr = self.prev_prob_
            r = np.clip(np.rint(x1[ci, 1]).astype(np.intp), 0, pr.shape[0] - 1)
            q = np.clip(np.rint(x1[ci, 0]).astype(np.intp), 0, pr.shape[1] - 1)
            fr.cand_prob = pr[r, q].astype(np.float64)
            if c.sampling == "weighted":
                weights = fr.cand_prob ** c.p
                fr.diag["weighted"] = True
        gc = c.ground
        fit = fit_ground(u[ci], v[ci], m.dbar[ci], c.h, model=c.model, weights=weights, n_iter=c.n_iter, rng=self.rng_,
                         lam=gc.lam, sigma=gc.sigma, compat="code" if c.published("ransac_draw") else "fixed")
        fr.diag["ransac_iterations"] = int(fit.iterations)
        fr.diag["n_inliers"] = int(fit.inliers.sum())
        return fit, ci, below

    def _fuse_depths(self, m, idx, speed_raw):
        """Metric inverse depths of every valid triplet, fused with their predictions (spec §3.4)."""
        c, trk = self.cfg_, self.tracks_
        pub = c.published("depth_fusion")
        V = speed_raw if pub else self.speed_filter_.x  # B5: the code divides by the raw RANSAC V
        if not V > 0:
            return
        vi = np.flatnonzero(m.valid)
        ti = idx[vi]
        d_m = m.dbar[vi] / V
        if pub:
            usable = trk["P"][ti] < c.depth_usable
            prior = np.where(trk["has"][ti], trk["d"][ti], 0.0)  # B5: new tracks fuse against 0
        else:
            usable = trk["has"][ti] & (trk["P"][ti] < c.depth_usable)
            prior = trk["d"][ti]
        d_f, P_f = fuse(prior, trk["P"][ti], d_m, usable, c.depth_r, c.depth_p_reset)
        trk["dmeas"][ti] = d_m
        trk["d"][ti] = d_f
        trk["P"][ti] = P_f
        trk["has"][ti] = True

    def _learn_ground(self, m, idx, x1, v, ci, below, fit, labels):
        """Ground counters and the self-supervised classifier update (spec §4.8, §5.3), and the
        calibrator's out-of-sample self-labels."""
        c, trk, cl = self.cfg_, self.tracks_, self.cfg_.classifier
        inl = fit.inliers if fit is not None else np.zeros(len(ci), dtype=bool)
        trk["gnd"][idx[ci[inl]]] += 1
        g_xy = x1[ci[inl]]
        if cl.train_depth is not None:
            # Far inliers are no evidence of ground: within the RANSAC noise a point at the horizon fits
            # the ground model whatever it is (sky edges, far obstacles). Learn ground only nearer than
            # train_depth (metres, flat-ground depth h / v of the level frame).
            g_xy = g_xy[v[ci[inl]] * cl.train_depth > c.h]
        if c.published("ground_labels"):
            ng_xy = trk["xy"][(trk["gnd"] < 0) & trk["has"], 1]
            lab = labels  # B8: frame-k labels sampled at frame-(k-1) positions
        else:
            ng_sel = m.valid & ~below
            if cl.ng_from_outliers and fit is not None:
                clear = np.zeros(len(v), dtype=bool)
                clear[ci] = fit.residuals > cl.ng_outlier_sigma * fit.sigma
                if cl.ng_outlier_history:
                    clear[ci] &= trk["gnd"][idx[ci]] <= 0
                ng_sel |= clear
            ng_xy = x1[ng_sel]
            lab = self.prev_labels_
        if len(self.dense_labels_):
            # Ground where the dense fit's parallax says so: these pixels learn ground, never non-ground.
            ng_xy = ng_xy[~self._dense_ground_at(ng_xy)]
            g_xy = np.concatenate([g_xy, self.dense_labels_])
        if len(self.sky_labels_):
            ng_xy = np.concatenate([ng_xy, self.sky_labels_])
        if c.calibration.method == "platt" and self.prev_score_ is not None:
            # Out-of-sample self-labels: the map of image k-1 was made before learning from them.
            sh = self.prev_score_.shape
            gi, ni = window_index(sh, g_xy, 1), window_index(sh, ng_xy, 1)
            sc = self.prev_score_.ravel()
            self.calibrator_.update(np.r_[sc[gi], sc[ni]], np.r_[np.ones(len(gi), bool), np.zeros(len(ni), bool)])
        self.classifier_.update(lab, g_xy, ng_xy)

    def _sky_points(self, shape):
        """Non-ground self-labels (m, 2) of a processed image of ``shape`` (H, W): up to
        ``classifier.sky_labels`` pixels spread over the part of the image more than ``sky_margin`` above
        the level horizon (and above a given ``horizon_row`` by as much). A plain sky has no tracks, so
        without them it never gets a label and its colour is decided by whichever ground tone shares it."""
        cl, cam = self.cfg_.classifier, self.camera_
        if cl.sky_labels == 0:
            return np.zeros((0, 2))
        H, W = shape
        yy, xx = np.mgrid[0:H, 0:W]
        xy = np.stack([xx.ravel(), yy.ravel()], axis=1).astype(np.float64)
        up = (cam.level(xy)[1] < -np.tan(cl.sky_margin)).reshape(H, W)
        if cam.horizon is not None:
            up &= yy < cam.horizon - cam.fy * np.tan(cl.sky_margin)
        up &= (xx >= 4) & (xx < W - 4) & (yy >= 4)
        return label_points(up.view(np.uint8), 0, cl.sky_labels)

    # -- dense ground alignment ----------------------------------------------------------------------

    def _dense_region(self, shape):
        """Pixels (H, W) bool of a processed image that the dense fit may align: below the horizon, flat-
        ground depth up to ``max_depth``, 4 px from the borders."""
        c, cam = self.cfg_, self.camera_
        H, W = shape
        yy, xx = np.mgrid[0:H, 0:W]
        xy = np.stack([xx.ravel(), yy.ravel()], axis=1).astype(np.float64)
        v = cam.level(xy)[1].reshape(H, W)
        near = (v > 0) & (v * c.dense.max_depth >= c.h)
        if cam.horizon is not None:
            near &= yy > cam.horizon
        return near & (xx >= 4) & (xx < W - 4) & (yy >= 4) & (yy < H - 4)

    def _align_dense(self, pyr, dt, diag):
        """Align the ground of the previous image to this one from the filters' prediction; keep the last
        two image pairs' fits and the previous image's ground self-labels."""
        c, d = self.cfg_, self.cfg_.dense
        w = None
        if self.classifier_.n_updates > 0:
            w = d.prob_floor + (1.0 - d.prob_floor) * self.prev_prob_
        fit = align_ground(self.prev_pyr_, pyr, self.camera_, c.h, self.speed_filter_.x * dt, self.yaw_filter_.x * dt,
                           mask=self.dense_mask_, weights=w, block=d.block, max_pixels=d.max_pixels,
                           min_gradient=d.min_gradient, min_pixels=d.min_pixels, max_iter=d.max_iter,
                           residual_floor=d.residual_floor, gradient_weight=d.gradient_weight, model=d.model,
                           alias_range=d.alias_sigmas * np.sqrt(self.speed_filter_.P + self.speed_filter_.q) * dt,
                           alias_margin=d.alias_margin, slip=c.motion.slip / dt)
        self.dense_fits_ = (self.dense_fits_[1], (fit, dt))
        diag.update(dense_ok=fit.ok, dense_aliased=fit.aliased, dense_pixels=fit.n_pixels,
                    dense_iterations=fit.iterations)
        self.dense_labels_ = np.zeros((0, 2))
        if fit.ok and not fit.aliased and d.label_evidence > 0 and d.max_labels > 0:
            if d.label_region == "support":
                # Labels spread over the ground the evidence is connected to, not only over its texture.
                self.evidence_, support = ground_evidence(self.prev_pyr_, pyr, self.camera_, c.h, fit, self.dense_mask_,
                                                          support_threshold=d.label_evidence)
                self.dense_labels_ = label_points(support.view(np.uint8), 0, d.max_labels)
            else:
                self.evidence_ = ground_evidence(self.prev_pyr_, pyr, self.camera_, c.h, fit, self.dense_mask_)
                self.dense_labels_ = label_points(self.evidence_, d.label_evidence, d.max_labels)
        diag["n_dense_labels"] = int(len(self.dense_labels_))

    def _dense_pair_motion(self):
        """(arc length m, yaw change rad) of the last image pair, if its dense fit is trusted; else None."""
        last = self.dense_fits_[1]
        if last is None or not last[0].ok or last[0].aliased:
            return None
        return last[0].s, last[0].a

    def _dense_speed(self):
        """The dense speed and yaw rate of the middle frame k-1: the arc lengths and yaw changes of the
        two image pairs around it over their time span (the central difference of the sparse flow),
        with their variances; None unless both pairs were fitted."""
        pairs = self.dense_fits_
        if any(p is None or not p[0].ok for p in pairs):
            return None
        span = pairs[0][1] + pairs[1][1]
        d = self.cfg_.dense
        var = np.zeros((2, 2))
        for f, _ in pairs:
            # The fit's own variance, and the plane model's error where the ground is not that plane.
            v = d.var_scale * f.cov
            v[0, 0] += (d.spread_scale * np.nan_to_num(f.band_spread, nan=0.0)) ** 2
            var += v * (d.alias_var_scale if f.aliased else 1.0)
        var /= span ** 2
        return _DenseSpeed(sum(f.s for f, _ in pairs) / span, float(var[0, 0]), sum(f.a for f, _ in pairs) / span,
                           float(var[1, 1]), any(f.aliased for f, _ in pairs))

    def _measured_speed(self, fr, fit):
        """The speed measurement of this frame and its variance: the RANSAC speed (``fit``, None if not
        accepted) and the dense speed fused by their variances; None if neither."""
        c = self.cfg_
        dense = self._dense_speed() if c.dense.enabled else None
        if dense is not None:
            fr.speed_dense = dense.speed
            fr.diag["speed_dense_var"] = dense.speed_var
        if fit is not None:
            fr.diag["speed_raw_var"] = c.ground.var_scale * fit.speed_var
        if fit is None and dense is None:
            return None
        if dense is None:
            z = (fit.speed, 0.0)  # the RANSAC speed alone: the filter's nominal noise, as without the dense fit
        elif fit is None:
            z = (dense.speed, dense.speed_var)
        else:
            z = fuse_measurements(fit.speed, c.ground.var_scale * fit.speed_var, dense.speed, dense.speed_var,
                                  c.dense.gate)
        fr.speed_measured = z[0]
        return z

    def _measured_yaw(self, fr, m):
        """The yaw-rate measurement of this frame (rad/s): the tracks' yaw rate fused with the dense fit's by
        their variances. The tracks' variance grows with the share of the ground's tracks seen to alias
        (1 + alias_var_scale x share): on a repeating texture the tracks that were not caught alias too.
        The tracks' yaw alone without the dense stage, or when either variance is unknown."""
        c = self.cfg_
        dense = self._dense_speed() if c.dense.enabled and c.dense.fuse_yaw else None
        if dense is None or dense.aliased or not np.isfinite(m.yaw_var) or not np.isfinite(dense.yaw_var):
            return fr.yaw_raw
        d = fr.diag
        share = d.get("n_track_aliased", 0) / max(d.get("n_track_aliased", 0) + d.get("n_tracked", 0), 1)
        var = c.dense.var_scale * m.yaw_var * (1.0 + c.dense.alias_var_scale * share)
        z, z_var = fuse_measurements(fr.yaw_raw, var, dense.yaw_rate, dense.yaw_var, c.dense.gate)
        d.update(yaw_tracks_var=var, yaw_dense=dense.yaw_rate, yaw_dense_var=dense.yaw_var, yaw_measured=z,
                 yaw_measured_var=z_var)
        return z

    def _dense_ground_at(self, xy):
        """Whether the dense fit's evidence marks each point (n, 2) of the previous image as ground."""
        e = self.evidence_
        r = np.clip(np.rint(xy[:, 1]).astype(np.intp), 0, e.shape[0] - 1)
        q = np.clip(np.rint(xy[:, 0]).astype(np.intp), 0, e.shape[1] - 1)
        return e[r, q] > self.cfg_.dense.label_evidence

    # -- steps 11-12: pose, ground map, new features -------------------------------------------------

    def _integrate_pose(self, k, dt, diag):
        """One pose per image (spec §6.1 with the B27 fix)."""
        if k == 0:
            return
        pub = self.cfg_.published("pose_steps")
        if k == 2 and not pub:
            # The step 0 -> 1 reuses the frame-1 estimate, available only now.
            self.poses_[1] = self._step_pose(np.eye(4), self.times_[1] - self.times_[0])
        self.poses_.append(self._step_pose(self.poses_[-1], dt))
        diag["pose_provisional"] = (k == 1 and not pub)

    def _step_pose(self, T, dt):
        """Compose one integration step of length dt with the filtered speed and yaw rate."""
        c = self.cfg_
        rates = self.rates_.copy() if c.integration == "3d" else np.zeros(3)
        rates[1] = self.yaw_filter_.x
        step = motion_step(self.speed_filter_.x, rates, dt, c.integration, semi_implicit=c.published("pose_steps"))
        return T @ self.camera_.to_camera(step)

    def _ground_map(self, labels):
        """P(ground) of this image: the classifier's map (kept to weight the next RANSAC), calibrated."""
        c = self.cfg_
        prob = self.classifier_.predict(labels)
        if c.published("ground_labels"):
            # The published map is not computed at the borders (1 px top/left, 2 px bottom/right).
            prob[:1, :] = prob[:, :1] = 0.5
            prob[-2:, :] = prob[:, -2:] = 0.5
        self.prev_prob_ = prob
        if c.calibration.method != "platt":
            return prob
        score = self.classifier_.log_odds_table()[labels]
        w = c.calibration.window
        if w > 1:
            score = cv2.blur(score, (w, w), borderType=cv2.BORDER_REPLICATE)
        self.prev_score_ = score
        return self.calibrator_.transform(score)

    def _replenish(self, g, diag):
        """New features in free grid cells; returns how many were added."""
        c, trk = self.cfg_, self.tracks_
        existing = trk["xy"][:, 2] if len(trk["xy"]) else np.zeros((0, 2))
        new = frontend.detect_new(g, existing, max_new=c.tracking.max_features - len(existing), cell=self.cell_)
        if len(new):
            per = None
            if c.dense.enabled and c.dense.periodic_ncc < 1.0:
                # Aliasing in tracks: a corner on a texture that repeats within a few pixels can be tracked
                # a period off, so it does not enter the motion solve.
                per = frontend.periodic(g, new, half=c.tracking.klt_window // 2,
                                        radius=max(4, int(round(8 * self.pixel_scale_))), threshold=c.dense.periodic_ncc)
                diag["n_periodic"] = int(per.sum())
            tracks.append(trk, new, c.depth_p_new if c.published("depth_fusion") else c.depth_p_reset, per)
        diag["n_features"] = int(len(trk["xy"]))
        return len(new)
