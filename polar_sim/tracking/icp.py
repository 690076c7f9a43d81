"""Robust, weighted, visibility-aware point-to-plane ICP on SE(3) (spec 3.5).

The pose is ``T_cam_cen``: the *centred* model frame (object frame moved to the model centroid)
to the camera. Increments are body twists ``delta = (omega, v)`` applied on the right,
``T <- T Exp(delta)``, i.e. rotations about the object's centre in its own axes. With a model point
m (centred frame), its normal n and an observation y = T^-1 x in the same frame, the residual is
``r = n . (m - y)`` (equal to the camera-frame ``n' . (p - x)``) and its Jacobian
``J = [(m x n)^T, n^T]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polar_sim.geometry import inv_pose, se3_exp, se3_log
from polar_sim.registration.robust import robust_weight
from polar_sim.tracking._kernels import icp_normal_equations, icp_residuals
from polar_sim.tracking.visibility import project_model

__all__ = ["ICPResult", "weighted_icp", "unobserved_directions", "symmetry_directions"]


@dataclass
class ICPResult:
    """Registration output: pose ``T`` (4, 4) T_cam_cen, covariance ``cov`` (6, 6) of the body
    twist (omega rad, v m), ``fitness`` in [0, 1], inlier RMSE (m), inlier count, points with a
    correspondence, iterations, ``ok`` (False: too few correspondences or a singular system), the
    robust scale ``sigma`` (m), the visibility flags (M,) at ``T`` and ``support``, the model
    points (indices) the inliers were registered to."""

    T: np.ndarray
    cov: np.ndarray
    fitness: float
    rmse: float
    n_inliers: int
    n_matched: int
    iterations: int
    ok: bool
    sigma: float
    vis: np.ndarray
    support: np.ndarray | None = None


def _normal_equations(J, r, w, m, n, y, mu):
    """J^T W J and J^T W r of point-to-plane plus the weighted tangential point-to-point term.

    The point-to-point Jacobian of ``m + omega x m + v`` is ``Jp = [-hat(m), I]`` and its normal
    component ``n^T Jp`` is the point-to-plane row, so the tangential Hessian is
    ``sum w Jp^T Jp - sum w J^T J``; the first sum has a closed form in sum w, sum w m, sum w m m^T.
    """
    Jw = J * w[:, None]
    Hpl = Jw.T @ J
    g = Jw.T @ r
    if mu <= 0:
        return Hpl, g
    s0 = w.sum()
    s1 = w @ m
    s2 = (m * w[:, None]).T @ m
    Hpp = np.empty((6, 6))
    Hpp[:3, :3] = np.trace(s2) * np.eye(3) - s2
    Hs = np.array([[0.0, -s1[2], s1[1]], [s1[2], 0.0, -s1[0]], [-s1[1], s1[0], 0.0]])
    Hpp[:3, 3:] = Hs
    Hpp[3:, :3] = -Hs
    Hpp[3:, 3:] = s0 * np.eye(3)
    e = m - y
    e = e - n * np.einsum("ij,ij->i", e, n)[:, None]  # tangential residual (I - n n^T)(m - y)
    ew = e * w[:, None]
    gt = np.concatenate([np.cross(m, ew).sum(axis=0), ew.sum(axis=0)])
    mu2 = mu * mu
    return (1.0 - mu2) * Hpl + mu2 * Hpp, g + mu2 * gt


def _correspond(X, T, model, vis, gate, exact):
    """Correspondence index (n,) (-1: none within the gate) and point-to-plane residual (n,)."""
    R, t = np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3])
    n = len(X)
    idx = np.empty(n, np.int64)
    res = np.empty(n)
    if not exact:
        icp_residuals(X, R, t, model.origin, model.inv_h, model.knn, model.P, model.N, vis, gate, idx, res)
        return idx, res
    Y = (X - t) @ R
    j, dist = model.nearest_visible(Y, vis, exact=True)
    j[dist >= gate] = -1
    ok = j >= 0
    idx[:] = j
    res[:] = 0.0
    res[ok] = np.einsum("ij,ij->i", model.N[j[ok]], model.P[j[ok]] - Y[ok])
    return idx, res


def weighted_icp(X, w0, model, T_init, K, shape, *, sigma_d, delta1, gate0, gate_floor,
                 max_iterations=30, vis_every=5, gate_decay=0.7, tol_rot=1e-4, tol_trans=1e-5,
                 exact=False, min_points=6, tangential_weight=0.6, vis_init=None, rel_decrease=1e-3,
                 prior=None):
    """Register camera-frame points X (n, 3) with prior weights w0 (n,) to the model.

    Parameters
    ----------
    X : (n, 3) observed points, camera frame, m.      w0 : (n,) prior weights in [0, 1].
    model : ShapeModel.      T_init : (4, 4) initial T_cam_cen.      K, shape : camera.
    sigma_d : (n,) depth noise per point, m (floors the robust scale).
    delta1 : (n,) inlier band per point, m (fitness and RMSE).
    gate0, gate_floor : correspondence gate (point-to-point, m) at the first outer iteration and
        its floor; it shrinks by ``gate_decay`` per outer iteration of ``vis_every`` iterations,
        after which the visibility is recomputed.
    tangential_weight : weight mu of an added point-to-point term restricted to the tangent plane,
        ``mu^2 |(I - n n^T)(m - y)|^2``. Point-to-plane alone cannot see a slide along a face (a
        box seen face-on); the tangential term lets the boundary of the selected points pin it.
        0 gives pure point-to-plane.
    vis_init : (M,) visibility at T_init if already known (saves one projection).
    rel_decrease : stop when the predicted cost decrease of a step is below this fraction of the
        weighted cost (besides the spec's step-size test ``tol_rot``, ``tol_trans``).
    prior : (T_prior (4, 4), information (6, 6)) or None
        Makes the registration a MAP estimate: the cost gains ``e^T Lambda e`` with
        ``e = Log(T_prior^-1 T)``, and the data term is scaled by the robust scale. Directions that the
        points do not constrain (a sliver of one face left by an occluder) then stay at the
        prediction instead of wandering. The returned covariance is the data's alone, for the
        filter.
    """
    X = np.ascontiguousarray(X, dtype=np.float64)
    sig_floor = float(np.median(sigma_d)) if len(sigma_d) else 1e-3
    step = dict(w0=w0, model=model, exact=exact, min_points=min_points, sig_floor=sig_floor,
                mu2=float(tangential_weight) ** 2, prior=prior)
    T, vis, gate, sigma, it, ok = T_init.copy(), vis_init, gate0, sig_floor, 0, False
    for outer in range(int(np.ceil(max_iterations / vis_every))):
        if outer > 0 or vis is None:
            vis = project_model(model.P, model.N, T[:3, :3], T[:3, 3], K, shape, model.spacing).vis
        gate = max(gate0 * gate_decay**outer, gate_floor)
        stop = False
        for _ in range(vis_every):
            if it >= max_iterations:
                stop = True
                break
            it += 1
            delta, gain, cost, sigma = _gauss_newton_step(X, T, vis, gate, sigma, **step)
            if delta is None:   # too few correspondences, or a singular system
                ok, stop = False, True
                break
            T, ok = T @ se3_exp(delta), True
            # converged: a tiny step, or a step that no longer lowers the cost (delta^T H delta is the
            # Gauss-Newton decrease; motion along an unobservable direction, such as a cylinder
            # turning about its axis, is large but free, and would otherwise run to max_iterations)
            small = np.linalg.norm(delta[:3]) < tol_rot and np.linalg.norm(delta[3:]) < tol_trans
            if small or gain < rel_decrease * cost:
                stop = True
                break
        if stop:
            break
    if not ok:
        return ICPResult(T_init.copy(), np.eye(6), 0.0, np.inf, 0, 0, it, False, sigma,
                         vis if vis is not None else np.zeros(len(model.P), bool))
    return _converged(X, w0, model, T, K, shape, gate, sigma, delta1, exact, it)


def _robust(w0, sel, res, sigma):
    """IRLS weights (n,): the prior weights times Tukey's biweight of the residuals at 4.685 x the
    robust scale ``sigma`` (m), 0 without a correspondence."""
    w = np.zeros(len(w0))
    w[sel] = w0[sel] * robust_weight(res[sel], "tukey", 4.685 * sigma)
    return w


def _gauss_newton_step(X, T, vis, gate, sigma, *, w0, model, exact, min_points, sig_floor, mu2, prior):
    """One IRLS Gauss-Newton step at T: ``(delta (6,), predicted decrease, cost, sigma)``, with
    delta None when fewer than ``min_points`` points correspond or the system is singular (sigma is
    the robust scale, MAD of the residuals floored at ``sig_floor``, or the one given when no scale
    could be measured)."""
    idx, res = _correspond(X, T, model, vis, gate, exact)
    sel = idx >= 0
    if sel.sum() < min_points:
        return None, 0.0, 0.0, sigma
    r = res[sel]
    sigma = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), sig_floor)
    w = _robust(w0, sel, res, sigma)
    H, g = np.zeros((6, 6)), np.zeros(6)
    icp_normal_equations(X, np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]),
                         model.P, model.N, idx, res, w, mu2, H, g)
    tr = np.trace(H)
    if not np.isfinite(tr) or tr <= 0:
        return None, 0.0, 0.0, sigma
    cost = float(w @ (res * res))
    if prior is not None:
        # MAP: data in units of the robust scale, plus the prediction's information
        e = se3_log(inv_pose(prior[0]) @ T)
        s2 = sigma * sigma
        H, g = H / s2 + prior[1], g / s2 + prior[1] @ e
        cost = cost / s2 + float(e @ prior[1] @ e)
    delta = -np.linalg.solve(H + 1e-6 * np.trace(H) * np.eye(6), g)
    return delta, float(delta @ H @ delta), cost, sigma


def _converged(X, w0, model, T, K, shape, gate, sigma, delta1, exact, iterations):
    """The result at the converged pose T: final correspondences, fitness, RMSE, covariance."""
    P, N = model.P, model.N
    vis = project_model(P, N, T[:3, :3], T[:3, 3], K, shape, model.spacing).vis
    idx, res = _correspond(X, T, model, vis, gate, exact)
    sel = idx >= 0
    inl = sel & (np.abs(res) < delta1)
    sw = float(w0.sum())
    fitness = float(w0[inl].sum() / sw) if sw > 0 else 0.0
    rmse = float(np.sqrt(np.mean(res[inl] ** 2))) if inl.any() else np.inf
    w = _robust(w0, sel, res, sigma)
    # covariance from point-to-plane alone: the tangential term's Hessian claims information that
    # its sliding nearest-neighbour residuals do not have (a cylinder turning about its axis would
    # look well measured and the filter would reject its true motion)
    H, g = np.zeros((6, 6)), np.zeros(6)
    icp_normal_equations(X, np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]),
                         P, N, idx, res, w, 0.0, H, g)
    tr = np.trace(H)
    try:
        cov = sigma**2 * np.linalg.inv(H + 1e-6 * max(tr, 1e-12) * np.eye(6))
    except np.linalg.LinAlgError:
        cov = np.eye(6)
    cov = 0.5 * (cov + cov.T)
    return ICPResult(T, cov, fitness, rmse, int(inl.sum()), int(sel.sum()), iterations, True, sigma, vis, idx[inl])


def unobserved_directions(model, support, cov, *, step=None, min_std=0.001, n_probe=3, max_rms=0.1,
                          max_points=600):
    """Directions of the pose that the observed surface does not constrain (issue 13 item 5).

    ``support``: indices of the model points that observed points were registered to (the
    surface the data saw). The registration's covariance ``cov`` (6, 6) (body twist (omega, v)
    about the centre) is scaled to metres of surface motion, ``W cov W`` with
    ``W = diag(rho I, I)`` and ``rho`` half the model's diameter; each of its ``n_probe`` least
    certain eigen-directions with a standard deviation above ``min_std`` is probed. The supported
    points are moved by ``+-step`` (m of surface motion at ``rho``; default a tenth of the
    diameter) along it, and their distance to the model surface measured: the normal offset to
    the nearest of 4 model points with a similar normal, plus the tangential offset beyond that
    point's own spacing (the gap random samples leave); no such point counts as ``step``. If the
    RMS distance stays below ``max_rms * step`` both ways, the observed surface maps onto itself
    and the direction is unobserved: a revolved object turning about its axis, a face sliding
    along itself while its edges are not seen. (The linearised covariance cannot tell: faceted
    normals and the tangential term make such directions look measured.)

    Returns ``(U, rho)``: U (6, k) orthonormal unobserved directions in the scaled coordinates
    (``W xi``), k = 0..n_probe.
    """
    rho = 0.5 * model.diameter
    Wd = np.array([rho, rho, rho, 1.0, 1.0, 1.0])
    Cs = cov * np.outer(Wd, Wd)
    lam, vec = np.linalg.eigh(0.5 * (Cs + Cs.T))
    h = float(step) if step is not None else 0.1 * model.diameter
    sup = np.unique(np.asarray(support, dtype=np.int64))
    sup = sup[(sup >= 0) & (sup < len(model.P))]
    if len(sup) < 6:
        return np.zeros((6, 0)), rho
    if len(sup) > max_points:
        sup = sup[np.linspace(0, len(sup) - 1, max_points).astype(np.int64)]
    M, Nm = model.P[sup], model.N[sup]
    out = []
    for k in np.argsort(lam)[::-1][:n_probe]:
        if not np.sqrt(max(lam[k], 0.0)) > min_std:
            break
        xi = vec[:, k] / Wd * h
        if max(_surface_rms(model, M, Nm, xi, h), _surface_rms(model, M, Nm, -xi, h)) < max_rms * h:
            out.append(vec[:, k])
    return (np.stack(out, axis=1) if out else np.zeros((6, 0))), rho


def _surface_rms(model, M, Nm, xi, h, keep=1.0):
    """RMS distance (m) of model points M (n, 3) with normals Nm moved by Exp(xi) to the model
    surface: the normal offset to the nearest of 4 model points with a similar normal, plus the
    tangential offset beyond that point's spacing; no such point (or more than h) counts as h.
    ``keep`` < 1: over the best ``keep`` fraction of the points only."""
    T = se3_exp(xi)
    Y = M @ T[:3, :3].T + T[:3, 3]
    Ny = Nm @ T[:3, :3].T
    _, nb = model.tree.query(Y, k=4)
    ok = np.einsum("nkj,nj->nk", model.N[nb], Ny) > 0.7
    d = Y[:, None, :] - model.P[nb]
    dist = np.where(ok, np.linalg.norm(d, axis=2), np.inf)
    c = np.argmin(dist, axis=1)
    j = nb[np.arange(len(Y)), c]
    dd = d[np.arange(len(Y)), c]
    dn = np.einsum("ij,ij->i", dd, model.N[j])
    dt = np.sqrt(np.maximum(np.einsum("ij,ij->i", dd, dd) - dn * dn, 0.0))
    e2 = dn * dn + np.maximum(dt - model.local_spacing[j], 0.0) ** 2
    e2 = np.where(ok.any(axis=1), np.minimum(e2, h * h), h * h)
    if keep < 1.0:
        e2 = np.sort(e2)[: max(1, int(np.ceil(keep * len(e2))))]
    return float(np.sqrt(e2.mean()))


def symmetry_directions(model, *, angles=(0.15, 0.4, 1.0), max_rms=0.1, keep=0.98, max_points=1500):
    """Rotations that map the whole model onto itself: the directions its shape can never observe.

    Each eigenvector of the model's rotational point-to-plane information is tried: the model (up to ``max_points``
    points, evenly picked) is turned about it, through the centroid, by each of ``+-angles`` (rad)
    and its distance to the model surface measured as in :func:`unobserved_directions`
    (``h`` = the surface motion at half the diameter), over the best ``keep`` of the points (a
    narrow bevel holds too few samples to find a neighbour of its own normal, and each such point
    counts as ``h``: 1 % of them alone gives 0.1 h). An axis about which every turn keeps that
    RMS distance below ``max_rms * h`` is a continuous symmetry: a revolved object's axis (all
    three for a sphere). Along it the registration, which sees geometry only, has nothing to go
    by whatever points it is given (a touching hand's included), so the tracker holds it always.

    Returns U (6, k), orthonormal, in the scaled coordinates of :func:`unobserved_directions`
    (rotation only: ``(a, 0)`` for an axis a); k = 0 for an object with no continuous symmetry.
    """
    P = model.P
    if len(P) < 6:
        return np.zeros((6, 0))
    idx = np.linspace(0, len(P) - 1, min(max_points, len(P))).astype(np.int64)
    M, Nm = P[idx], model.N[idx]
    # candidate axes: the eigenvectors of sum (m x n)(m x n)^T, the rotation block of the whole
    # model's point-to-plane information; a revolved surface's axis is its null direction (every
    # normal meets the axis), which principal axes of the points give only to a degree or so
    C = np.cross(P, model.N)
    _, axes = np.linalg.eigh(C.T @ C)
    rho = 0.5 * model.diameter
    out = []
    for a in axes.T:
        ok = True
        for th in angles:
            h = th * rho
            xi = np.concatenate([a * th, np.zeros(3)])
            if max(_surface_rms(model, M, Nm, xi, h, keep), _surface_rms(model, M, Nm, -xi, h, keep)) >= max_rms * h:
                ok = False
                break
        if ok:
            out.append(np.concatenate([a, np.zeros(3)]))
    return np.stack(out, axis=1) if out else np.zeros((6, 0))
