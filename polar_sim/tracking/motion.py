"""Constant-velocity motion filter on SE(3) (spec 5): error-state EKF, alpha-beta, or none.

State: the pose ``T`` (T_cam_cen, the centred model frame in the camera) and the body twist
``xi = (omega, v)`` (rad/s, m/s) about the object's centre, in its own axes; the 12-D error state
is ``[delta_pose (6), delta_xi (6)]`` with ``T_true = T Exp(delta_pose)``. Departure from the spec
(which uses the camera-frame left twist): a twist about the object centre keeps rotation and
translation uncertainty apart, so the process noise (rad, m per sqrt(s)) means what it says for a
hand-held object and the gates compare the object's own motion.
"""

from __future__ import annotations

import numpy as np

from polar_sim.geometry import inv_pose, se3_exp, se3_log

__all__ = ["MotionFilter"]


class MotionFilter:
    """Predict/update on SE(3).

    Parameters
    ----------
    T0 : (4, 4) initial T_cam_cen.
    mode : "ekf" | "alpha-beta" | "none" ("none": the prediction is the last pose, fixed spread).
    q_pose, q_vel : (rot, trans) process noise densities, (rad, m)/sqrt(s) and (rad/s, m/s)/sqrt(s).
    meas_floor : (rot rad, trans m) standard deviations added to the measurement covariance.
    sigma_cap : (rot rad, trans m) upper bound of the pose standard deviations.
    velocity_cap : (rad/s, m/s) upper bound of the velocity standard deviations.
    beta : alpha-beta velocity gain.
    """

    def __init__(self, T0, *, mode="ekf", q_pose=(0.05, 0.01), q_vel=(2.0, 0.5),
                 meas_floor=(np.deg2rad(0.5), 0.002), sigma_cap=(0.3, 0.04), velocity_cap=(3.0, 1.0),
                 beta=0.5, v0=(0.5, 0.1),
                 sigma_static=(0.05, 0.01)):
        self.mode = mode
        self.T = T0.copy()
        self.xi = np.zeros(6)
        self.q = np.repeat(np.asarray(q_pose, float) ** 2, 3)
        self.qv = np.repeat(np.asarray(q_vel, float) ** 2, 3)
        self.floor = np.repeat(np.asarray(meas_floor, float) ** 2, 3)
        self.cap = np.concatenate([np.repeat(np.asarray(sigma_cap, float), 3),
                                   np.repeat(np.asarray(velocity_cap, float), 3)])
        self.beta = beta
        self.static = np.repeat(np.asarray(sigma_static, float) ** 2, 3)
        p0 = np.concatenate([np.repeat(np.array([np.deg2rad(1.0), 0.002]) ** 2, 3),
                             np.repeat(np.asarray(v0, float) ** 2, 3)])
        self.P = np.diag(p0)
        self.T_bar = self.T.copy()
        self.P_bar = self.P.copy()

    def predict(self, dt):
        """Predicted pose T_bar (4, 4) and its 6x6 covariance (also kept for :meth:`update`)."""
        if self.mode == "none":
            self.T_bar = self.T.copy()
            self.P_bar = self.P.copy()
            self.P_bar[:6, :6] = np.diag(self.static)
            return self.T_bar, self.P_bar[:6, :6]
        if self.mode == "alpha-beta":
            self.T_bar = self.T @ se3_exp(dt * self.xi)
            s = np.concatenate([np.maximum(np.full(3, np.deg2rad(2.0)), np.linalg.norm(self.xi[:3]) * dt),
                                np.maximum(np.full(3, 0.005), np.linalg.norm(self.xi[3:]) * dt)])
            self.P_bar = self.P.copy()
            self.P_bar[:6, :6] = np.diag(s**2)
            return self.T_bar, self.P_bar[:6, :6]
        F = np.eye(12)
        F[:6, 6:] = dt * np.eye(6)
        Q = np.diag(np.concatenate([self.q * dt, self.qv * dt]))
        self.T_bar = self.T @ se3_exp(dt * self.xi)
        self.P_bar = self._cap(F @ self.P @ F.T + Q)
        return self.T_bar, self.P_bar[:6, :6]

    def _cap(self, P):
        # bound every standard deviation (pose and velocity): repeated x4 inflations while an
        # object stays hidden would otherwise grow the velocity block without limit, and the
        # first update after it reappears would then throw the velocity (and the pose) away
        s = np.sqrt(np.maximum(np.diag(P), 1e-30))
        f = np.minimum(1.0, self.cap / s)
        return P * np.outer(f, f)

    def update(self, T_meas, cov, dt, *, inflate=1.0, hold=None):
        """Fuse a registration T_meas (4, 4) with covariance cov (6, 6); ``inflate`` scales P after.

        ``hold``: ``(U, scale)`` with U (6, k) orthonormal directions of the scaled twist
        ``scale * xi`` that the measurement does not see; the velocity along them is set to 0."""
        if self.mode == "none":
            self.T = T_meas.copy()
            return
        if self.mode == "alpha-beta":
            if dt > 0:  # a velocity needs an interval: none before the first frame
                step = se3_log(inv_pose(self.T) @ T_meas) / dt
                self.xi = (1.0 - self.beta) * self.xi + self.beta * step
            self.T = T_meas.copy()
            self._hold(hold)
            return
        e = se3_log(inv_pose(self.T_bar) @ T_meas)
        S = self.P_bar[:6, :6] + cov + np.diag(self.floor)
        G = np.linalg.solve(S, self.P_bar[:6, :]).T  # (12, 6) = P H^T S^-1
        dx = G @ e
        self.T = self.T_bar @ se3_exp(dx[:6])
        self.xi = self.xi + dx[6:]
        P = self.P_bar - G @ self.P_bar[:6, :]
        self.P = self._cap(0.5 * (P + P.T) * inflate)
        if not (np.all(np.isfinite(self.T)) and np.all(np.isfinite(self.xi)) and np.all(np.isfinite(self.P))):
            # cannot happen with the caps above; never let a numerical failure escape as a pose
            self.T, self.xi, self.P = T_meas.copy(), np.zeros(6), self._cap(self.P_bar.copy())
        self._hold(hold)

    def _hold(self, hold):
        # no velocity where no measurement constrains the motion: an object at rest stays at rest
        if hold is None or hold[0].shape[1] == 0:
            return
        U, scale = hold
        xs = self.xi * scale
        self.xi = (xs - U @ (U.T @ xs)) / scale

    def coast(self, *, velocity_decay=1.0, inflate=1.0):
        """No (usable) measurement: keep the prediction, damp the velocity, scale P by ``inflate``."""
        self.T = self.T_bar.copy()
        self.xi = self.xi * velocity_decay
        if self.mode == "ekf":
            self.P = self._cap(self.P_bar * inflate)

    @property
    def pose_cov(self):
        """Current 6x6 pose covariance (body twist about the centre)."""
        return self.P[:6, :6].copy()
