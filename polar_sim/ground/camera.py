"""The processed image's pinhole camera and its level, vehicle-aligned frame (spec §9.2)."""

from __future__ import annotations

import numpy as np

__all__ = ["LevelCamera"]


class LevelCamera:
    """Pinhole camera of the processed (possibly downsampled) image, pitched down by a known angle.

    Parameters
    ----------
    K : ndarray of shape (3, 3)
        Intrinsics of the input image, px.
    downsample : {1, 2}
        Pyramid reduction of the processed image: output pixel i sits on input pixel ds*i (0-based
        centres), so the intrinsics divide exactly.
    pitch : float
        Downward pitch of the camera relative to the level vehicle frame, rad (> 0 looks down).
    horizon_row : float or None
        Input-image row below which points are ground candidates; None: v > 0 in the level frame.
    """

    def __init__(self, K, downsample, pitch, horizon_row):
        self.fx, self.fy = K[0, 0] / downsample, K[1, 1] / downsample
        self.cx, self.cy = K[0, 2] / downsample, K[1, 2] / downsample
        self.horizon = None if horizon_row is None else horizon_row / downsample
        self.pitch = pitch
        cp, sp = np.cos(pitch), np.sin(pitch)
        # Rotation camera -> level frame: the optical axis of a camera pitched down by θ is (0, sin θ, cos θ).
        self.R_lc = np.array([[1.0, 0.0, 0.0], [0.0, cp, sp], [0.0, -sp, cp]])
        self.K = np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def level(self, xy):
        """Normalised coordinates (u, v) in the level frame of processed-image pixels (n, 2)."""
        r = np.stack([(xy[:, 0] - self.cx) / self.fx, (xy[:, 1] - self.cy) / self.fy, np.ones(len(xy))], axis=1)
        if self.pitch != 0.0:
            r = r @ self.R_lc.T
            with np.errstate(divide="ignore", invalid="ignore"):
                return r[:, 0] / r[:, 2], r[:, 1] / r[:, 2]
        return r[:, 0], r[:, 1]

    def image(self, u, v):
        """Processed-image pixels (n, 2) of level-frame normalised coordinates."""
        r = np.stack([u, v, np.ones(len(u))], axis=1)
        if self.pitch != 0.0:
            r = r @ self.R_lc
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.stack([self.fx * r[:, 0] / r[:, 2] + self.cx, self.fy * r[:, 1] / r[:, 2] + self.cy], axis=1)

    def below(self, xy):
        """Ground-candidate side of the horizon (n,) bool: below ``horizon_row``, or v > 0 in the level frame."""
        if self.horizon is not None:
            return xy[:, 1] > self.horizon
        return self.level(xy)[1] > 0

    def level_homography(self, H_level):
        """A homography of level-frame normalised coordinates, as one of processed-image pixels."""
        M = self.K @ self.R_lc.T
        return M @ H_level @ np.linalg.inv(M)

    def to_camera(self, step):
        """A (4, 4) motion step of the level frame expressed for the (pitched) camera frame."""
        if self.pitch == 0.0:
            return step
        M = np.eye(4)
        M[:3, :3] = self.R_lc
        return np.linalg.inv(M) @ step @ M
