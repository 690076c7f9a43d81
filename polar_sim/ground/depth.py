"""Per-track inverse depth: propagation with the filtered motion and scalar MAP fusion (spec §3.4–3.5)."""

from __future__ import annotations

import numpy as np

__all__ = ["propagate", "fuse"]


def propagate(d, P, u, speed, yaw_rate, dt, q):
    """Predict inverse depths one frame ahead (spec Eq. 4.9–4.10).

    z' = z (1 + u ω dt) - V dt, d' = 1/z', P' = J² P + q with J = (d'/d)² (1 + u ω dt).
    d, P, u : (n,) inverse depth (1/m), its variance ((1/m)²) and the normalised column of the track.
    Points whose predicted depth is not positive keep their value. Returns (d', P').
    """
    d = np.asarray(d, dtype=np.float64)
    ok = np.isfinite(d) & (d > 0)
    d_new = d.copy()
    P_new = np.asarray(P, dtype=np.float64).copy()
    if not ok.any():
        return d_new, P_new
    rot = 1.0 + u[ok] * yaw_rate * dt
    z1 = rot / d[ok] - speed * dt
    good = z1 > 0
    idx = np.flatnonzero(ok)[good]
    d1 = 1.0 / z1[good]
    J = (d1 / d[idx]) ** 2 * rot[good]
    d_new[idx] = d1
    P_new[idx] = J * J * P_new[idx] + q
    return d_new, P_new


def fuse(d_pred, P_pred, d_meas, usable, r, p_reset):
    """Scalar MAP fusion of a measured inverse depth with its prediction (spec §3.4).

    Where ``usable`` (a prior with variance < 5): d = (r d_pred + P d_meas)/(r + P), P = r P/(r + P);
    elsewhere d = d_meas, P = p_reset. Returns (d, P).
    """
    d = np.where(usable, (r * d_pred + P_pred * d_meas) / (r + P_pred), d_meas)
    P = np.where(usable, r * P_pred / (r + P_pred), p_reset)
    return d, P
