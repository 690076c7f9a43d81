"""The tracker's settings, one frozen dataclass per stage of a frame (after kiss-icp's ``config/``).

:class:`~polar_sim.tracking.ObjectTracker` takes the few arguments a user sets (the model, the
camera, the first pose, the appearance variant, the seed) and one config per stage:

=================== =========================== ===============================================
argument            class                       stage
=================== =========================== ===============================================
``motion``          :class:`MotionConfig`       the pose prediction (spec 3.1, 5)
``attention``       :class:`AttentionConfig`    the prior pi and the ROI (spec 3.3)
``registration``    :class:`RegistrationConfig` the highly probable points and the ICP (spec 3.5)
``guard``           :class:`GuardConfig`        the drift guard and lost mode (spec 3.7)
``learning``        :class:`LearningConfig`     the online appearance training (spec 4.3)
=================== =========================== ===============================================

Each config checks every field in ``__post_init__`` with :mod:`polar_sim._validation` (type, range,
finiteness) and bounds every size before anything is allocated, so a bad value raises
``ValueError``/``TypeError`` naming the field (and the limit) where the config is made.
``ObjectTracker.get_params()`` lists the fields as ``stage__field`` and ``set_params`` changes
them, as scikit-learn's nested estimators do: ``tr.set_params(registration__tau_y=0.6)``.
The defaults are spec §10's, with the departures of ``docs/guide/tracking.md`` (chosen on dev).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polar_sim._validation import as_bool, as_float, as_int, check_choice

__all__ = ["MotionConfig", "AttentionConfig", "RegistrationConfig", "GuardConfig", "LearningConfig",
           "MAX_REGISTRATION_POINTS", "MAX_ITERATIONS", "MAX_EPOCHS", "MAX_REPLAY", "MAX_SAMPLES"]

#: Upper bounds of the sizes (checked before anything is allocated; each well above any use: a
#: 640x480 ROI has 307,200 pixels, and the time or memory they allow stays within a frame's budget
#: by orders of magnitude less than a hang).
MAX_REGISTRATION_POINTS = 1_000_000
MAX_ITERATIONS = 1000
MAX_EPOCHS = 100
MAX_REPLAY = 100
MAX_SAMPLES = 10_000
MAX_SIGMA_PX = 1000.0


def _choice(value, choices, name):
    if not isinstance(value, str):
        raise TypeError(f"{name}: expected a string, one of {', '.join(map(repr, choices))}; got "
                        f"{type(value).__name__}")
    return check_choice(value, choices, name)


def _open(value, name, lo, hi):
    """A finite number strictly between ``lo`` and ``hi``."""
    v = as_float(value, name, minimum=lo, maximum=hi, exclusive_minimum=True)
    if v >= hi:
        raise ValueError(f"{name}: expected a number in ({lo}, {hi}), got {value!r}")
    return v


def _unit(value, name):
    return as_float(value, name, minimum=0.0, maximum=1.0)


@dataclass(frozen=True)
class MotionConfig:
    """The motion prior: a constant-velocity filter on SE(3) (:class:`~polar_sim.tracking.motion.MotionFilter`).

    Parameters
    ----------
    filter : {"ekf", "alpha-beta", "none"}, default="ekf"
        Error-state EKF, the spec's alpha-beta fallback, or "none": the prediction is the last
        pose (the motion-prior-off ablation).
    velocity_decay : float in [0, 1], default=0.5
        Factor applied to the filter's velocity on each frame without a usable registration.
    """

    filter: str = "ekf"
    velocity_decay: float = 0.5

    def __post_init__(self):
        _choice(self.filter, ("ekf", "alpha-beta", "none"), "filter")
        _unit(self.velocity_decay, "velocity_decay")


@dataclass(frozen=True)
class AttentionConfig:
    """The spatial prior pi and the region of interest around the predicted silhouette.

    Parameters
    ----------
    spatial_prior : bool, default=False
        The predicted silhouette blurred by the pose spread, in [epsilon, 1 - epsilon], as the prior
        pi (the spec's form). False gives pi = 0.5 in the ROI, which the ROI (the silhouette's box
        grown by 3 sigma) still bounds. Off since issue 13: at epsilon = 0.02 the prior's log-odds
        (+-3.9) outweigh the depth term (at most +3.1), so a mispredicted object cannot re-enter
        the registration; chosen on the dev split.
    epsilon : float in (0, 0.5), default=0.02
        Floor and ceiling of the prior.
    sigma_min_px : float in (0, 1000], default=3
        Smallest blur of the prior, pixels.
    """

    spatial_prior: bool = False
    epsilon: float = 0.02
    sigma_min_px: float = 3.0

    def __post_init__(self):
        as_bool(self.spatial_prior, "spatial_prior")
        _open(self.epsilon, "epsilon", 0.0, 0.5)
        as_float(self.sigma_min_px, "sigma_min_px", minimum=0.0, maximum=MAX_SIGMA_PX, exclusive_minimum=True)


@dataclass(frozen=True)
class RegistrationConfig:
    """The highly probable points and their robust, weighted, visibility-aware ICP.

    Parameters
    ----------
    method : {"weighted", "plain"}, default="weighted"
        "weighted": the points with P > ``tau_y``, weighted by P (spec 3.5). "plain": robust ICP
        on every ROI point with depth, no label weighting (the baseline).
    correspondence : {"grid", "kdtree"}, default="grid"
        Nearest visible model point from the precomputed k-NN lookup grid, or the cKDTree itself.
    max_points : int in [6, 1,000,000], default=3000
        N_Y, the most points registered (sampled with probability proportional to P).
    tau_y : float in (0, 1), default=0.5
        Threshold on P for the highly probable points.
    max_iterations : int in [1, 1000], default=30
        ICP iterations.
    tangential_deadzone : float in [0, 5], default=1.5
        Dead zone of the ICP's tangential term for a fully hidden object, in units of the model's
        local point spacing (:func:`polar_sim.tracking.icp.weighted_icp`); on each frame it is
        scaled by the hidden fraction of the predicted silhouette (pixels where something is seen
        in front of the predicted surface). A tangential offset from the nearest model point within
        it is a sampling gap, not a slide. With few points visible the gaps no longer average out
        and pull the weakly observed rotations (a mug under a palm); with the whole object visible
        the tangential term keeps its full pull. It is also scaled by the evidence that the object
        is at rest (``deadzone_rest_speed``). 0: every offset pulls.
    deadzone_rest_speed : float in [0, 10], default=0.25
        The surface speed, in model spacings per frame, up to which the motion filter's predicted
        velocity counts as at rest: the dead zone applies in full below it, fades linearly to
        nothing at twice it, and is off above. A moving object needs its tangential pull, and
        behind an occluder its hidden fraction is no evidence of rest: a pose that lags a pushed
        object puts the pusher in front of the predicted surface, which grew the dead zone and the
        lag with it. 0: no dead zone at all.
    em_refine : bool, default=True
        When the registration lands more than 2 predicted standard deviations from the prediction,
        redo the prediction map at the registered pose (3 mm / 1 deg spread) and register again: a
        second EM step (spec 2) that rescues fast motion.
    pose_prior : bool, default=True
        Register as a MAP estimate with the motion filter's prediction as the prior (its 6x6
        covariance): directions the visible points leave unconstrained keep the prediction.
    hold_unobserved : bool, default=True
        Along directions in which moving the model does not change its fit to the registered
        points (:func:`polar_sim.tracking.icp.unobserved_directions`), and about the model's own
        symmetry axes (:func:`polar_sim.tracking.icp.symmetry_directions`, every frame), the pose
        keeps the prediction and the filter's velocity is zeroed: an object at rest stays at rest
        where its shape cannot see.
    """

    method: str = "weighted"
    correspondence: str = "grid"
    max_points: int = 3000
    tau_y: float = 0.5
    max_iterations: int = 30
    tangential_deadzone: float = 1.5
    deadzone_rest_speed: float = 0.25
    em_refine: bool = True
    pose_prior: bool = True
    hold_unobserved: bool = True

    def __post_init__(self):
        _choice(self.method, ("weighted", "plain"), "method")
        _choice(self.correspondence, ("grid", "kdtree"), "correspondence")
        as_int(self.max_points, "max_points", minimum=6, maximum=MAX_REGISTRATION_POINTS)
        _open(self.tau_y, "tau_y", 0.0, 1.0)
        as_int(self.max_iterations, "max_iterations", minimum=1, maximum=MAX_ITERATIONS)
        as_float(self.tangential_deadzone, "tangential_deadzone", minimum=0.0, maximum=5.0)
        as_float(self.deadzone_rest_speed, "deadzone_rest_speed", minimum=0.0, maximum=10.0)
        for name in ("em_refine", "pose_prior", "hold_unobserved"):
            as_bool(getattr(self, name), name)


@dataclass(frozen=True)
class GuardConfig:
    """The drift guard (spec 3.7): when a registration is used, when it trains, when the track is lost.

    Parameters
    ----------
    fitness_min : float in [0, 1], default=0.5
        A good fit has at least this fitness ...
    min_inliers : int >= 0, default=50
        ... and at least this many inliers. A good fit updates the filter; a poor one is reported
        but not fused (the filter coasts, widened x4) and counts towards lost mode.
    min_coverage : float in [0, 1], default=0.1
        Inliers per expected pixel (see ``coverage``) below which the registration is not used
        (object out of view, or the fit is elsewhere).
    coverage : {"visible", "silhouette"}, default="visible"
        Which pixels of the predicted silhouette (with valid depth) ``min_coverage`` counts as
        expected: "visible" leaves out those where something is seen in front of the predicted
        surface (by more than 3 sigma of depth noise and pose spread, at least 1 cm: a hand), so a
        mostly hidden object whose visible part fits is tracked, not lost; "silhouette" counts
        them all (the rule before, which declares an object lost once about 85 % of it is hidden).
    learn_coverage : float in [0, 1], default=0.25
        Inliers per valid-depth pixel of the whole predicted silhouette, hidden ones included,
        needed for the frame to train the appearance model.
    max_jump : (float, float), default=(0.5, 0.1)
        Largest accepted change from the prediction: rotation (rad) and centroid translation (m).
    max_mahalanobis : float > 0 (inf allowed), default=50
        Largest squared Mahalanobis distance of the registration from the prediction under the
        predicted covariance (6 dof); ``np.inf`` disables the gate.
    lost_after : int >= 1, default=10
        Poor or unusable frames in a row after which the tracker is in lost mode (appearance off,
        the prediction reported) until a good fit.
    confident_fitness : float in [0, 1] or None, default=0.9
        A registration with at least this fitness that also covers ``learn_coverage`` of the
        silhouette passes the Mahalanobis gate up to 4 x ``max_mahalanobis`` (twice the predicted
        spread, the widening of a poor fit): a sudden push, measured cleanly while the motion
        prior still expects the slow slide before it, is fused rather than coasted through. None
        keeps the single gate.
    """

    fitness_min: float = 0.5
    min_inliers: int = 50
    min_coverage: float = 0.1
    coverage: str = "visible"
    learn_coverage: float = 0.25
    max_jump: tuple = (0.5, 0.1)
    max_mahalanobis: float = 50.0
    lost_after: int = 10
    confident_fitness: float | None = 0.9

    def __post_init__(self):
        for name in ("fitness_min", "min_coverage", "learn_coverage"):
            _unit(getattr(self, name), name)
        as_int(self.min_inliers, "min_inliers", minimum=0)
        _choice(self.coverage, ("visible", "silhouette"), "coverage")
        if not isinstance(self.max_jump, (tuple, list, np.ndarray)) or len(self.max_jump) != 2:
            raise ValueError(f"max_jump: expected (rotation rad, translation m), got {self.max_jump!r}")
        for v, what in zip(self.max_jump, ("rotation", "translation")):
            as_float(v, f"max_jump ({what})", minimum=0.0, exclusive_minimum=True)
        as_float(self.max_mahalanobis, "max_mahalanobis", minimum=0.0, exclusive_minimum=True, allow_inf=True)
        as_int(self.lost_after, "lost_after", minimum=1)
        if self.confident_fitness is not None:
            _unit(self.confident_fitness, "confident_fitness")


@dataclass(frozen=True)
class LearningConfig:
    """Online training of the appearance model from the labels O (spec 4.3).

    Parameters
    ----------
    k_warm : int >= 1, default=5
        Ramp-in of the appearance term: gamma = min(1, accepted updates / k_warm).
    decay : float in [0, 1], default=0.7
        Histogram fading of the colour model "h".
    lr : float in (0, 10], default=0.01
        Adam learning rate of the feature heads.
    epochs : int in [0, 100], default=2
        Passes over the samples per accepted frame.
    replay : int in [1, 100], default=10
        Frames kept in the replay buffer.
    n_samples : int in [1, 10,000], default=500
        Most positives (and negatives) sampled per frame.
    """

    k_warm: int = 5
    decay: float = 0.7
    lr: float = 1e-2
    epochs: int = 2
    replay: int = 10
    n_samples: int = 500

    def __post_init__(self):
        as_int(self.k_warm, "k_warm", minimum=1)
        _unit(self.decay, "decay")
        as_float(self.lr, "lr", minimum=0.0, maximum=10.0, exclusive_minimum=True)
        as_int(self.epochs, "epochs", minimum=0, maximum=MAX_EPOCHS)
        as_int(self.replay, "replay", minimum=1, maximum=MAX_REPLAY)
        as_int(self.n_samples, "n_samples", minimum=1, maximum=MAX_SAMPLES)
