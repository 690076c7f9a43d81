"""The per-image result of :class:`polar_sim.ground.GroundVO`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["GroundEstimate", "STATUSES"]

#: Values of ``GroundEstimate.status``.
STATUSES = ("init", "ok", "static", "no_features", "few_triplets", "no_ground")


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
