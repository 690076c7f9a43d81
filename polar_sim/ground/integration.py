"""Pose integration of a ground vehicle's speed and rotation rates (spec §6.1, with the B27 fix).

:func:`motion_step` is the one step both :class:`polar_sim.ground.GroundVO` and the offline
re-integration use; :func:`integrate` re-integrates whole sequences of per-image estimates (e.g. the
same estimates in the plane and in 3-D, or with other speeds), exactly as the estimator does.
Camera frame: OpenCV axes (x right, y down, z forward); yaw is the rotation about +y.
"""

from __future__ import annotations

import numpy as np

from polar_sim.geometry import so3_exp

__all__ = ["motion_step", "integrate"]


def motion_step(V, rates, dt, mode="planar", *, semi_implicit=False):
    """The (4, 4) motion over ``dt`` s at speed ``V`` (m/s, along +z) and rates ``rates`` (3,) rad/s.

    ``mode="planar"``: an exact unicycle arc with the yaw rate ``rates[1]`` (``semi_implicit``: turn,
    then move along the new heading, as the published code); ``"3d"``: R = exp([Ω] dt) and the
    translation (0, 0, V dt) rotated by exp([Ω] dt / 2).
    """
    step = np.eye(4)
    if mode == "3d":
        step[:3, :3] = so3_exp(rates * dt)
        step[:3, 3] = so3_exp(rates * dt / 2) @ np.array([0.0, 0.0, V * dt])
        return step
    w = rates[1]
    a = w * dt
    ca, sa = np.cos(a), np.sin(a)
    step[:3, :3] = [[ca, 0.0, sa], [0.0, 1.0, 0.0], [-sa, 0.0, ca]]
    if semi_implicit:
        step[:3, 3] = [V * dt * sa, 0.0, V * dt * ca]
    elif abs(a) < 1e-9:
        step[:3, 3] = [V * dt * a / 2, 0.0, V * dt]
    else:
        step[:3, 3] = [V / w * (1.0 - ca), 0.0, V / w * sa]
    return step


def integrate(times, speeds, rates, mode="3d"):
    """Poses (n, 4, 4), camera k in camera 0's frame, integrated from per-image estimates.

    ``times`` (n,) s; ``speeds`` (n,) m/s and ``rates`` (n, 3) rad/s are the values reported when
    image k arrives (they describe the middle frame k − 1): the step k − 1 → k uses those of image k,
    and the step 0 → 1 reuses those of image 2 (the B27 fix, as ``GroundVO`` does). Non-finite
    speeds or rates raise ``ValueError``.
    """
    t = np.asarray(times, dtype=np.float64)
    V = np.asarray(speeds, dtype=np.float64)
    R = np.asarray(rates, dtype=np.float64)
    n = len(t)
    if t.shape != (n,) or V.shape != (n,) or R.shape != (n, 3):
        raise ValueError(f"times, speeds, rates: expected shapes (n,), (n,), (n, 3), got {t.shape}, {V.shape}, {R.shape}")
    if not (np.isfinite(t).all() and np.isfinite(V).all() and np.isfinite(R).all()):
        raise ValueError("times, speeds, rates: contain NaN or inf")
    if mode not in ("planar", "3d"):
        raise ValueError(f"mode: expected 'planar' or '3d', got {mode!r}")
    P = np.tile(np.eye(4), (n, 1, 1))
    for k in range(1, n):
        j = max(k, 2) if n > 2 else k
        P[k] = P[k - 1] @ motion_step(float(V[j]), R[j], t[k] - t[k - 1], mode)
    return P
