"""Scan handling shared by the registration code, the GPIS localiser and the baselines.

Valid beams, sensor-frame end points and planar sensor offsets, planar transforms, arc-length
subsampling, and the two 3D scan forms (depth image + intrinsics, or ray directions + ranges).
Input checks go through :mod:`polar_sim._validation`; the one check it lacks (a planar sensor
offset of shape (2,) or (3,)) lives here.
"""

from __future__ import annotations

import math

import numpy as np

from polar_sim._validation import (
    as_float_array,
    as_angles,
    as_depth,
    as_intrinsics,
    as_points,
    as_ranges,
    check_same_length,
)

__all__ = ["as_sensor_offset", "as_scan2d", "valid_beams", "beam_points", "transform2d",
           "arc_length_subsample", "scan3d_points"]


def as_sensor_offset(offset, name="sensor_offset"):
    """Return a planar sensor mounting ``(x, y, yaw)`` (3,) from (x, y) or (x, y, yaw), m and rad."""
    a = as_float_array(offset, name)
    if a.shape not in ((2,), (3,)):
        raise ValueError(f"{name}: expected (x, y) or (x, y, yaw), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: contains NaN or inf")
    return np.array([a[0], a[1], a[2] if a.shape == (3,) else 0.0])


def as_scan2d(angles, ranges):
    """Validated ``(angles, ranges)``: finite angles (n,), ranges (n,) with NaN/inf kept."""
    angles = as_angles(angles, "angles")
    ranges = as_ranges(ranges, "ranges", n=angles.shape[0])
    return angles, ranges


def valid_beams(ranges, min_range, max_range):
    """Mask (n,) of beams with a return: finite and strictly inside (min_range, max_range)."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(ranges) & (ranges > min_range) & (ranges < max_range)


def beam_points(angles, ranges, offset):
    """End points (n, 2) in the robot base frame of beams ``r (cos a, sin a)`` from a sensor at ``offset``.

    ``offset`` is ``(x, y, yaw)`` of the sensor in the base frame; ranges must be finite.
    """
    a = angles + offset[2]
    return np.column_stack([offset[0] + ranges * np.cos(a), offset[1] + ranges * np.sin(a)])


def transform2d(pose, points):
    """Points (n, 2) in a frame with planar pose ``(x, y, theta)`` -> world frame (n, 2)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    out = np.empty_like(points)
    out[:, 0] = pose[0] + c * points[:, 0] - s * points[:, 1]
    out[:, 1] = pose[1] + s * points[:, 0] + c * points[:, 1]
    return out


def arc_length_subsample(points, n, max_gap=0.5):
    """Indices of at most ``n`` points spread evenly in arc length along an ordered scan (k, 2|3).

    The arc length is the cumulative distance between consecutive end points with jumps capped at
    ``max_gap`` metres, so that occlusion edges do not swallow the budget. Unlike a fixed beam
    stride this gives near surfaces (dense returns) and far ones the same point density.
    """
    k = points.shape[0]
    if k <= n:
        return np.arange(k)
    step = np.minimum(np.linalg.norm(np.diff(points, axis=0), axis=1), max_gap)
    s = np.concatenate([[0.0], np.cumsum(step)])
    targets = np.linspace(0.0, s[-1], n)
    idx = np.minimum(np.searchsorted(s, targets, side="left"), k - 1)
    # non-decreasing: its distinct values are where it changes (np.unique, without the sort)
    return idx[np.concatenate([[True], idx[1:] != idx[:-1]])]


def scan3d_points(scan, *, pixel_stride, min_range, max_range):
    """Sensor-frame points (n, 3) of a 3D scan given as ``(depth, K)`` or ``(directions, ranges)``.

    ``depth`` (H, W) is metric planar depth with OpenCV axes (z forward); every ``pixel_stride``-th
    pixel in each direction is used; zero, NaN and inf mean no return. ``directions`` (n, 3) need not
    be unit length (they are normalised); ``ranges`` (n,) in metres, NaN/inf = no return. Returns
    only points whose depth / range lies strictly inside ``(min_range, max_range)``.
    """
    if not isinstance(scan, (tuple, list)) or len(scan) != 2:
        raise TypeError("scan: expected a tuple (depth, K) or (directions, ranges)")
    first, second = scan
    second_a = as_float_array(second, "scan")
    if second_a.ndim == 2:
        K = as_intrinsics(second_a, "K")
        depth = as_depth(first, "depth")
        h, w = depth.shape
        rows = np.arange(0, h, pixel_stride)
        cols = np.arange(0, w, pixel_stride)
        z = depth[np.ix_(rows, cols)]
        uu, vv = np.meshgrid(cols.astype(np.float64), rows.astype(np.float64))
        ok = valid_beams(z, min_range, max_range)
        z = z[ok]
        x = (uu[ok] - K[0, 2] - K[0, 1] * (vv[ok] - K[1, 2]) / K[1, 1]) / K[0, 0] * z
        y = (vv[ok] - K[1, 2]) / K[1, 1] * z
        return np.column_stack([x, y, z])
    ranges = as_ranges(second_a, "ranges")
    dirs = as_points(first, 3, "directions", allow_empty=True)
    check_same_length(directions=dirs, ranges=ranges)
    ok = valid_beams(ranges, min_range, max_range)
    norms = np.linalg.norm(dirs[ok], axis=1)
    if (norms <= 0).any():
        raise ValueError("directions: contains a zero-length direction")
    return dirs[ok] * (ranges[ok] / norms)[:, None]
