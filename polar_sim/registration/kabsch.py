"""Closed-form rigid alignment of paired points and its Gauss-Newton covariance."""

from __future__ import annotations

import numpy as np

from polar_sim.geometry import hat, rigid_alignment

__all__ = ["kabsch", "point_to_point_covariance"]


def kabsch(P, Q):
    """Homogeneous transform (dim+1, dim+1) minimising ``sum |R p_i + t - q_i|^2``.

    P, Q: paired points (n, dim), dim 2 or 3, metres. The SVD solution of Arun et al. (1987)
    with Umeyama's (1991) reflection fix, without scale.
    """
    dim = P.shape[1]
    R, t, _ = rigid_alignment(P, Q)
    T = np.eye(dim + 1)
    T[:dim, :dim] = R
    T[:dim, dim] = t
    return T


def point_to_point_covariance(Q, T, e):
    """Gauss-Newton covariance of point-to-point registration at the solution.

    Q: the registered points (n, dim) in the world; T: the pose (dim+1, dim+1); e: the residual
    vectors (n, dim), metres. 2D: over (x, y, theta) with the rotation about the pose's position;
    3D: over the twist (omega, v), ``R <- exp(omega) R``, ``t <- t + v`` (the parameterisation of
    :func:`~polar_sim.registration.register_sdf`). Scaled by the a-posteriori variance factor.
    """
    dim = Q.shape[1]
    lever = Q - T[:dim, dim]
    n = len(Q)
    if dim == 2:
        J = np.zeros((n, 2, 3))
        J[:, 0, 0] = J[:, 1, 1] = 1.0
        J[:, 0, 2] = -lever[:, 1]
        J[:, 1, 2] = lever[:, 0]
    else:
        J = np.zeros((n, 3, 6))
        J[:, :, :3] = -np.stack([hat(v) for v in lever])
        J[:, :, 3:] = np.eye(3)
    H = np.einsum("nki,nkj->ij", J, J)
    dof = H.shape[0]
    s2 = float(np.sum(e * e)) / max(dim * n - dof, 1)
    return s2 * np.linalg.inv(H + 1e-12 * np.eye(dof))
