"""ObjectTracker: self-supervised object segmentation and 6-DoF tracking (spec 2, 3, 6).

One frame: predict the pose (motion filter) -> project the model (visibility, silhouette, ROI)
-> attention prior x depth likelihood x appearance likelihood = prediction map -> weighted robust
ICP of the highly probable points -> labels O of all ROI points off the registered model -> drift
guard -> online appearance update -> filter update.
"""

from __future__ import annotations

import logging
import numbers
import time
from dataclasses import dataclass

import cv2
import numpy as np

from polar_sim._validation import as_intrinsics, as_pose, as_positive_float, check_choice
from polar_sim.geometry import inv_pose, make_pose, se3_exp, se3_log
from polar_sim.params import Parameterised
from polar_sim.tracking._checks import as_model_points, as_normals, as_rgbd
from polar_sim.tracking._kernels import roi_distances
from polar_sim.tracking.appearance import make_appearance
from polar_sim.tracking.calibration import OnlineCalibration
from polar_sim.tracking.icp import symmetry_directions, unobserved_directions, weighted_icp
from polar_sim.tracking.model import ShapeModel, estimate_normals
from polar_sim.tracking.motion import MotionFilter
from polar_sim.tracking.visibility import disc, project_model, splat_depth, splat_silhouette

__all__ = ["ObjectTracker", "TrackResult", "APPEARANCE_VARIANTS"]

logger = logging.getLogger(__name__)

#: Values of the ``appearance`` parameter: the colour Naive Bayes, the S/W x u/w feature heads, none.
APPEARANCE_VARIANTS = ("h", "su", "sw", "wu", "ww", "none")
_LOGIT_CLIP = 8.0
KAPPA = 3.0
#: Pose spread assumed by the second E-step (em_refine): 3 mm and 1 degree.
_EM_SIGMA_TR = 0.003
_EM_SIGMA_ROT = np.deg2rad(1.0)
#: Longest frame interval the motion filter predicts over, s (see :meth:`ObjectTracker.process`).
MAX_GAP_S = 1.0


@dataclass(frozen=True)
class TrackResult:
    """Output of :meth:`ObjectTracker.process` for one frame.

    Attributes
    ----------
    pose : (4, 4) T_cam_obj, the registration output (the prediction when the frame was lost).
    mask : (H, W) bool target segmentation (O == 1, plus undecided pixels without depth inside
        the registered silhouette that the appearance model calls target); empty when the frame
        had no usable registration.
    prob : (H, W) float32 P(target): the prediction map P(L=1 | I, D, T_bar), calibrated online
        against the tracker's own labels (``calibrate=True``; see
        :mod:`polar_sim.tracking.calibration`), 0 outside the ROI.
    labels : (H, W) int8 O: 1 target, 0 not target, -1 undecided.
    fitness : prior-weighted fraction of registered points within the inlier band.
    inlier_rmse : m (NaN when the frame was lost).
    n_points : points registered.
    time_s : wall time of the call, s.
    lost : no usable registration (object out of view, fully occluded, ICP failed or jumped) or
        ``lost_after`` rejected frames in a row.
    accepted : the frame passed the drift guard and trained the appearance model.
    covariance : (6, 6) registration covariance of the body twist (omega rad, v m) about the model
        centroid in object axes; the filter's pose covariance when lost.
    pose_filtered, pose_predicted : (4, 4) T_cam_obj of the motion filter after / before the update.
    roi : (x0, y0, x1, y1) pixels processed (x1, y1 exclusive).
    gamma : weight of the appearance term this frame.
    iterations, n_inliers : ICP iterations and inliers.
    stage_times : wall time per pipeline stage, s (validate, predict_attention, depth_likelihood,
        appearance, registration, labels, learning, output).
    attention, appearance, silhouette : (H, W) maps (debug_maps=True only, else None): the spatial
        prior pi, the appearance probability sigmoid(log Lambda_I), the registered silhouette.
    prob_raw : (H, W) float32 the prediction map before calibration (what the registration
        thresholds at ``tau_y``).
    n_unobserved : pose directions the registered points did not constrain this frame (held
        at the prediction, see ``hold_unobserved``).
    """

    pose: np.ndarray
    mask: np.ndarray
    prob: np.ndarray
    labels: np.ndarray
    fitness: float
    inlier_rmse: float
    n_points: int
    time_s: float
    lost: bool
    accepted: bool
    covariance: np.ndarray
    pose_filtered: np.ndarray
    pose_predicted: np.ndarray
    roi: tuple
    gamma: float
    iterations: int
    n_inliers: int
    stage_times: dict | None = None
    attention: np.ndarray | None = None
    appearance: np.ndarray | None = None
    silhouette: np.ndarray | None = None
    prob_raw: np.ndarray | None = None
    n_unobserved: int = 0


class _Clock:
    """Accumulates wall time per pipeline stage (perf_counter laps)."""

    def __init__(self):
        self.t = time.perf_counter()
        self.stages = {}

    def lap(self, name):
        now = time.perf_counter()
        self.stages[name] = self.stages.get(name, 0.0) + now - self.t
        self.t = now


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
    motion : {"ekf", "alpha-beta", "none"}, default="ekf"
        Constant-velocity filter; "none" predicts the last pose (motion-prior-off ablation).
    spatial_prior : bool, default=False
        Blurred predicted silhouette as the prior pi (the spec's form, with floor ``epsilon``);
        False gives pi = 0.5 in the ROI, which the ROI (the predicted silhouette's box, grown by
        3 sigma) still bounds. Off by default since issue 13: at epsilon = 0.02 the prior's
        log-odds (+-3.9) outweighs the depth term (at most +3.1), so wherever the prediction is off
        the map copies the predicted silhouette and a mispredicted object cannot re-enter the
        registration; chosen on the dev split, where no prior and a softened one (epsilon = 0.1)
        score alike (see benchmarks/RESULTS.md).
    registration : {"weighted", "plain"}, default="weighted"
        "plain": robust ICP on every ROI point with depth (no label weighting) - the baseline.
    correspondence : {"grid", "kdtree"}, default="grid"
        Nearest visible model point from the precomputed k-NN lookup grid, or the cKDTree itself.
    fps : float, default=30
        Frame rate used when ``process`` gets no time stamp.
    n_registration : int, default=3000
        N_Y, maximum number of points registered.
    tau_y : float, default=0.5
        Threshold on P for the highly probable points.
    k_warm : int, default=5
        Appearance ramp-in: gamma = min(1, accepted updates / k_warm).
    epsilon : float, default=0.02
        Floor and ceiling of the attention prior.
    sigma_min_px : float, default=3
        Minimum attention blur, pixels.
    fitness_min : float, default=0.5
        Drift guard: minimum fitness for learning.
    min_inliers : int, default=50
        Drift guard: minimum inliers for learning.
    min_coverage : float, default=0.1
        Inliers per expected pixel (see ``coverage``) below which the registration is not used and
        the frame counts towards lost (object out of view, or the fit is elsewhere).
    coverage : {"visible", "silhouette"}, default="visible"
        Which pixels of the predicted silhouette (with valid depth) ``min_coverage`` counts as
        expected: ``"visible"`` leaves out those where something is seen in front of the predicted
        surface (by more than 3 sigma of depth noise and pose spread, at least 1 cm: a hand or
        another object), so a mostly hidden object whose visible part fits is tracked, not lost;
        ``"silhouette"`` counts them all (the behaviour before, which declares an object lost once
        about 85 % of it is hidden).
    learn_coverage : float, default=0.25
        Drift guard: inliers per valid-depth pixel of the whole predicted silhouette, hidden pixels
        included, must reach this for the frame to train the appearance model (a mostly hidden
        object gives labels too few and too uncertain to learn from).
    max_jump : (float, float), default=(0.5, 0.1)
        Largest accepted change from the prediction: rotation (rad) and centroid translation (m).
    max_mahalanobis : float, default=50
        Largest squared Mahalanobis distance of the registration from the prediction, under the
        predicted covariance (6 dof; about 7 sigma along one axis). A registration that jumps
        further (onto the hand after a full occlusion, say) is not used; the filter's covariance
        grows while it coasts, so the gate widens for re-acquisition. ``np.inf`` disables it.
    lost_after : int, default=10
        Rejected frames in a row after which the appearance term is switched off until a frame is
        accepted.
    lost_velocity_decay : float, default=0.5
        Factor applied to the filter's velocity on each frame without a registration.
    decay : float, default=0.7
        Histogram fading of the "h" model.
    lr, epochs, replay, n_samples : Adam learning rate, epochs per accepted frame, replay buffer
        (frames), maximum positives (and negatives) sampled per frame for the feature heads.
    max_iterations : int, default=30
        ICP iterations.
    em_refine : bool, default=True
        When the registration lands more than 2 predicted standard deviations from the prediction,
        redo the prediction map at the registered pose (3 mm / 1 deg spread) and register again:
        a second EM step (spec 2) that rescues fast motion.
    pose_prior : bool, default=True
        Register as a MAP estimate with the motion filter's prediction as the prior (its 6x6
        covariance): directions the visible points leave unconstrained keep the prediction.
    hold_unobserved : bool, default=True
        Probe the registration's least certain directions (:func:`polar_sim.tracking.icp.unobserved_directions`):
        along a direction in which moving the model does not change its fit to the points (a
        revolved object turning about its axis; a flat face whose boundary is hidden), the pose
        keeps the prediction and the filter's velocity is zeroed, so an object at rest stays at
        rest where its shape cannot see. Rotations that map the whole model onto itself (a
        revolved object's axis, found once from the model by
        :func:`polar_sim.tracking.icp.symmetry_directions`) are held on every frame: no data the
        registration is given, a touching hand's points included, can observe them.
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
    The module contract (:class:`polar_sim.params.Parameterised`): the constructor stores the
    parameters above as given and checks them (``_check_params``, the one place, also used by
    ``set_params`` and the first frame); ``get_params()``/``set_params()``; the state is created
    by the first :meth:`process` in attributes ending in ``_`` (``model_``, ``filter_``,
    ``appearance_model_``, ``calibration_``, ``symmetry_axes_``, ``rng_``, ``pose_``, ``n_frames_``, ...) and
    :meth:`reset` removes it.
    """

    def __init__(self, model_points, K, initial_pose, *, model_normals=None, appearance="ww",
                 motion="ekf", spatial_prior=False, registration="weighted", correspondence="grid",
                 fps=30.0, n_registration=3000, tau_y=0.5, k_warm=5, epsilon=0.02, sigma_min_px=3.0,
                 fitness_min=0.5, min_inliers=50, min_coverage=0.1, coverage="visible", learn_coverage=0.25,
                 max_jump=(0.5, 0.1),
                 max_mahalanobis=50.0,
                 lost_after=10, lost_velocity_decay=0.5, decay=0.7, lr=1e-2, epochs=2, replay=10,
                 n_samples=500, max_iterations=30, em_refine=True, pose_prior=True, hold_unobserved=True,
                 calibrate=True, random_state=0, debug_maps=False):
        self.model_points = model_points
        self.K = K
        self.initial_pose = initial_pose
        self.model_normals = model_normals
        self.appearance = appearance
        self.motion = motion
        self.spatial_prior = spatial_prior
        self.registration = registration
        self.correspondence = correspondence
        self.fps = fps
        self.n_registration = n_registration
        self.tau_y = tau_y
        self.k_warm = k_warm
        self.epsilon = epsilon
        self.sigma_min_px = sigma_min_px
        self.fitness_min = fitness_min
        self.min_inliers = min_inliers
        self.min_coverage = min_coverage
        self.coverage = coverage
        self.learn_coverage = learn_coverage
        self.max_jump = max_jump
        self.max_mahalanobis = max_mahalanobis
        self.lost_after = lost_after
        self.lost_velocity_decay = lost_velocity_decay
        self.decay = decay
        self.lr = lr
        self.epochs = epochs
        self.replay = replay
        self.n_samples = n_samples
        self.max_iterations = max_iterations
        self.em_refine = em_refine
        self.pose_prior = pose_prior
        self.hold_unobserved = hold_unobserved
        self.calibrate = calibrate
        self.random_state = random_state
        self.debug_maps = debug_maps
        # fail early: the same checks as every later use (no state is built here)
        self._check_params()

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
        check_choice(self.motion, ("ekf", "alpha-beta", "none"), "motion")
        check_choice(self.registration, ("weighted", "plain"), "registration")
        check_choice(self.correspondence, ("grid", "kdtree"), "correspondence")
        check_choice(self.coverage, ("visible", "silhouette"), "coverage")
        for name in ("spatial_prior", "em_refine", "pose_prior", "hold_unobserved", "calibrate", "debug_maps"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"{name}: expected True or False, got {getattr(self, name)!r}")
        for name in ("fps", "sigma_min_px", "lr", "max_mahalanobis"):
            as_positive_float(getattr(self, name), name)
        ranges = {"tau_y": (0.0, 1.0, False), "epsilon": (0.0, 0.5, False), "fitness_min": (0.0, 1.0, True),
                  "min_coverage": (0.0, 1.0, True), "learn_coverage": (0.0, 1.0, True),
                  "lost_velocity_decay": (0.0, 1.0, True),
                  "decay": (0.0, 1.0, True)}
        for name, (lo, hi, closed) in ranges.items():
            v = as_positive_float(getattr(self, name), name, allow_zero=True)
            if not (lo <= v <= hi if closed else lo < v < hi):
                br = "[]" if closed else "()"
                raise ValueError(f"{name}: expected a value in {br[0]}{lo}, {hi}{br[1]}, got {v}")
        for name, lo in (("n_registration", 6), ("k_warm", 1), ("min_inliers", 0), ("lost_after", 1),
                         ("epochs", 0), ("replay", 1), ("n_samples", 1), ("max_iterations", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < lo:
                raise ValueError(f"{name}: expected an integer >= {lo}, got {v!r}")
        rs = self.random_state
        if isinstance(rs, bool) or not isinstance(rs, numbers.Integral) or rs < 0:
            raise ValueError(f"random_state: expected an integer seed >= 0, got {rs!r}")
        mj = np.asarray(self.max_jump, dtype=float)
        if mj.shape != (2,) or not np.all(np.isfinite(mj)) or np.any(mj <= 0):
            raise ValueError(f"max_jump: expected (rotation rad, translation m) > 0, got {self.max_jump!r}")
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
        self.filter_ = MotionFilter(c["T0"] @ self.T_obj_cen_, mode=self.motion, sigma_cap=cap)
        kw = dict(decay=self.decay, lr=self.lr, epochs=self.epochs, replay=self.replay)
        self.appearance_model_ = make_appearance(self.appearance, **kw)
        self.rng_ = np.random.default_rng(self.random_state)
        self.calibration_ = OnlineCalibration() if self.calibrate else None
        # rotations that map the whole model onto itself (a revolved object's axis): held always
        self.symmetry_axes_ = symmetry_directions(m) if self.hold_unobserved else np.zeros((6, 0))
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
            is predicted as 1 s.

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

    # ------------------------------------------------------------------------------------------
    def _step(self, rgb, depth, dt):
        m, K = self.model_, self.K_
        H, W = self.image_shape_
        f = float(K[0, 0])
        filt = self.filter_
        self.n_unobserved_ = 0
        T_bar, P_bar = filt.predict(dt)
        sig_rot = float(np.sqrt(max(np.linalg.eigvalsh(P_bar[:3, :3]).max(), 0.0)))
        sig_tr = float(np.sqrt(max(np.linalg.eigvalsh(P_bar[3:, 3:]).max(), 0.0)))
        sig_pos = sig_tr + 0.5 * m.diameter * sig_rot
        proj = project_model(m.P, m.N, T_bar[:3, :3], T_bar[:3, 3], K, (H, W), m.spacing)
        lost_mode = self.rejections_ >= self.lost_after
        gamma = 0.0
        if self.appearance_model_ is not None and not lost_mode:
            gamma = min(1.0, self.appearance_model_.n_updates / self.k_warm)
        if proj.vis.sum() < 3:
            return self._coast(T_bar, (0, 0, 0, 0), gamma)

        # -- attention: silhouette, prior, ROI ------------------------------------------------
        zb = proj.z_mean
        sigma_px = max(self.sigma_min_px, f * sig_pos / zb)
        r_s = int(max(1, np.ceil(f * m.spacing / zb)))
        pad = int(np.ceil(max(20.0, 3.0 * sigma_px))) + r_s
        uvv = proj.uv[proj.vis]
        x0 = int(max(0, np.floor(uvv[:, 0].min()) - pad))
        y0 = int(max(0, np.floor(uvv[:, 1].min()) - pad))
        x1 = int(min(W, np.ceil(uvv[:, 0].max()) + pad + 1))
        y1 = int(min(H, np.ceil(uvv[:, 1].max()) + pad + 1))
        roi = (x0, y0, x1, y1)
        D = depth[y0:y1, x0:x1]
        valid = D > 0
        self.clock_.lap("predict_attention")
        # -- appearance ---------------------------------------------------------------------
        feats = None
        lI = None
        if self.appearance_model_ is not None:
            feats = self.appearance_model_.prepare(np.ascontiguousarray(rgb[y0:y1, x0:x1]))
            if gamma > 0 or self.debug_maps:
                lI = self.appearance_model_.log_ratio(feats)
        self.clock_.lap("appearance")
        # -- prediction map (E-step) and registration (M-step) ----------------------------------
        Pmap, pi, S = self._prediction_map(D, roi, T_bar, proj, sig_pos, lI, gamma)
        self.clock_.lap("depth_likelihood")
        res, n_sel, n_cand = self._register(D, roi, Pmap, T_bar, proj.vis, sig_pos)
        at = (proj, sig_pos)  # the projection and pose spread that the silhouette S is of
        if res is not None and res.ok and self.em_refine:
            # a registration far outside the predicted spread was made with a prior centred on the
            # wrong place: redo the E-step at the registered pose with a tight spread, register again
            d_rot = _rot_angle(T_bar[:3, :3].T @ res.T[:3, :3]) / max(sig_rot, 1e-6)
            d_tr = float(np.linalg.norm(res.T[:3, 3] - T_bar[:3, 3])) / max(sig_tr, 1e-6)
            if d_rot**2 + d_tr**2 > 4.0:
                proj2 = project_model(m.P, m.N, res.T[:3, :3], res.T[:3, 3], K, (H, W), m.spacing)
                if proj2.vis.sum() >= 3:
                    sig2 = _EM_SIGMA_TR + 0.5 * m.diameter * _EM_SIGMA_ROT
                    Pmap2, pi2, S2 = self._prediction_map(D, roi, res.T, proj2, sig2, lI, gamma)
                    res2, n_sel2, n_cand2 = self._register(D, roi, Pmap2, res.T, proj2.vis, sig2)
                    if res2 is not None and res2.ok:
                        res, n_sel, n_cand, Pmap, pi, S = res2, n_sel2, n_cand2, Pmap2, pi2, S2
                        at = (proj2, sig2)
        self.clock_.lap("registration")
        # -- drift guard ----------------------------------------------------------------------
        measured = res is not None and res.ok and res.n_matched >= 6
        coverage = 0.0
        if measured:
            rot_jump = _rot_angle(T_bar[:3, :3].T @ res.T[:3, :3])
            tr_jump = float(np.linalg.norm(res.T[:3, 3] - T_bar[:3, 3]))
            seen = valid & (S > 0)
            expected = max(int(np.count_nonzero(seen)), 1)
            scale = n_cand / max(n_sel, 1)
            coverage = res.n_inliers * scale / expected
            if self.coverage == "visible":
                # an occluder is no evidence against the pose: count only the unhidden pixels
                hidden = seen & self._in_front(D, roi, *at)
                tracked = res.n_inliers * scale / max(expected - int(np.count_nonzero(hidden)), 1)
            else:
                tracked = coverage
            e = se3_log(inv_pose(T_bar) @ res.T)
            S_e = self.filter_.P_bar[:6, :6] + np.diag(self.filter_.floor)
            d2 = float(e @ np.linalg.solve(S_e, e))
            measured = (rot_jump < self.max_jump[0] and tr_jump < self.max_jump[1]
                        and d2 < self.max_mahalanobis and tracked >= self.min_coverage)
        if not measured:
            return self._coast(T_bar, roi, gamma, D=D, Pmap=Pmap, pi=pi, lI=lI, n_points=n_sel, res=res)
        good_fit = res.fitness >= self.fitness_min and res.n_inliers >= self.min_inliers
        accepted = good_fit and coverage >= self.learn_coverage
        T_hat, hold = res.T, None
        if self.hold_unobserved:
            # directions the points cannot see (a revolved object's axis, a face whose edges are
            # hidden) keep the prediction, and the filter integrates no velocity along them
            U, rho = unobserved_directions(m, res.support, res.cov)
            U = _with_axes(U, self.symmetry_axes_)
            if U.shape[1]:
                hold = (U, np.array([rho, rho, rho, 1.0, 1.0, 1.0]))
                es = se3_log(inv_pose(T_bar) @ res.T) * hold[1]
                T_hat = T_bar @ se3_exp((es - U @ (U.T @ es)) / hold[1])
        self.n_unobserved_ = 0 if hold is None else hold[0].shape[1]
        O, S_hat, r_hat = self._labels(D, roi, T_hat, vis=res.vis)
        self.clock_.lap("labels")
        cal = self._calibrated(Pmap)  # the prediction, before this frame's labels are learned
        if accepted and self.calibration_ is not None:
            z = _logit(Pmap[O >= 0])
            self.calibration_.update(z, O[O >= 0] == 1)
        if accepted and self.appearance_model_ is not None:
            self._train(feats, O, S_hat, r_hat, D)
        self.clock_.lap("learning")
        # a good fit updates the filter (a mostly hidden object only skips learning); a poor fit is
        # reported (spec 3.7) but not fused: the filter coasts (widened x4, velocity damped) and
        # the frame counts towards lost mode, in which the prediction is reported instead
        if good_fit:
            filt.update(T_hat, res.cov, dt, hold=hold)
            self.rejections_ = 0
        else:
            filt.coast(velocity_decay=self.lost_velocity_decay, inflate=4.0)
            self.rejections_ += 1
        lost = self.rejections_ >= self.lost_after
        if lost:
            T_hat = T_bar
            O[O == 1] = -1
        return self._emit(T_hat, roi, O, S_hat, Pmap, pi, lI, valid, gamma, res.fitness, res.rmse,
                          n_sel, lost, accepted, res.cov, res.iterations, res.n_inliers, cal=cal)

    # ------------------------------------------------------------------------------------------
    def _prediction_map(self, D, roi, T, proj, sig_pos, lI, gamma):
        """Prediction map P (h, w), prior pi (h, w) and silhouette S (h, w) around pose T (spec 3.3-3.4)."""
        m, f = self.model_, float(self.K_[0, 0])
        zb = proj.z_mean
        S = splat_silhouette(proj.uv[proj.vis], zb, f, m.local_spacing[proj.vis], roi)
        if self.spatial_prior:
            sigma_px = max(self.sigma_min_px, f * sig_pos / zb)
            blur = cv2.GaussianBlur(S.astype(np.float32), (0, 0), sigma_px)
            pi = self.epsilon + (1.0 - 2.0 * self.epsilon) * blur
            logit = np.log(pi / (1.0 - pi))
        else:
            pi = np.full(D.shape, 0.5, np.float32)
            logit = np.zeros(D.shape, np.float32)
        # depth likelihood ratio against the visible surface at T: log of N(r; 0, sigma_r) / c_0,
        # with c_0 putting the ratio at 1 for r = 2.5 sigma_r
        dist = self._distances(D, roi, T, proj.vis, KAPPA)
        sig_d = (0.0012 + 0.0019 * (D - 0.4) ** 2).astype(np.float32)
        sr2 = sig_d * sig_d + np.float32(sig_pos * sig_pos)
        with np.errstate(invalid="ignore", over="ignore"):
            ld = np.float32(0.5 * 2.5**2) - dist * dist / (2.0 * sr2)
        ld = np.where(D > 0, np.nan_to_num(ld, nan=0.0, neginf=-2 * _LOGIT_CLIP), 0.0)
        logit = logit + ld
        if lI is not None and gamma > 0:
            logit = logit + np.float32(gamma) * lI
        logit = np.clip(logit, -_LOGIT_CLIP, _LOGIT_CLIP).astype(np.float32)
        return (0.5 * (1.0 + np.tanh(0.5 * logit))).astype(np.float32), pi, S

    def _in_front(self, D, roi, proj, sig_pos):
        """(h, w) bool: valid depth nearer than the model's surface (splatted from the visible
        points of ``proj``, its projection at a pose) by more than 3 sigma of depth noise and pose
        spread ``sig_pos`` (m), and at least 1 cm."""
        m, f = self.model_, float(self.K_[0, 0])
        r = int(max(1, np.ceil(f * m.spacing / proj.z_mean)))
        Z = splat_depth(proj.uv[proj.vis], proj.Pc[proj.vis, 2], r, roi)
        sig_d = 0.0012 + 0.0019 * (D - 0.4) ** 2
        band = np.maximum(3.0 * np.sqrt(sig_d * sig_d + sig_pos * sig_pos), 0.01)
        return (D > 0) & (D < Z - band)

    def _register(self, D, roi, Pmap, T_init, vis, sig_pos):
        """Select the highly probable points and run the weighted ICP from T_init (spec 3.5).

        Returns the ICP result (None with fewer than 6 points), the points registered and the
        candidates before subsampling."""
        m = self.model_
        valid = D > 0
        if self.registration == "plain":
            cand = np.flatnonzero(valid)
            w_all = np.ones(len(cand))
        else:
            cand = np.flatnonzero(valid & (Pmap > self.tau_y))
            w_all = Pmap.ravel()[cand].astype(np.float64)
        n_cand = len(cand)
        if n_cand > self.n_registration:
            # weighted sampling without replacement (Efraimidis-Spirakis): the k largest
            # log(u) / w, one uniform draw per candidate, O(n)
            keys = np.log(self.rng_.random(n_cand)) / np.maximum(w_all, 1e-12)
            pick = np.sort(np.argpartition(-keys, self.n_registration - 1)[: self.n_registration])
            cand, w0 = cand[pick], w_all[pick]
        else:
            w0 = w_all
        if len(cand) < 6:
            return None, len(cand), n_cand
        X, zc = self._backproject(D, roi, cand)
        sd = 0.0012 + 0.0019 * (zc - 0.4) ** 2
        gate0 = min(max(3.0 * float(np.sqrt(np.median(sd**2) + sig_pos**2)), 0.015), m.margin)
        gate_floor = min(max(3.0 * float(np.median(sd)), m.spacing), gate0)
        prior = None
        if self.pose_prior:
            T_pred, P_pred = self.filter_.T_bar, self.filter_.P_bar[:6, :6]
            prior = (T_pred, np.linalg.inv(P_pred + 1e-12 * np.eye(6)))
        res = weighted_icp(X, w0, m, T_init, self.K_, self.image_shape_, sigma_d=sd,
                           delta1=np.maximum(3 * sd, 0.006), gate0=gate0, gate_floor=gate_floor,
                           max_iterations=self.max_iterations, exact=self.correspondence == "kdtree",
                           vis_init=vis, prior=prior)
        return res, len(cand), n_cand

    def _distances(self, D, roi, T, vis, kappa=1.0):
        m, K = self.model_, self.K_
        Ti = np.linalg.inv(T)
        D = np.ascontiguousarray(D, np.float32)  # one layout: a crop would compile the kernel twice
        out = np.empty(D.shape, np.float32)
        roi_distances(D, roi[0], roi[1], K[0, 0], K[1, 1], K[0, 2], K[1, 2],
                      np.ascontiguousarray(Ti[:3, :3]), np.ascontiguousarray(Ti[:3, 3]),
                      m.origin, m.inv_h, m.knn, m.P, m.N, vis, float(kappa), m.slack, out)
        return out

    def _backproject(self, D, roi, flat):
        K = self.K_
        w = D.shape[1]
        v, u = np.divmod(flat, w)
        z = D.ravel()[flat].astype(np.float64)
        x = (u + roi[0] - K[0, 2]) / K[0, 0] * z
        y = (v + roi[1] - K[1, 2]) / K[1, 1] * z
        return np.stack([x, y, z], axis=1), z

    def _labels(self, D, roi, T, vis=None):
        """Labels O (h, w) int8, silhouette (h, w) uint8 and distances (h, w) at pose T (spec 3.6)."""
        m, K = self.model_, self.K_
        pr = project_model(m.P, m.N, T[:3, :3], T[:3, 3], K, self.image_shape_, m.spacing, zbuffer=vis is None)
        if vis is not None:
            pr.vis = vis
        S = splat_silhouette(pr.uv[pr.vis], pr.z_mean, K[0, 0], m.local_spacing[pr.vis], roi)
        inner = cv2.erode(S, disc(1), borderType=cv2.BORDER_CONSTANT, borderValue=1) > 0
        outer = cv2.dilate(S, disc(2)) > 0
        # distances only where they can matter: inside the dilated silhouette's bounding box
        r = np.full(D.shape, np.inf, np.float32)
        ys, xs = np.nonzero(outer.any(axis=1))[0], np.nonzero(outer.any(axis=0))[0]
        if len(ys):
            a0, a1, b0, b1 = ys[0], ys[-1] + 1, xs[0], xs[-1] + 1
            sub = (roi[0] + b0, roi[1] + a0, roi[0] + b1, roi[1] + a1)
            r[a0:a1, b0:b1] = self._distances(np.ascontiguousarray(D[a0:a1, b0:b1]), sub, T, pr.vis)
        sig_d = 0.0012 + 0.0019 * (D - 0.4) ** 2
        d1 = np.maximum(3.0 * sig_d, 0.006)
        O = np.full(D.shape, -1, np.int8)
        with np.errstate(invalid="ignore"):
            O[~outer | (r > 0.015)] = 0
            O[inner & (r < d1)] = 1
        return O, S, r

    def _train(self, feats, O, S, r, D):
        rng = self.rng_
        h, w = O.shape
        app = self.appearance_model_
        if app.name == "h":
            ys, xs = np.nonzero(O >= 0)
            lab = O[ys, xs]
            app.update(feats, ys, xs, lab, np.ones(len(ys)), rng)
            return
        n = self.n_samples
        pos = np.flatnonzero(O.ravel() == 1)
        # hard negatives: a band 30 px wide around the silhouette (square kernel: separable, fast)
        ring = (cv2.dilate(S, np.ones((61, 61), np.uint8)) > 0) & (S == 0)
        neg0 = O.ravel() == 0
        neg_ring = np.flatnonzero(neg0 & ring.ravel())
        neg_rest = np.flatnonzero(neg0 & ~ring.ravel())
        if len(pos) < 10 or len(neg_ring) + len(neg_rest) < 10:
            return
        pos = rng.choice(pos, min(n, len(pos)), replace=False)
        k_ring = min(len(neg_ring), (2 * n) // 3)
        k_rest = min(len(neg_rest), n - k_ring)
        neg = np.concatenate([rng.choice(neg_ring, k_ring, replace=False),
                              rng.choice(neg_rest, k_rest, replace=False)])
        flat = np.concatenate([pos, neg])
        ys, xs = np.divmod(flat, w)
        lab = np.concatenate([np.ones(len(pos), np.int8), np.zeros(len(neg), np.int8)])
        sig_d = 0.0012 + 0.0019 * (D.ravel()[pos] - 0.4) ** 2
        d1 = np.maximum(3.0 * sig_d, 0.006)
        wpos = np.clip(1.0 - r.ravel()[pos] / d1, 0.1, 1.0)
        weights = np.concatenate([wpos, np.ones(len(neg))])
        app.update(feats, ys, xs, lab, weights, rng)

    def _coast(self, T_bar, roi, gamma, *, D=None, Pmap=None, pi=None, lI=None, n_points=0, res=None):
        """No usable registration: keep the prediction, damp the velocity, label at the prediction."""
        self.filter_.coast(velocity_decay=self.lost_velocity_decay)
        self.rejections_ += 1
        cov = self.filter_.pose_cov
        if D is None:
            z = np.zeros((0, 0), np.float32)
            return self._emit(T_bar, (0, 0, 0, 0), np.zeros((0, 0), np.int8), z.astype(np.uint8), z,
                              None, None, z > 0, gamma, 0.0, float("nan"), 0, True, False, cov, 0, 0)
        O, S, _ = self._labels(D, roi, T_bar)
        O[O == 1] = -1  # nothing is confidently target without a registration
        it = res.iterations if res is not None else 0
        return self._emit(T_bar, roi, O, S, Pmap, pi, lI, D > 0, gamma, 0.0, float("nan"), n_points,
                          True, False, cov, it, 0)

    def _calibrated(self, Pmap):
        if self.calibration_ is None or Pmap is None:
            return Pmap
        return self.calibration_(_logit(Pmap))

    def _emit(self, T_cen, roi, O, S, Pmap, pi, lI, valid, gamma, fitness, rmse, n_points, lost,
              accepted, cov, iterations, n_inliers, cal=None):
        H, W = self.image_shape_
        x0, y0, x1, y1 = roi
        labels = np.zeros((H, W), np.int8)
        mask = np.zeros((H, W), bool)
        prob = np.zeros((H, W), np.float32)
        prob_raw = np.zeros((H, W), np.float32)
        if cal is None:
            cal = self._calibrated(Pmap)
        if x1 > x0 and y1 > y0:
            labels[y0:y1, x0:x1] = O
            inner = cv2.erode(S, disc(1), borderType=cv2.BORDER_CONSTANT, borderValue=1) > 0
            und = (O == -1) & inner & ~valid
            if lI is not None and gamma > 0:
                und &= lI > 0
            if not lost or accepted:
                mask[y0:y1, x0:x1] = (O == 1) | und
            prob[y0:y1, x0:x1] = cal
            prob_raw[y0:y1, x0:x1] = Pmap
        extra = {}
        if self.debug_maps:
            att = np.zeros((H, W), np.float32)
            app = np.full((H, W), np.nan, np.float32)
            sil = np.zeros((H, W), bool)
            if x1 > x0 and y1 > y0:
                att[y0:y1, x0:x1] = pi
                if lI is not None:
                    app[y0:y1, x0:x1] = 0.5 * (1.0 + np.tanh(0.5 * lI))
                sil[y0:y1, x0:x1] = S > 0
            extra = dict(attention=att, appearance=app, silhouette=sil)
        pose = T_cen @ self.T_cen_obj_
        return dict(pose=pose, mask=mask, prob=prob, labels=labels, fitness=float(fitness),
                    inlier_rmse=float(rmse), n_points=int(n_points), time_s=0.0, lost=bool(lost),
                    accepted=bool(accepted), covariance=np.array(cov, dtype=float),
                    pose_filtered=self.filter_.T @ self.T_cen_obj_,
                    pose_predicted=self.filter_.T_bar @ self.T_cen_obj_, roi=tuple(int(v) for v in roi),
                    gamma=float(gamma), iterations=int(iterations), n_inliers=int(n_inliers), prob_raw=prob_raw,
                    n_unobserved=int(self.n_unobserved_), **extra)
