"""Nonholonomic image kinematics: rotation rates and scaled inverse depths (spec §3.1–3.3).

Flow model of a camera moving along its optical axis at speed V and rotating at
(Ωx, Ωy = ω, Ωz), in normalised image coordinates (u, v) and per second::

    u̇ = (u - t1) d̄ + u v Ωx - (1 + u²) Ωy + v Ωz
    v̇ = (v - t2) d̄ + (1 + v²) Ωx - u v Ωy - u Ωz

with d̄ = V/Z the scaled inverse depth of each point and (t1, t2) the focus of expansion (0 unless
``estimate_foe``, or (-slip·Ωy, 0) for a camera that slips sideways in turns). Each point has its own d̄, so the normal equations are arrow-shaped and are solved
in O(N) through the Schur complement of the diagonal block (:func:`arrow_solve`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["arrow_solve", "arrow_normal_equations", "estimate_motion", "central_difference_flow", "MotionResult"]


def arrow_solve(A11, A12, D, b_g, b_d):
    """Solve the arrow system ``[[A11, A12], [A12ᵀ, diag(D)]] [g; d] = [b_g; b_d]`` in O(N n_g²).

    A11 (n_g, n_g), A12 (n_g, N), D (N,) positive, b_g (n_g,), b_d (N,). Returns (g (n_g,), d (N,)).
    """
    A12_Dinv = A12 / D
    S = A11 - A12_Dinv @ A12.T
    g = np.linalg.solve(S, b_g - A12_Dinv @ b_d)
    d = (b_d - A12.T @ g) / D
    return g, d


def arrow_normal_equations(C_u, a_u, C_v, a_v, y_u, y_v, w_u=None, w_v=None, ridge=None):
    """Arrow-structured normal equations of the two-rows-per-point system (spec §3.2).

    Point i contributes rows ``C_u[i] · g + a_u[i] d_i ≈ y_u[i]`` and ``C_v[i] · g + a_v[i] d_i ≈ y_v[i]``
    with weights w_u, w_v (default 1). C_* (N, n_g); a_*, y_*, w_* (N,); ridge (n_g,) or None adds
    diag(ridge) to A11. Returns (A11, A12, D, b_g, b_d).
    """
    if w_u is None:
        w_u = np.ones_like(a_u)
    if w_v is None:
        w_v = np.ones_like(a_v)
    Cu_w = C_u * w_u[:, None]
    Cv_w = C_v * w_v[:, None]
    A11 = C_u.T @ Cu_w + C_v.T @ Cv_w
    if ridge is not None:
        A11 = A11 + np.diag(ridge)
    A12 = (Cu_w * a_u[:, None] + Cv_w * a_v[:, None]).T
    D = w_u * a_u * a_u + w_v * a_v * a_v
    b_g = Cu_w.T @ y_u + Cv_w.T @ y_v
    b_d = w_u * a_u * y_u + w_v * a_v * y_v
    return A11, A12, D, b_g, b_d


@dataclass(frozen=True)
class MotionResult:
    """Output of :func:`estimate_motion`.

    rates : (3,) (Ωx, Ωy = yaw rate ω, Ωz) in rad/s (n_global = 1: only Ωy is estimated).
    foe : (2,) focus of expansion (t1, t2), normalised; zeros unless estimated or given by ``slip``.
    dbar : (N,) scaled inverse depth V/Z in 1/s, absolute value; NaN where not valid.
    valid : (N,) bool, d̄ has the sign of the median d̄ (points behind or reversing are dropped).
    iterations : IRLS iterations run (0 = plain least squares).
    yaw_var : variance of the yaw rate, (rad/s)²: the least-squares covariance of the inlier rows (residuals
        within 3 robust standard deviations) at the solution, the depths eliminated; NaN if undetermined.
    """

    rates: np.ndarray
    foe: np.ndarray
    dbar: np.ndarray
    valid: np.ndarray
    iterations: int
    yaw_var: float = float("nan")

    @property
    def yaw_rate(self):
        return float(self.rates[1])


def _rows(u, v, n_global, t, dbar):
    """Jacobian rows: global coefficients C_u, C_v (N, n_g) and depth coefficients a_u, a_v (N,)."""
    n = len(u)
    uv = u * v
    if n_global == 1:
        C_u = -(1.0 + u * u)[:, None]
        C_v = -uv[:, None]
    else:
        C_u = np.stack([uv, -(1.0 + u * u), v], axis=1)
        C_v = np.stack([1.0 + v * v, -uv, -u], axis=1)
    if n_global == 5:
        z = np.zeros(n)
        C_u = np.concatenate([np.stack([-dbar, z], axis=1), C_u], axis=1)
        C_v = np.concatenate([np.stack([z, -dbar], axis=1), C_v], axis=1)
    return C_u, u - t[0], C_v, v - t[1]


def _predict(u, v, rates, t, dbar):
    ox, oy, oz = rates
    fu = (u - t[0]) * dbar + u * v * ox - (1.0 + u * u) * oy + v * oz
    fv = (v - t[1]) * dbar + (1.0 + v * v) * ox - u * v * oy - u * oz
    return fu, fv


def _twist_pose(w, v):
    """Rotation (3, 3) and translation (3,) of exp of the body twist (w, v) (closed form, no scipy)."""
    th2 = float(w @ w)
    W = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    W2 = W @ W
    th = np.sqrt(th2)
    if th2 < 1e-6:  # series: exact to round-off below 1e-3 rad, where the closed forms cancel
        A, B, C = 1.0 - th2 / 6.0 + th2 * th2 / 120.0, 0.5 - th2 / 24.0 + th2 * th2 / 720.0, 1.0 / 6.0 - th2 / 120.0
    else:
        A, C = np.sin(th) / th, (th - np.sin(th)) / (th2 * th)
        B = 0.5 * (np.sin(th / 2.0) / (th / 2.0)) ** 2  # (1 - cos θ)/θ² without cancellation
    R = np.eye(3) + A * W + B * W2
    V = np.eye(3) + B * W + C * W2
    return R, V @ v


def central_difference_flow(u, v, dbar, rates, foe, tau_before, tau_after):
    """Exact centred flow of points under a constant body twist, normalised units per second.

    The camera moves with angular velocity ``rates`` (3,) and unit-speed translation (t1, t2, 1) (the
    FOE direction); a point seen at (u, v) at time 0 with scaled inverse depth d̄ (1/s) sits at depth
    1/d̄ in these units. Returns ((x(τa) - x(-τb)) / (τa + τb) for x = u and v, ok mask); where a point
    has d̄ <= 0 or leaves the front of the camera, ``ok`` is False and the flow is NaN.
    """
    ok = np.isfinite(dbar) & (dbar > 0)
    Z = np.where(ok, 1.0 / np.where(ok, dbar, 1.0), 1.0)
    X = np.stack([u * Z, v * Z, Z], axis=1)
    vel = np.array([foe[0], foe[1], 1.0])
    proj = []
    for tau in (-tau_before, tau_after):
        R, p = _twist_pose(np.asarray(rates, dtype=np.float64) * tau, vel * tau)
        Y = (X - p) @ R
        ok &= Y[:, 2] > 1e-9
        zz = np.where(ok, Y[:, 2], 1.0)
        proj.append((Y[:, 0] / zz, Y[:, 1] / zz))
    span = tau_before + tau_after
    fu = np.where(ok, (proj[1][0] - proj[0][0]) / span, np.nan)
    fv = np.where(ok, (proj[1][1] - proj[0][1]) / span, np.nan)
    return fu, fv, ok


def _discretisation_bias(u, v, rates, t, dbar, span):
    """Centred-difference flow minus the instantaneous model flow at the current estimate (0 where undefined)."""
    cu, cv, ok = central_difference_flow(u, v, dbar, rates, t, span[0], span[1])
    fu, fv = _predict(u, v, rates, t, dbar)
    return np.where(ok, cu - fu, 0.0), np.where(ok, cv - fv, 0.0)


def estimate_motion(u, v, udot, vdot, *, n_global=3, ridge=1.0, irls_iter=10, irls_tol=1e-3,
                    irls_floor=1e-5, estimate_foe=False, span=None, slip=0.0, compat="fixed"):
    """Rotation rates and scaled inverse depths from centred image flow (spec §3).

    Parameters
    ----------
    u, v : (N,) normalised image coordinates of the points at the middle frame.
    udot, vdot : (N,) normalised image velocities (1/s).
    n_global : {1, 3}
        1: yaw rate only (text); 3: (Ωx, Ωy, Ωz) with a ridge on Ωx, Ωz (code). ``estimate_foe`` adds
        (t1, t2) to the three rates (n_g = 5).
    ridge : float
        Ridge weight on Ωx and Ωz (pitch/roll rates pulled toward 0), every iteration.
    irls_iter : int
        Maximum IRLS iterations with row weights 1/max(|r|, irls_floor) (L1); 0 = plain LS.
    estimate_foe : bool
        Also estimate the focus of expansion (n_g = 5, Gauss–Newton inside the IRLS).
    span : (float, float), optional
        (t_mid - t_first, t_last - t_mid) of the three frames the centred flow was taken over, s. When
        given (fixed mode), the measured flow is corrected at every iteration for the difference between
        the exact centred difference under constant motion and the instantaneous model
        (:func:`central_difference_flow`); this removes the O((V dt / Z)²) bias of near points that the
        differential model of the spec has (≈1 % in ω for a camera 1 m above the ground). None: the
        spec's plain differential model.
    slip : float, default=0.0
        The camera's sideways velocity per unit forward speed and yaw rate, s: the focus of expansion
        sits at t1 = -slip x ω (ω the current yaw-rate estimate, at every IRLS iteration; t2 = 0). A
        wheeled robot's camera is not at the point of its chassis that moves straight ahead in a turn
        (tyres creep outward, a camera sits ahead of the rear axle); with the focus of expansion at the
        centre, the ground's sideways flow (-t1 d̄) is read partly as yaw. The flow cannot tell it
        from a roll rate within one frame, so it is a constant of the robot, given. Ignored with
        ``estimate_foe`` or ``irls_iter=0``.
    compat : {"fixed", "code"}
        "code" returns exactly the initial ridge LS with n_g = 3 (B1: the published IRLS is inert).
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    udot = np.asarray(udot, dtype=np.float64)
    vdot = np.asarray(vdot, dtype=np.float64)
    n = len(u)
    if compat == "code":
        n_global, irls_iter, estimate_foe, span = 3, 0, False, None
    slip = 0.0 if estimate_foe else float(slip)
    ng_rates = 1 if (n_global == 1 and not estimate_foe) else 3  # the FOE model carries all three rates
    lam_rates = np.zeros(ng_rates) if ng_rates == 1 else np.array([ridge, 0.0, ridge])

    # Initial plain least squares (FOE fixed at 0).
    t = np.zeros(2)
    C_u, a_u, C_v, a_v = _rows(u, v, ng_rates, t, None)
    g, dbar = arrow_solve(*arrow_normal_equations(C_u, a_u, C_v, a_v, udot, vdot, ridge=lam_rates))
    rates = np.zeros(3)
    if ng_rates == 1:
        rates[1] = g[0]
    else:
        rates[:] = g

    bias_u = bias_v = 0.0
    if span is not None:
        # A plain LS pass on bias-corrected flow before the IRLS.
        bias_u, bias_v = _discretisation_bias(u, v, rates, t, dbar, span)
        g, dbar = arrow_solve(*arrow_normal_equations(C_u, a_u, C_v, a_v, udot - bias_u, vdot - bias_v,
                                                      ridge=lam_rates))
        rates[:] = [0.0, g[0], 0.0] if ng_rates == 1 else g
        if irls_iter == 0:
            bias_u, bias_v = _discretisation_bias(u, v, rates, t, dbar, span)
            g, dbar = arrow_solve(*arrow_normal_equations(C_u, a_u, C_v, a_v, udot - bias_u, vdot - bias_v,
                                                          ridge=lam_rates))
            rates[:] = [0.0, g[0], 0.0] if ng_rates == 1 else g

    it = 0
    ng = 5 if estimate_foe else ng_rates
    lam = np.concatenate([np.zeros(2), lam_rates]) if estimate_foe else lam_rates
    for it in range(1, irls_iter + 1):
        if slip:
            t = np.array([-slip * rates[1], 0.0])
        if span is not None:
            bias_u, bias_v = _discretisation_bias(u, v, rates, t, dbar, span)
        fu, fv = _predict(u, v, rates, t, dbar)
        r_u, r_v = udot - bias_u - fu, vdot - bias_v - fv
        w_u = 1.0 / np.maximum(np.abs(r_u), irls_floor)
        w_v = 1.0 / np.maximum(np.abs(r_v), irls_floor)
        C_u, a_u, C_v, a_v = _rows(u, v, ng, t, dbar)
        x_g = np.concatenate([t, rates]) if estimate_foe else (rates[1:2] if ng == 1 else rates)
        A11, A12, D, b_g, b_d = arrow_normal_equations(C_u, a_u, C_v, a_v, r_u, r_v, w_u, w_v, ridge=lam)
        # Gauss–Newton step of the ridge-penalised weighted cost (the ridge acts on the value, not the step).
        dg, dd = arrow_solve(A11, A12, D, b_g - lam * x_g, b_d)
        x_g = x_g + dg
        dbar = dbar + dd
        if estimate_foe:
            t, rates = x_g[:2].copy(), x_g[2:].copy()
        elif ng == 1:
            rates = np.array([0.0, x_g[0], 0.0])
        else:
            rates = x_g.copy()
        if np.sqrt(dg @ dg + dd @ dd) < irls_tol:
            break

    med = np.median(dbar) if n else 0.0
    valid = np.sign(dbar) == np.sign(med) if med != 0 else np.zeros(n, dtype=bool)
    out = np.where(valid, np.abs(dbar), np.nan)
    fu, fv = _predict(u, v, rates, t, dbar)
    yaw_var = _yaw_variance(u, v, udot - bias_u - fu, vdot - bias_v - fv, ng_rates, lam_rates)
    return MotionResult(rates=rates, foe=t, dbar=out, valid=valid, iterations=it, yaw_var=yaw_var)


def _yaw_variance(u, v, r_u, r_v, ng_rates, ridge):
    """Variance of the yaw rate, (rad/s)²: σ² [S⁻¹] of the yaw with S the Schur complement of the depths in
    the unit-weight normal equations of the inlier points (both residuals within 3 σ), σ the residuals'
    robust scale. Ignores the FOE unknowns (the yaw's variance with them fixed)."""
    r = np.r_[r_u, r_v]
    r = r[np.isfinite(r)]
    if len(r) < 2 * ng_rates + 2:
        return float("nan")
    sigma = 1.4826 * float(np.median(np.abs(r)))
    inl = np.isfinite(r_u) & np.isfinite(r_v) & (np.abs(r_u) <= 3 * sigma) & (np.abs(r_v) <= 3 * sigma)
    if inl.sum() < ng_rates + 2 or not sigma > 0:
        return float("nan")
    C_u, a_u, C_v, a_v = _rows(u[inl], v[inl], ng_rates, np.zeros(2), None)
    A11, A12, D, _, _ = arrow_normal_equations(C_u, a_u, C_v, a_v, r_u[inl], r_v[inl], ridge=ridge)
    S = A11 - (A12 / D) @ A12.T
    try:
        cov = np.linalg.inv(S)
    except np.linalg.LinAlgError:
        return float("nan")
    # The rows' residual variance, with the depths and rates fitted (2 rows and 1 unknown per point).
    dof = max(2 * int(inl.sum()) - int(inl.sum()) - ng_rates, 1)
    s2 = float(np.sum(r_u[inl] ** 2 + r_v[inl] ** 2)) / dof
    return float(s2 * cov[1 if ng_rates == 3 else 0, 1 if ng_rates == 3 else 0])
