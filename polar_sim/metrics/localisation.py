"""Errors of planar pose estimates against the truth, and their statistics pooled over steps.

Poses are ``(x, y, theta)`` in metres and radians. A pose error is the pair (position error m,
heading error deg): the Euclidean distance between the two positions, and the absolute
difference of the two headings wrapped to [0, 180] degrees. The localisation experiments score
every step of every drive with :func:`pose2d_errors` and pool the steps with
:func:`pooled_pose2d_errors`.
"""

from __future__ import annotations

import numpy as np

from polar_sim._validation import as_float, as_float_array

__all__ = ["heading_error_deg", "pose2d_errors", "pooled_pose2d_errors"]


def _finite(x, name):
    a = as_float_array(x, name)
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: contains NaN or inf")
    return a


def heading_error_deg(est, truth):
    """|est - truth| of headings in radians, wrapped to [0, 180] degrees.

    ``est`` and ``truth`` are numbers or arrays of one shape; a float for two numbers, else an
    array of that shape.
    """
    e, t = _finite(est, "est"), _finite(truth, "truth")
    if e.shape != t.shape:
        raise ValueError(f"truth: expected the shape of est {e.shape}, got {t.shape}")
    out = np.abs(np.degrees((e - t + np.pi) % (2 * np.pi) - np.pi))
    return float(out) if out.ndim == 0 else out


def pose2d_errors(est, truth):
    """Position error (m) and heading error (deg) of poses ``est`` (n, 3) against ``truth`` (n, 3):
    an array (n, 2)."""
    e, t = _finite(est, "est"), _finite(truth, "truth")
    if e.ndim != 2 or e.shape[1] != 3:
        raise ValueError(f"est: expected poses (x, y, theta) of shape (n, 3), got {e.shape}")
    if t.shape != e.shape:
        raise ValueError(f"truth: expected the shape of est {e.shape}, got {t.shape}")
    return np.column_stack([np.hypot(e[:, 0] - t[:, 0], e[:, 1] - t[:, 1]), heading_error_deg(e[:, 2], t[:, 2])])


def pooled_pose2d_errors(errors, fail_m):
    """Statistics of pose errors (n, 2) (position m, heading deg; :func:`pose2d_errors`) pooled
    over steps.

    Returns a dict: ``steps`` (n), the median, 90th percentile and maximum of the position error
    (``pos_median_m``, ``pos_p90_m``, ``pos_max_m``), the median and 90th percentile of the heading
    error (``head_median_deg``, ``head_p90_deg``), and ``fail_steps``, the steps more than
    ``fail_m`` metres off.
    """
    e = _finite(errors, "errors")
    if e.ndim != 2 or e.shape[1] != 2 or len(e) == 0:
        raise ValueError(f"errors: expected (position m, heading deg) rows of shape (n, 2), n >= 1, got {e.shape}")
    if (e < 0).any():
        raise ValueError("errors: expected errors >= 0")
    fail_m = as_float(fail_m, "fail_m", minimum=0.0)
    return {"steps": len(e), "pos_median_m": float(np.median(e[:, 0])), "pos_p90_m": float(np.percentile(e[:, 0], 90)),
            "pos_max_m": float(e[:, 0].max()), "head_median_deg": float(np.median(e[:, 1])),
            "head_p90_deg": float(np.percentile(e[:, 1], 90)), "fail_steps": int((e[:, 0] > fail_m).sum())}
