"""The Gauss-Newton steps of :func:`~polar_sim.registration.register_sdf` as numba kernels.

:func:`linearise` forms the normal equations of a scan's points from the map's answers in one
pass (one call per iteration instead of some forty small numpy operations, which on a GPIS map
cost as much as the map query itself), :func:`gauss_newton_step` solves them, and
:func:`apply_2d`, :func:`split_2d`, :func:`correction_2d` move a planar pose. A map whose query is
a numba kernel (``GPISMap2D``) runs the whole loop in compiled code with them (its
``_register_native``); :func:`register_sdf`'s Python loop is the same algorithm for any map.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["KERNEL_CODES", "linearise", "gauss_newton_step", "transform_2d", "apply_2d", "split_2d",
           "correction_2d", "wrap"]

#: Robust kernel names (``robust.ROBUST_KERNELS``) -> the codes ``linearise`` takes.
KERNEL_CODES = {"huber": 0, "tukey": 1, "none": 2}


@nb.njit(cache=True)
def _rho_weight(r, kind, scale):
    """(rho(r), rho'(r) / r) of ``robust.robust_cost`` / ``robust.robust_weight``."""
    a = abs(r)
    if kind == 0:
        if a <= scale:
            return 0.5 * a * a, 1.0
        return scale * (a - 0.5 * scale), scale / max(a, scale)
    if kind == 1:
        u = min(a / scale, 1.0)
        c = 1.0 - u * u
        return scale * scale / 6.0 * (1.0 - c ** 3), c * c
    return 0.5 * a * a, 1.0


@nb.njit(cache=True)
def linearise(q, d, g, v, centre, max_var, sigma2, kind, scale, H, b):
    """Normal equations of the points q (n, dim) with map answers d (n,), g (n, dim), v (n,).

    A point is used where d, |g| and v are finite, |g| > 1e-9 and v <= ``max_var``. Its
    residual is d, its Jacobian row the unit gradient n through the pose: 2D (x, y, theta) with
    the rotation about ``centre`` (the base position), ``[n_x, n_y, n_y l_x - n_x l_y]`` with
    ``l = q - centre``; 3D the twist (omega, v), ``[(q - centre) x n, n]``. Its weight is
    ``rho'(d) / d / (max(v, 0) + sigma2)``. Writes ``H = J^T W J`` (dof, dof) and
    ``b = J^T W d`` (dof,); returns (points used, sum of ``rho(d) / (max(v, 0) + sigma2)``,
    ``sum w d^2``, ``sum d^2``).
    """
    n, dim = q.shape
    dof = H.shape[0]
    H[:] = 0.0
    b[:] = 0.0
    J = np.empty(dof)
    used = 0
    cost = 0.0
    wrr = 0.0
    r2 = 0.0
    for i in range(n):
        gn = 0.0
        for k in range(dim):
            gn += g[i, k] * g[i, k]
        gn = np.sqrt(gn)
        if not (np.isfinite(d[i]) and np.isfinite(gn) and gn > 1e-9 and np.isfinite(v[i])
                and v[i] <= max_var):
            continue
        r = d[i]
        iv = 1.0 / (max(v[i], 0.0) + sigma2)
        rho, wr = _rho_weight(r, kind, scale)
        if dim == 2:
            n0 = g[i, 0] / gn
            n1 = g[i, 1] / gn
            J[0] = n0
            J[1] = n1
            J[2] = n1 * (q[i, 0] - centre[0]) - n0 * (q[i, 1] - centre[1])
        else:
            n0 = g[i, 0] / gn
            n1 = g[i, 1] / gn
            n2 = g[i, 2] / gn
            l0 = q[i, 0] - centre[0]
            l1 = q[i, 1] - centre[1]
            l2 = q[i, 2] - centre[2]
            J[0] = l1 * n2 - l2 * n1
            J[1] = l2 * n0 - l0 * n2
            J[2] = l0 * n1 - l1 * n0
            J[3] = n0
            J[4] = n1
            J[5] = n2
        w = wr * iv
        for a in range(dof):
            wa = w * J[a]
            b[a] += wa * r
            for c in range(a + 1):
                H[a, c] += wa * J[c]
        used += 1
        cost += rho * iv
        wrr += w * r * r
        r2 += r * r
    for a in range(dof):
        for c in range(a):
            H[c, a] = H[a, c]
    return used, cost, wrr, r2


@nb.njit(cache=True)
def gauss_newton_step(H, b, delta):
    """``H += (1e-9 trace(H) / dof + 1e-12) I`` (a degenerate scene stays solvable), then
    ``delta = -H^-1 b`` by Cholesky (H is symmetric positive definite)."""
    dof = H.shape[0]
    tr = 0.0
    for a in range(dof):
        tr += H[a, a]
    reg = 1e-9 * tr / dof + 1e-12
    for a in range(dof):
        H[a, a] += reg
    L = np.zeros((dof, dof))
    for j in range(dof):
        s = H[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        L[j, j] = np.sqrt(s)
        for i in range(j + 1, dof):
            s = H[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    for i in range(dof):                 # L y = -b
        s = -b[i]
        for k in range(i):
            s -= L[i, k] * delta[k]
        delta[i] = s / L[i, i]
    for i in range(dof - 1, -1, -1):     # L' delta = y
        s = delta[i]
        for k in range(i + 1, dof):
            s -= L[k, i] * delta[k]
        delta[i] = s / L[i, i]


@nb.njit(cache=True)
def wrap(a):
    """An angle wrapped to [-pi, pi) (as ``geometry.wrap_angle``)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@nb.njit(cache=True)
def transform_2d(x, pts, out):
    """Points (n, 2) of the frame with planar pose x = (x, y, theta) into the world (out)."""
    c, s = np.cos(x[2]), np.sin(x[2])
    for i in range(pts.shape[0]):
        out[i, 0] = x[0] + c * pts[i, 0] - s * pts[i, 1]
        out[i, 1] = x[1] + s * pts[i, 0] + c * pts[i, 1]


@nb.njit(cache=True)
def apply_2d(x, delta):
    """The planar pose x moved by delta (translation added, angle wrapped)."""
    y = x + delta
    y[2] = wrap(y[2])
    return y


@nb.njit(cache=True)
def split_2d(delta):
    """(translation, rotation) size of a planar step."""
    return np.hypot(delta[0], delta[1]), abs(delta[2])


@nb.njit(cache=True)
def correction_2d(x, x0):
    """(translation, rotation) between two planar poses."""
    return np.hypot(x[0] - x0[0], x[1] - x0[1]), abs(wrap(x[2] - x0[2]))
