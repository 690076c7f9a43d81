"""ObjectTracker: self-supervised object segmentation and 6-DoF tracking (spec 2, 3, 6).

One frame (:meth:`ObjectTracker._step`): predict the pose (motion filter) -> project the model
(visibility, silhouette, ROI) -> appearance -> attention prior x depth likelihood x appearance
likelihood = prediction map (E-step) -> weighted robust ICP of the highly probable points (M-step)
-> drift guard -> labels O of all ROI points off the registered model -> online appearance update
-> filter update.
"""

from __future__ import annotations

import logging
import numbers
import time
from dataclasses import dataclass

import cv2
import numpy as np

from polar_sim._validation import as_bool, as_float, as_int, as_intrinsics, as_pose, check_choice
from polar_sim.errors import PolarSimError
from polar_sim.geometry import inv_pose, make_pose, se3_exp, se3_log
from polar_sim.params import Parameterised, Tags
from polar_sim.tracking import pixels
from polar_sim.tracking._checks import as_model_points, as_normals, as_rgbd
from polar_sim.tracking.appearance import make_appearance
from polar_sim.tracking.calibration import OnlineCalibration
from polar_sim.tracking.config import AttentionConfig, GuardConfig, LearningConfig, MotionConfig, RegistrationConfig
from polar_sim.tracking.icp import symmetry_directions, unobserved_directions, weighted_icp
from polar_sim.tracking.model import ShapeModel, estimate_normals
from polar_sim.tracking.motion import MotionFilter
from polar_sim.tracking.result import TrackResult
from polar_sim.tracking.visibility import disc, project_model

__all__ = ["ObjectTracker", "TrackResult", "APPEARANCE_VARIANTS"]

logger = logging.getLogger(__name__)

#: Values of the ``appearance`` parameter: the colour Naive Bayes, the S/W x u/w feature heads, none.
APPEARANCE_VARIANTS = ("h", "su", "sw", "wu", "ww", "none")
#: Pose spread assumed by the second E-step (``registration.em_refine``): 3 mm and 1 degree.
_EM_SIGMA_TR = 0.003
_EM_SIGMA_ROT = np.deg2rad(1.0)
#: Widening of the filter after a poor fit, and of the Mahalanobis gate for a confident one (x4 in d2).
_COAST_INFLATE = 4.0
#: Longest frame interval the motion filter predicts over, s (see :meth:`ObjectTracker.process`).
MAX_GAP_S = 1.0
_STAGES = {"motion": MotionConfig, "attention": AttentionConfig, "registration": RegistrationConfig,
           "guard": GuardConfig, "learning": LearningConfig}
_NO_PRESET = (
    "ObjectTracker has no published preset: the thesis material (Lee 2019, ch. 5; Lee & Lee, IROS "
    "2016/2017) gives no equation, threshold, ICP variant or parameter value of the tracker (see "
    "docs/specs/tracking.md, section 0), so there is no published setting to reproduce. Every "
    "default is this reimplementation's choice (spec section 10, departures chosen on the dev split): "
    "use ObjectTracker(model_points, K, initial_pose, ...) with its defaults")


class _Clock:
    """Accumulates wall time per pipeline stage (perf_counter laps)."""

    def __init__(self):
        self.t = time.perf_counter()
        self.stages = {}

    def lap(self, name):
        now = time.perf_counter()
        self.stages[name] = self.stages.get(name, 0.0) + now - self.t
        self.t = now


@dataclass
class _Frame:
    """One frame's working state, passed between the stages of :meth:`ObjectTracker._step`.

    ``T_bar`` (4, 4) predicted T_cam_cen, its spreads ``sig_rot`` (rad), ``sig_tr`` and ``sig_pos``
    (m), the model's projection ``proj`` there; the ROI and its depth crop ``D``; the appearance
    features and log-ratio ``lI`` with weight ``gamma``; the prediction map ``Pmap``, prior ``pi``
    and silhouette ``S``; the registration ``res`` of ``n_sel`` of ``n_cand`` candidate points,
    ``at``, the (projection, spread) that ``S`` was made with, and the ICP's tangential dead zone.
    """

    dt: float
    T_bar: np.ndarray
    sig_rot: float
    sig_tr: float
    sig_pos: float
    proj: object
    gamma: float
    roi: tuple = (0, 0, 0, 0)
    D: np.ndarray | None = None
    feats: object = None
    lI: np.ndarray | None = None
    Pmap: np.ndarray | None = None
    pi: np.ndarray | None = None
    S: np.ndarray | None = None
    res: object = None
    n_sel: int = 0
    n_cand: int = 0
    at: tuple = ()
    deadzone: float = 0.0


def _logit(p):
    """log(p / (1 - p)) of a probability map (float32), finite for p in [0, 1]."""
    p = np.clip(p.astype(np.float32), np.float32(1e-6), np.float32(1 - 1e-6))
    return np.log(p) - np.log1p(-p)


def _with_axes(U, A, tol=0.5):
    """U (6, k) orthonormal, extended (Gram-Schmidt) by each unit column of A (6, n) whose part
    outside span(U) is longer than ``tol``; U itself is returned when it already spans A."""
    for a in A.T:
        r = a - U @ (U.T @ a)
        nr = float(np.linalg.norm(r))
        if nr > tol:
            U = np.concatenate([U, (r / nr)[:, None]], axis=1)
    return U


def _rot_angle(R):
    return float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))


class ObjectTracker(Parameterised):
    """Model-based RGB-D object tracker with an appearance model learned online from its own labels.

    Parameters
    ----------
    model_points : ndarray (M, 3)
        Object model points, object frame, metres (about 3000, area-uniform).
    K : ndarray (3, 3)
        Camera intrinsics (OpenCV).
    initial_pose : ndarray (4, 4)
        T_cam_obj at the first frame.
    model_normals : ndarray (M, 3), optional
        Outward unit normals; estimated by local PCA (oriented away from the centroid) if omitted.
    appearance : {"ww", "wu", "sw", "su", "h", "none"}, default="ww"
        Appearance model (case-insensitive): multi-scale feature head S (stacked) or W (weighted
        sum of per-scale heads) with u (uniform) or w (confidence-weighted) self-labels; "h" the
        216-bin HSV Naive Bayes; "none" the shape-and-motion-only ablation (gamma = 0).
    motion : MotionConfig
        The motion prior: filter ("ekf", "alpha-beta", "none") and velocity damping.
    attention : AttentionConfig
        The spatial prior pi (off by default) and its floor and blur.
    registration : RegistrationConfig
        Which points are registered and how: method ("weighted", "plain"), correspondences, N_Y,
        tau_y, ICP iterations, the second EM step, the MAP prior, the hold of unobserved directions.
    guard : GuardConfig
        The drift guard: good fit, coverage (lost), learning coverage, jump gates, lost mode.
    learning : LearningConfig
        Online training of the appearance model: ramp-in, fading, Adam, replay, samples.
    fps : float, default=30
        Frame rate used when ``process`` gets no time stamp.
    calibrate : bool, default=True
        Report ``prob`` calibrated by :class:`polar_sim.tracking.calibration.OnlineCalibration`,
        learned from the labels O of the accepted frames (never from truth); False reports the
        raw prediction map. The registration always uses the raw map.
    random_state : int, default=0
        Seed of the sampling Generator (point selection, training samples, mini-batches).
    debug_maps : bool, default=False
        Also return the attention, appearance and silhouette maps.

    Notes
    -----
    The stage configs (:mod:`polar_sim.tracking.config`) are frozen dataclasses that check their
    fields when made; ``get_params()`` lists their fields as ``stage__field`` and
    ``set_params(registration__tau_y=0.6)`` changes one (scikit-learn's nested convention).
    The module contract (:class:`polar_sim.params.Parameterised`): the constructor stores the
    parameters as given and checks them (``_check_params``, also used by ``set_params`` and the
    first frame); the state is created by the first :meth:`process` in attributes ending in ``_``
    (``model_``, ``filter_``, ``appearance_model_``, ``calibration_``, ``symmetry_axes_``, ``rng_``,
    ``pose_``, ``n_frames_``, ...) and :meth:`reset` removes it. There is no published preset
    (:meth:`published` says why).
    """

    TAGS = Tags(update="process", random_state="random_state", data="polar_sim.tracking.synthetic:check_data")

    def __init__(self, model_points, K, initial_pose, *, model_normals=None, appearance="ww",
                 motion=MotionConfig(), attention=AttentionConfig(), registration=RegistrationConfig(),
                 guard=GuardConfig(), learning=LearningConfig(), fps=30.0, calibrate=True, random_state=0,
                 debug_maps=False):
        self.model_points = model_points
        self.K = K
        self.initial_pose = initial_pose
        self.model_normals = model_normals
        self.appearance = appearance
        self.motion = motion
        self.attention = attention
        self.registration = registration
        self.guard = guard
        self.learning = learning
        self.fps = fps
        self.calibrate = calibrate
        self.random_state = random_state
        self.debug_maps = debug_maps
        # fail early: the same checks as every later use (no state is built here)
        self._check_params()

    @classmethod
    def published(cls, *args, **overrides):
        """Not available: the thesis gives no setting of the tracker to reproduce.

        Raises
        ------
        polar_sim.errors.PolarSimError
            Always (a ``ValueError``). The thesis material gives no equation, threshold, ICP
            variant or number of the tracker (``docs/specs/tracking.md`` section 0): every default
            is this reimplementation's (spec section 10, departures chosen on the dev split).
        """
        raise PolarSimError(_NO_PRESET)

    def _check_params(self):
        """Check every parameter (the one place); returns the clean arrays.

        Returns
        -------
        dict with ``P`` (M, 3) model points, ``N`` (M, 3) normals or None, ``K`` (3, 3) and
        ``T0`` (4, 4). Raises ``ValueError``/``TypeError`` naming the parameter.
        """
        if not isinstance(self.appearance, str):
            raise TypeError(f"appearance: expected a string, got {type(self.appearance).__name__}")
        check_choice(self.appearance.lower(), APPEARANCE_VARIANTS, "appearance")
        for name, cls in _STAGES.items():
            if not isinstance(getattr(self, name), cls):
                raise TypeError(f"{name}: expected a {cls.__name__} (polar_sim.tracking.config), got "
                                f"{type(getattr(self, name)).__name__}")
        for name in ("calibrate", "debug_maps"):
            as_bool(getattr(self, name), name)
        as_float(self.fps, "fps", minimum=0.0, exclusive_minimum=True)
        as_int(self.random_state, "random_state", minimum=0)
        P = as_model_points(self.model_points)
        N = None if self.model_normals is None else as_normals(self.model_normals, len(P))
        return {"P": P, "N": N, "K": as_intrinsics(self.K, "K"), "T0": as_pose(self.initial_pose, "initial_pose")}

    def _build(self):
        """The state of a tracker that has seen no frame (on the first :meth:`process`)."""
        c = self._check_params()
        P = c["P"]
        m = ShapeModel(P, estimate_normals(P) if c["N"] is None else c["N"])
        self.K_ = c["K"]
        self.model_ = m
        self.T_obj_cen_ = make_pose(None, m.centroid)
        self.T_cen_obj_ = make_pose(None, -m.centroid)
        cap = (0.3, max(0.02, 0.3 * m.diameter))
        self.filter_ = MotionFilter(c["T0"] @ self.T_obj_cen_, mode=self.motion.filter, sigma_cap=cap)
        lc = self.learning
        self.appearance_model_ = make_appearance(self.appearance, decay=lc.decay, lr=lc.lr, epochs=lc.epochs,
                                                 replay=lc.replay)
        self.rng_ = np.random.default_rng(self.random_state)
        self.calibration_ = OnlineCalibration() if self.calibrate else None
        # rotations that map the whole model onto itself (a revolved object's axis): held always
        hold = self.registration.hold_unobserved
        self.symmetry_axes_ = symmetry_directions(m) if hold else np.zeros((6, 0))
        self.n_unobserved_ = 0
        self.image_shape_ = None
        self.t_prev_ = None
        self.rejections_ = 0
        self.n_frames_ = 0

    def reset(self):
        """Forget everything learned (the ``_``-suffixed attributes): the next :meth:`process`
        starts again at ``initial_pose`` with zero velocity and an untrained appearance model."""
        return super().reset()

    # ------------------------------------------------------------------------------------------
    def process(self, rgb, depth, t=None):
        """Track one RGB-D frame.

        Parameters
        ----------
        rgb : ndarray (H, W, 3) uint8.
        depth : ndarray (H, W) float, metres; 0, NaN or inf = missing.
        t : float, optional
            Time stamp, s; without it frames are 1/fps apart. Either every frame since the first
            (or since :meth:`reset`) has one or none has. A gap longer than ``MAX_GAP_S`` (1 s)
            is predicted as 1 s. The first frame is taken at the time of ``initial_pose``: it is
            registered from that pose and its spread, with no motion predicted before it.

        Returns
        -------
        TrackResult
        """
        t_start = time.perf_counter()
        built = hasattr(self, "filter_")
        t_prev = self.t_prev_ if built else None
        rgb, depth = as_rgbd(rgb, depth, shape=self.image_shape_ if built else None)
        if t is not None:
            if isinstance(t, bool) or not isinstance(t, numbers.Real) or not np.isfinite(t):
                raise ValueError(f"t: expected a finite time stamp in seconds, got {t!r}")
            if t_prev is not None and t <= t_prev:
                raise ValueError(f"t: time stamps must increase, got {t} after {t_prev}")
        if built and self.n_frames_ > 0 and (t is None) != (t_prev is None):
            # mixing stamped and unstamped frames leaves the frame interval undefined
            raise ValueError("t: every frame needs a time stamp once one was given, and none may be "
                             f"given after unstamped frames (got {t!r}, previous {t_prev!r}); reset() to start again")
        dt = 1.0 / self.fps if (t is None or t_prev is None) else float(t - t_prev)
        if not built or self.n_frames_ == 0:
            # the first frame is at the time of initial_pose: predicting over 1/fps before it would
            # correlate the pose with the (unknown) velocity, so that its first registration error
            # became a spurious velocity that rings for frames (issue 35: up to 1.7 deg at rest)
            dt = 0.0
        # a longer gap is predicted as MAX_GAP_S: the covariance is at its caps by then, and constant
        # velocity is not extrapolated further (nor overflows on absurd gaps)
        dt = min(dt, MAX_GAP_S)
        # -- validated: from here on the state changes ------------------------------------------
        if not built:
            self._build()
        self.image_shape_ = rgb.shape[:2]
        self.t_prev_ = t if t is not None else self.t_prev_
        self.clock_ = _Clock()
        self.clock_.stages["validate"] = self.clock_.t - t_start
        out = self._step(rgb, depth, dt)
        self.clock_.lap("output")
        out["stage_times"] = dict(self.clock_.stages)
        self.n_frames_ += 1
        self.pose_ = out["pose"]
        out["time_s"] = time.perf_counter() - t_start
        return TrackResult(**out)

    # -- the stages of one frame ---------------------------------------------------------------
    def _step(self, rgb, depth, dt):
        """One frame, as steps; returns the fields of its :class:`TrackResult`."""
        fr = self._predict(dt)
        if fr.proj.vis.sum() < 3:
            return self._coast(fr)
        self._attend(fr, depth)
        self.clock_.lap("predict_attention")
        self._see(fr, rgb)
        self.clock_.lap("appearance")
        fr.Pmap, fr.pi, fr.S = self._prediction_map(fr, fr.T_bar, fr.proj, fr.sig_pos)
        fr.at = (fr.proj, fr.sig_pos)
        self.clock_.lap("depth_likelihood")
        self._register_frame(fr)
        self.clock_.lap("registration")
        coverage = self._gate(fr)
        if coverage is None:
            return self._coast(fr)
        return self._update(fr, coverage)

    def _predict(self, dt):
        """Predicted pose, its spread, the model's projection there and the appearance weight."""
        m = self.model_
        self.n_unobserved_ = 0
        T_bar, P_bar = self.filter_.predict(dt)
        sig_rot = float(np.sqrt(max(np.linalg.eigvalsh(P_bar[:3, :3]).max(), 0.0)))
        sig_tr = float(np.sqrt(max(np.linalg.eigvalsh(P_bar[3:, 3:]).max(), 0.0)))
        proj = project_model(m.P, m.N, T_bar[:3, :3], T_bar[:3, 3], self.K_, self.image_shape_, m.spacing)
        gamma = 0.0
        if self.appearance_model_ is not None and self.rejections_ < self.guard.lost_after:
            gamma = min(1.0, self.appearance_model_.n_updates / self.learning.k_warm)
        return _Frame(dt, T_bar, sig_rot, sig_tr, sig_tr + 0.5 * m.diameter * sig_rot, proj, gamma)

    def _attend(self, fr, depth):
        """The ROI: the predicted silhouette's box, grown by max(20 px, 3 sigma) and a splat radius."""
        H, W = self.image_shape_
        f, proj = float(self.K_[0, 0]), fr.proj
        zb = proj.z_mean
        sigma_px = max(self.attention.sigma_min_px, f * fr.sig_pos / zb)
        r_s = int(max(1, np.ceil(f * self.model_.spacing / zb)))
        pad = int(np.ceil(max(20.0, 3.0 * sigma_px))) + r_s
        uvv = proj.uv[proj.vis]
        x0 = int(max(0, np.floor(uvv[:, 0].min()) - pad))
        y0 = int(max(0, np.floor(uvv[:, 1].min()) - pad))
        x1 = int(min(W, np.ceil(uvv[:, 0].max()) + pad + 1))
        y1 = int(min(H, np.ceil(uvv[:, 1].max()) + pad + 1))
        fr.roi = (x0, y0, x1, y1)
        fr.D = depth[y0:y1, x0:x1]

    def _see(self, fr, rgb):
        """Appearance features of the ROI and, when they are used or shown, their log-ratio."""
        app = self.appearance_model_
        if app is None:
            return
        x0, y0, x1, y1 = fr.roi
        fr.feats = app.prepare(np.ascontiguousarray(rgb[y0:y1, x0:x1]))
        if fr.gamma > 0 or self.debug_maps:
            fr.lI = app.log_ratio(fr.feats)

    def _prediction_map(self, fr, T, proj, sig_pos):
        """The E-step at pose T: prediction map, prior and silhouette (:func:`pixels.prediction_map`)."""
        return pixels.prediction_map(self.model_, self.K_, fr.D, fr.roi, T, proj, sig_pos, fr.lI, fr.gamma,
                                     self.attention)

    def _register_frame(self, fr):
        """The M-step from the prediction; when it lands more than 2 predicted standard deviations
        away, the prediction map was centred on the wrong place: redo the E-step at the registered
        pose with a tight spread and register again (``registration.em_refine``)."""
        m, T_bar = self.model_, fr.T_bar
        rest = self._at_rest(fr)
        fr.deadzone = self.registration.tangential_deadzone * rest * self._hidden_fraction(fr) if rest > 0 else 0.0
        fr.res, fr.n_sel, fr.n_cand = self._register(fr, fr.Pmap, T_bar, fr.proj.vis, fr.sig_pos)
        res = fr.res
        if res is None or not res.ok or not self.registration.em_refine:
            return
        d_rot = _rot_angle(T_bar[:3, :3].T @ res.T[:3, :3]) / max(fr.sig_rot, 1e-6)
        d_tr = float(np.linalg.norm(res.T[:3, 3] - T_bar[:3, 3])) / max(fr.sig_tr, 1e-6)
        if d_rot**2 + d_tr**2 <= 4.0:
            return
        proj2 = project_model(m.P, m.N, res.T[:3, :3], res.T[:3, 3], self.K_, self.image_shape_, m.spacing)
        if proj2.vis.sum() < 3:
            return
        sig2 = _EM_SIGMA_TR + 0.5 * m.diameter * _EM_SIGMA_ROT
        Pmap2, pi2, S2 = self._prediction_map(fr, res.T, proj2, sig2)
        res2, n_sel2, n_cand2 = self._register(fr, Pmap2, res.T, proj2.vis, sig2)
        if res2 is not None and res2.ok:
            fr.res, fr.n_sel, fr.n_cand, fr.Pmap, fr.pi, fr.S = res2, n_sel2, n_cand2, Pmap2, pi2, S2
            fr.at = (proj2, sig2)

    def _at_rest(self, fr):
        """Evidence in [0, 1] that the object is at rest: 1 while the motion filter's velocity moves
        the surface (translation plus rotation at half the diameter) by at most
        ``registration.deadzone_rest_speed`` model spacings over this frame's interval, falling
        linearly to 0 at twice that (``motion.filter="none"`` keeps no velocity: always 1)."""
        rc, m = self.registration, self.model_
        limit = rc.deadzone_rest_speed * m.spacing
        if rc.tangential_deadzone == 0.0 or limit == 0.0:
            return 0.0
        xi = self.filter_.xi
        u = (float(np.linalg.norm(xi[3:])) + 0.5 * m.diameter * float(np.linalg.norm(xi[:3]))) * fr.dt
        return float(np.clip(2.0 - u / limit, 0.0, 1.0))

    def _hidden_fraction(self, fr):
        """Fraction of the predicted silhouette's valid-depth pixels where something is seen in front
        of the predicted surface (a hand, another object); 0 when no dead zone is asked for."""
        if self.registration.tangential_deadzone == 0.0:
            return 0.0
        seen = (fr.D > 0) & (fr.S > 0)
        n_seen = int(np.count_nonzero(seen))
        if n_seen == 0:
            return 0.0
        hidden = seen & pixels.in_front(self.model_, self.K_, fr.D, fr.roi, fr.proj, fr.sig_pos)
        return int(np.count_nonzero(hidden)) / n_seen

    def _register(self, fr, Pmap, T_init, vis, sig_pos):
        """Select the highly probable points and run the weighted ICP from T_init (spec 3.5).

        Returns the ICP result (None with fewer than 6 points), the points registered and the
        candidates before subsampling."""
        m, D, rc = self.model_, fr.D, self.registration
        valid = D > 0
        if rc.method == "plain":
            cand = np.flatnonzero(valid)
            w_all = np.ones(len(cand))
        else:
            cand = np.flatnonzero(valid & (Pmap > rc.tau_y))
            w_all = Pmap.ravel()[cand].astype(np.float64)
        n_cand = len(cand)
        if n_cand > rc.max_points:
            # weighted sampling without replacement (Efraimidis-Spirakis): the k largest
            # log(u) / w, one uniform draw per candidate, O(n)
            keys = np.log(self.rng_.random(n_cand)) / np.maximum(w_all, 1e-12)
            pick = np.sort(np.argpartition(-keys, rc.max_points - 1)[: rc.max_points])
            cand, w0 = cand[pick], w_all[pick]
        else:
            w0 = w_all
        if len(cand) < 6:
            return None, len(cand), n_cand
        X, zc = pixels.backproject(self.K_, D, fr.roi, cand)
        sd = pixels.depth_sigma(zc)
        gate0 = min(max(3.0 * float(np.sqrt(np.median(sd**2) + sig_pos**2)), 0.015), m.margin)
        gate_floor = min(max(3.0 * float(np.median(sd)), m.spacing), gate0)
        prior = None
        if rc.pose_prior:
            T_pred, P_pred = self.filter_.T_bar, self.filter_.P_bar[:6, :6]
            prior = (T_pred, np.linalg.inv(P_pred + 1e-12 * np.eye(6)))
        res = weighted_icp(X, w0, m, T_init, self.K_, self.image_shape_, sigma_d=sd,
                           delta1=np.maximum(3 * sd, 0.006), gate0=gate0, gate_floor=gate_floor,
                           max_iterations=rc.max_iterations, exact=rc.correspondence == "kdtree",
                           tangential_deadzone=fr.deadzone, vis_init=vis, prior=prior)
        return res, len(cand), n_cand

    def _gate(self, fr):
        """The drift guard's first test: the registration's coverage (inliers per expected pixel)
        if it is usable, None if not (no fit, a jump past either gate, too little of it covered)."""
        res, T_bar, g = fr.res, fr.T_bar, self.guard
        if res is None or not res.ok or res.n_matched < 6:
            return None
        rot_jump = _rot_angle(T_bar[:3, :3].T @ res.T[:3, :3])
        tr_jump = float(np.linalg.norm(res.T[:3, 3] - T_bar[:3, 3]))
        seen = (fr.D > 0) & (fr.S > 0)
        expected = max(int(np.count_nonzero(seen)), 1)
        scale = fr.n_cand / max(fr.n_sel, 1)
        coverage = res.n_inliers * scale / expected
        if g.coverage == "visible":
            # an occluder is no evidence against the pose: count only the unhidden pixels
            hidden = seen & pixels.in_front(self.model_, self.K_, fr.D, fr.roi, *fr.at)
            tracked = res.n_inliers * scale / max(expected - int(np.count_nonzero(hidden)), 1)
        else:
            tracked = coverage
        e = se3_log(inv_pose(T_bar) @ res.T)
        S_e = self.filter_.P_bar[:6, :6] + np.diag(self.filter_.floor)
        d2 = float(e @ np.linalg.solve(S_e, e))
        limit = g.max_mahalanobis
        if g.confident_fitness is not None and res.fitness >= g.confident_fitness and coverage >= g.learn_coverage:
            limit = _COAST_INFLATE * limit  # a clean fit of a sudden push: the prior's spread lags the motion
        ok = (rot_jump < g.max_jump[0] and tr_jump < g.max_jump[1] and d2 < limit
              and tracked >= g.min_coverage)
        return coverage if ok else None

    def _update(self, fr, coverage):
        """A usable registration: hold what it cannot see, label, learn, update the filter, report."""
        res, g = fr.res, self.guard
        good_fit = res.fitness >= g.fitness_min and res.n_inliers >= g.min_inliers
        accepted = good_fit and coverage >= g.learn_coverage
        T_hat, hold = self._held(fr)
        O, S_hat, r_hat = self._labels(fr, T_hat, vis=res.vis)
        self.clock_.lap("labels")
        cal = self._calibrated(fr.Pmap)  # the prediction, before this frame's labels are learned
        if accepted and self.calibration_ is not None:
            z = _logit(fr.Pmap[O >= 0])
            self.calibration_.update(z, O[O >= 0] == 1)
        if accepted and self.appearance_model_ is not None:
            self._train(fr, O, S_hat, r_hat)
        self.clock_.lap("learning")
        # a good fit updates the filter (a mostly hidden object only skips learning); a poor fit is
        # reported (spec 3.7) but not fused: the filter coasts (widened x4, velocity damped) and
        # the frame counts towards lost mode, in which the prediction is reported instead
        if good_fit:
            self.filter_.update(T_hat, res.cov, fr.dt, hold=hold)
            self.rejections_ = 0
        else:
            self.filter_.coast(velocity_decay=self.motion.velocity_decay, inflate=_COAST_INFLATE)
            self.rejections_ += 1
        lost = self.rejections_ >= g.lost_after
        if lost:
            T_hat = fr.T_bar
            O[O == 1] = -1
        quality = dict(fitness=res.fitness, inlier_rmse=res.rmse, n_points=fr.n_sel, iterations=res.iterations,
                       n_inliers=res.n_inliers)
        return self._emit(fr, T_hat, O, S_hat, res.cov, lost=lost, accepted=accepted, quality=quality, cal=cal)

    def _held(self, fr):
        """The registered pose with the directions the points cannot see (a revolved object's axis,
        a face whose edges are hidden) kept at the prediction, and those directions for the filter,
        which integrates no velocity along them: ``(T_hat, hold)``, hold None when there are none."""
        res, T_bar = fr.res, fr.T_bar
        T_hat, hold = res.T, None
        if self.registration.hold_unobserved:
            U, rho = unobserved_directions(self.model_, res.support, res.cov)
            U = _with_axes(U, self.symmetry_axes_)
            if U.shape[1]:
                hold = (U, np.array([rho, rho, rho, 1.0, 1.0, 1.0]))
                es = se3_log(inv_pose(T_bar) @ res.T) * hold[1]
                T_hat = T_bar @ se3_exp((es - U @ (U.T @ es)) / hold[1])
        self.n_unobserved_ = 0 if hold is None else hold[0].shape[1]
        return T_hat, hold

    def _labels(self, fr, T, vis=None):
        return pixels.labels(self.model_, self.K_, self.image_shape_, fr.D, fr.roi, T, vis)

    def _train(self, fr, O, S, r):
        """One online update of the appearance model from the labels O (spec 4.3)."""
        app, rng = self.appearance_model_, self.rng_
        if app.name == "h":
            ys, xs = np.nonzero(O >= 0)
            app.update(fr.feats, ys, xs, O[ys, xs], np.ones(len(ys)), rng)
            return
        picked = pixels.training_pixels(O, S, r, fr.D, self.learning.n_samples, rng)
        if picked is not None:
            app.update(fr.feats, *picked, rng)

    def _coast(self, fr):
        """No usable registration: keep the prediction, damp the velocity, label at the prediction."""
        self.filter_.coast(velocity_decay=self.motion.velocity_decay)
        self.rejections_ += 1
        cov = self.filter_.pose_cov
        quality = dict(fitness=0.0, inlier_rmse=float("nan"), n_points=fr.n_sel, iterations=0, n_inliers=0)
        if fr.D is None:
            return self._emit(fr, fr.T_bar, None, None, cov, lost=True, accepted=False, quality=quality)
        O, S, _ = self._labels(fr, fr.T_bar)
        O[O == 1] = -1  # nothing is confidently target without a registration
        quality["iterations"] = fr.res.iterations if fr.res is not None else 0
        return self._emit(fr, fr.T_bar, O, S, cov, lost=True, accepted=False, quality=quality)

    def _calibrated(self, Pmap):
        if self.calibration_ is None or Pmap is None:
            return Pmap
        return self.calibration_(_logit(Pmap))

    def _emit(self, fr, T_cen, O, S, cov, *, lost, accepted, quality, cal=None):
        """The fields of a :class:`TrackResult`: the ROI maps pasted into full images."""
        H, W = self.image_shape_
        x0, y0, x1, y1 = fr.roi
        labels = np.zeros((H, W), np.int8)
        mask = np.zeros((H, W), bool)
        prob = np.zeros((H, W), np.float32)
        prob_raw = np.zeros((H, W), np.float32)
        if x1 > x0 and y1 > y0:
            labels[y0:y1, x0:x1] = O
            inner = cv2.erode(S, disc(1), borderType=cv2.BORDER_CONSTANT, borderValue=1) > 0
            und = (O == -1) & inner & ~(fr.D > 0)
            if fr.lI is not None and fr.gamma > 0:
                und &= fr.lI > 0
            if not lost or accepted:
                mask[y0:y1, x0:x1] = (O == 1) | und
            prob[y0:y1, x0:x1] = self._calibrated(fr.Pmap) if cal is None else cal
            prob_raw[y0:y1, x0:x1] = fr.Pmap
        extra = self._debug_maps(fr, S) if self.debug_maps else {}
        return dict(pose=T_cen @ self.T_cen_obj_, mask=mask, prob=prob, labels=labels, time_s=0.0, lost=bool(lost),
                    accepted=bool(accepted), covariance=np.array(cov, dtype=float),
                    pose_filtered=self.filter_.T @ self.T_cen_obj_,
                    pose_predicted=self.filter_.T_bar @ self.T_cen_obj_, roi=tuple(int(v) for v in fr.roi),
                    gamma=float(fr.gamma), prob_raw=prob_raw, n_unobserved=int(self.n_unobserved_),
                    fitness=float(quality["fitness"]), inlier_rmse=float(quality["inlier_rmse"]),
                    n_points=int(quality["n_points"]), iterations=int(quality["iterations"]),
                    n_inliers=int(quality["n_inliers"]), **extra)

    def _debug_maps(self, fr, S):
        """The attention, appearance and silhouette ``S`` maps as full images (``debug_maps=True``)."""
        H, W = self.image_shape_
        x0, y0, x1, y1 = fr.roi
        att = np.zeros((H, W), np.float32)
        app = np.full((H, W), np.nan, np.float32)
        sil = np.zeros((H, W), bool)
        if x1 > x0 and y1 > y0:
            att[y0:y1, x0:x1] = fr.pi
            if fr.lI is not None:
                app[y0:y1, x0:x1] = 0.5 * (1.0 + np.tanh(0.5 * fr.lI))
            sil[y0:y1, x0:x1] = S > 0
        return dict(attention=att, appearance=app, silhouette=sil)
