"""The result of one frame of :class:`~polar_sim.tracking.ObjectTracker`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["TrackResult"]


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
        ``guard.lost_after`` rejected frames in a row.
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
        thresholds at ``registration.tau_y``).
    n_unobserved : pose directions the registered points did not constrain this frame (held
        at the prediction, see ``registration.hold_unobserved``).
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
