"""SE(2) and SE(3) helpers over ``scipy.spatial.transform``.

Conventions: a 3D pose is a 4x4 homogeneous matrix ``T_a_b`` that maps points in frame b to
frame a (``p_a = T_a_b @ p_b``). A planar pose is ``(x, y, theta)`` in metres and radians. A twist
on SE(3) is ordered ``(omega, v)`` (rotation first, rad then m), as in the tracking spec; the
exponential map is the closed form (Rodrigues with the left Jacobian), exact to round-off.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "make_pose",
    "inv_pose",
    "transform_points",
    "hat",
    "so3_exp",
    "so3_log",
    "se3_exp",
    "se3_log",
    "wrap_angle",
    "pose2d_to_matrix",
    "matrix_to_pose2d",
    "pose2d_to_T",
    "T_to_pose2d",
    "compose2d",
    "inv2d",
    "between2d",
    "quat_to_matrix",
    "matrix_to_quat",
    "pinhole_intrinsics",
    "diameter",
    "rigid_alignment",
    "CV_FROM_GL",
]

#: Rotation from MuJoCo/OpenGL camera axes (x right, y up, looking down -z) to OpenCV camera
#: axes (x right, y down, looking down +z): ``R_world_cv = R_world_gl @ CV_FROM_GL``.
CV_FROM_GL = np.diag([1.0, -1.0, -1.0])


def make_pose(R=None, t=None):
    """4x4 pose from a rotation (3, 3) and a translation (3,) in metres."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if t is not None:
        T[:3, 3] = t
    return T


def inv_pose(T):
    """Inverse of a rigid transform (4, 4), or a stack (..., 4, 4)."""
    T = np.asarray(T, dtype=np.float64)
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    out = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, t)
    out[..., 3, 3] = 1.0
    return out


def transform_points(T, points):
    """Apply a pose (4, 4) to points (n, 3): returns ``R @ p + t`` of shape (n, 3)."""
    return points @ T[:3, :3].T + T[:3, 3]


def hat(w):
    """Skew-symmetric matrix (3, 3) of a vector (3,), so that ``hat(w) @ x == cross(w, x)``."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def so3_exp(w):
    """Rotation matrix (3, 3) of a rotation vector (3,) in radians."""
    return Rotation.from_rotvec(np.asarray(w, dtype=np.float64)).as_matrix()


def so3_log(R):
    """Rotation vector (3,) in radians of a rotation matrix (3, 3)."""
    return Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_rotvec()


def _left_jacobian(w):
    th = np.linalg.norm(w)
    W = hat(w)
    if th < 1e-8:
        return np.eye(3) + 0.5 * W + W @ W / 6.0
    a = (1.0 - np.cos(th)) / th**2
    b = (th - np.sin(th)) / th**3
    return np.eye(3) + a * W + b * W @ W


def se3_exp(xi):
    """Pose (4, 4) of a twist ``xi = (omega, v)`` of shape (6,) (rad, m)."""
    xi = np.asarray(xi, dtype=np.float64)
    w, v = xi[:3], xi[3:]
    return make_pose(so3_exp(w), _left_jacobian(w) @ v)


def se3_log(T):
    """Twist ``(omega, v)`` of shape (6,) of a pose (4, 4); inverse of :func:`se3_exp`."""
    T = np.asarray(T, dtype=np.float64)
    w = so3_log(T[:3, :3])
    v = np.linalg.solve(_left_jacobian(w), T[:3, 3])
    return np.concatenate([w, v])


def wrap_angle(a):
    """Wrap angles (any shape) to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def pose2d_to_matrix(p):
    """3x3 homogeneous matrix of a planar pose ``(x, y, theta)``."""
    x, y, th = p
    c, s = np.cos(th), np.sin(th)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def matrix_to_pose2d(M):
    """Planar pose ``(x, y, theta)`` of a 3x3 homogeneous matrix."""
    return np.array([M[0, 2], M[1, 2], np.arctan2(M[1, 0], M[0, 0])])


def pose2d_to_T(p, z=0.0):
    """4x4 pose of a planar pose ``(x, y, theta)``: rotation about world z, at height ``z``."""
    x, y, th = p
    return make_pose(Rotation.from_euler("z", th).as_matrix(), [x, y, z])


def T_to_pose2d(T):
    """Planar pose ``(x, y, yaw)`` of a 4x4 pose: position in the xy plane and the heading of its x axis."""
    return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])


def compose2d(a, b):
    """Planar composition ``a ∘ b`` of poses (3,) or stacks (n, 3): b expressed in a's frame."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap_angle(a[..., 2] + b[..., 2])], axis=-1)


def inv2d(a):
    """Inverse of planar poses (3,) or (n, 3)."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, wrap_angle(-a[..., 2])], axis=-1)


def between2d(a, b):
    """Relative planar pose ``a^-1 ∘ b``: b expressed in a's frame."""
    return compose2d(inv2d(a), b)


def quat_to_matrix(q):
    """Rotation matrix (3, 3) of a scalar-first quaternion ``(w, x, y, z)`` (MuJoCo order)."""
    return Rotation.from_quat(np.asarray(q, dtype=np.float64), scalar_first=True).as_matrix()


def matrix_to_quat(R):
    """Scalar-first quaternion ``(w, x, y, z)`` (MuJoCo order) of a rotation matrix (3, 3)."""
    return Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_quat(scalar_first=True)


def pinhole_intrinsics(width, height, fovy_deg):
    """Pinhole K (3, 3) of a ``width`` x ``height`` px camera with vertical field of view
    ``fovy_deg`` (degrees), as MuJoCo renders it: square pixels, f = (H/2) / tan(fovy/2) px, the
    principal point at the image centre ((W-1)/2, (H-1)/2); OpenCV convention. The one home of
    this formula: the simulator's cameras and the modules' synthetic scenes use it."""
    f = 0.5 * height / np.tan(np.radians(fovy_deg) / 2)
    return np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])


def diameter(points):
    """Largest distance between two of the points (n, 3) (or (n, 2)), in their unit: exact,
    searched over the convex hull's vertices (all points when the set is flat or degenerate).
    The one home of an object's diameter (ADD thresholds, tracking gates, scene metadata)."""
    from scipy.spatial import ConvexHull, QhullError

    P = np.asarray(points, dtype=np.float64)
    if len(P) > P.shape[1] + 1:
        try:
            P = P[ConvexHull(P).vertices]
        except QhullError:  # flat or degenerate point sets: every point is a candidate
            pass
    best = 0.0
    for i in range(0, len(P), 1024):  # blocks of rows keep the pairwise table small
        best = max(best, float(np.linalg.norm(P[i : i + 1024, None] - P[None], axis=2).max()))
    return best


def rigid_alignment(P, Q, *, with_scale=False):
    """Least-squares alignment of paired points: (R (d, d), t (d,), s) minimising
    ``sum |s R p_i + t - q_i|^2`` over P, Q (n, d), d = 2 or 3 (s = 1 unless ``with_scale``).

    The SVD solution of Arun et al. (1987) with Umeyama's (1991) reflection fix and scale. The one
    home of rigid alignment: registration's Kabsch step and the trajectory metrics' alignment use it.
    """
    P, Q = np.asarray(P, dtype=np.float64), np.asarray(Q, dtype=np.float64)
    dim = P.shape[1]
    pc, qc = P.mean(axis=0), Q.mean(axis=0)
    xp = P - pc
    U, S, Vt = np.linalg.svd(xp.T @ (Q - qc))
    D = np.eye(dim)
    D[-1, -1] = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ D @ U.T
    var = float((xp**2).sum())
    s = float(np.trace(np.diag(S) @ D) / var) if with_scale and var > 0 else 1.0
    return R, qc - s * R @ pc, s
