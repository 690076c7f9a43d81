"""ICP-G on a planar GPIS map in compiled code: ``register_sdf``'s Gauss-Newton loop with the map's
default query (``_query.faithful``) called directly, so that no iteration returns to Python.

The loop is step for step :func:`polar_sim.registration.sdf._gauss_newton` (the same kernels form
and solve the normal equations and move the pose; ``tests/gpis/test_localize.py`` checks that
both give the same bits); see ``register_sdf`` for the algorithm and the statuses.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from polar_sim.gpis._native import entry
from polar_sim.gpis._query import faithful
from polar_sim.registration.gauss_newton import (apply_2d, correction_2d, gauss_newton_step, linearise,
                                                 split_2d, transform_2d)

__all__ = ["register_2d"]


@entry
@nb.njit(cache=True)
def register_2d(pts, x0, max_iterations, min_points, tol, kind, scale, sigma2, max_var, step_t,
                step_r, corr_t, corr_r, k, sptr, sidx, pos, nrm, sp, sg, gate, use_trust, r_s, fgrid,
                fshape, foff, fres, var_unobs, near, far, sign_h, behind, W, T, legacy, map_scale,
                var_f0, var_g0, fbias, t_info, geo, cgrid, gshape, goff, node_sample, node_internal,
                slot_gen, gp_gen, gp_m, gp_obs, gp_tri, X, kinds, alpha, Lbuf, mmax, H_best):
    """Gauss-Newton with backtracking of the base-frame points pts (n, 2) from the pose x0 (3,).

    Returns (status, iteration, points, rmse, cost, points queried, ct, cr, pose, sum w r^2,
    points of the accepted step, an accepted step exists); the accepted step's H goes into
    ``H_best`` (3, 3). The fields are those of ``registration.sdf._Run``.
    """
    n = pts.shape[0]
    q = np.empty((n, 2))
    d, g, v = np.empty(n), np.empty((n, 2)), np.empty(n)
    H, b, delta = np.empty((3, 3)), np.empty(3), np.empty(3)
    x = x0.copy()
    best_x, best_step = x0.copy(), np.zeros(3)
    best_cost, best_wrr, best_n, has_best = 0.0, 0.0, 0, False
    last_it, last_n, last_rmse, last_cost = 0, 0, np.nan, np.nan
    queried = 0
    for it in range(1, max_iterations + 1):
        transform_2d(x, pts, q)
        faithful(q, k, sptr, sidx, pos, nrm, sp, sg, gate, use_trust, r_s, fgrid, fshape, foff, fres,
                 var_unobs, near, far, sign_h, behind, W, T, legacy, map_scale, var_f0, var_g0, fbias,
                 t_info, geo, cgrid, gshape, goff, node_sample, node_internal, slot_gen, gp_gen, gp_m,
                 gp_obs, gp_tri, X, kinds, alpha, Lbuf, mmax, d, g, v)
        queried += n
        used, cost_sum, wrr, r2 = linearise(q, d, g, v, x[:2].copy(), max_var, sigma2, kind, scale, H,
                                            b)
        if used < min_points:
            if not has_best:
                return 1, it, used, last_rmse, last_cost, queried, 0.0, 0.0, x0.copy(), 0.0, 0, False
            for j in range(3):                # the last step left the mapped area: retreat
                best_step[j] *= 0.5
            x = apply_2d(best_x, best_step)
            continue
        cost = cost_sum / used
        if has_best and cost > best_cost:     # worse: retry half of the last step
            for j in range(3):
                best_step[j] *= 0.5
            dt, dr = split_2d(best_step)
            if dt < tol and dr < tol:
                return (0, it, last_n, last_rmse, last_cost, queried, 0.0, 0.0, best_x.copy(), best_wrr,
                        best_n, True)
            x = apply_2d(best_x, best_step)
            continue
        gauss_newton_step(H, b, delta)
        last_it, last_n, last_rmse, last_cost = it, used, np.sqrt(r2 / used), cost
        dt, dr = split_2d(delta)
        f = min(1.0, step_t / max(dt, 1e-300), step_r / max(dr, 1e-300))
        for j in range(3):
            best_step[j] = delta[j] * f
        best_x[:] = x
        best_cost, best_wrr, best_n, has_best = cost, wrr, used, True
        H_best[:] = H
        x = apply_2d(x, best_step)
        ct, cr = correction_2d(x, x0)
        if ct > corr_t or cr > corr_r:
            return 2, it, last_n, last_rmse, last_cost, queried, ct, cr, x0.copy(), best_wrr, best_n, True
        dt, dr = split_2d(best_step)
        if dt < tol and dr < tol:
            return 0, it, last_n, last_rmse, last_cost, queried, 0.0, 0.0, x, best_wrr, best_n, True
    return 3, last_it, last_n, last_rmse, last_cost, queried, 0.0, 0.0, x, best_wrr, best_n, has_best
