"""Parameter and input checks specific to polar_sim.gpis (shared ones live in polar_sim._validation)."""

from __future__ import annotations

import numpy as np

from polar_sim._validation import as_float_array, as_positive_float

__all__ = ["check_params", "as_directions", "MAX_CLUSTER_NODES", "MAX_TRAIN_CAP", "MAX_RANGE_NOISE",
           "MIN_SAMPLE_SPACING"]

MAX_CLUSTER_NODES = 100_000     # tree nodes per cluster cell (2D default 341, 3D 585)
#: train_cap's limit: a local GP of that many samples keeps a Cholesky factor of 8 * cap**2 bytes
#: (134 MB at the limit; the default cap is 32).
MAX_TRAIN_CAP = 4096
#: range_noise's limit, m: beyond it no beam carries information, and squares of the noise
#: overflow long before 1e300.
MAX_RANGE_NOISE = 100.0
#: sample_spacing's lower limit, m: spacings are divided by (a 1e-300 spacing overflowed there).
MIN_SAMPLE_SPACING = 1e-6

_ALLOW_ZERO = {"fbias", "min_grad_noise", "map_noise", "min_range", "blend_near", "retrain_tol"}
_OPTIONAL = {"surfel_radius", "free_res", "retrain_tol", "sample_spacing"}
_NOT_FLOAT = {"legacy", "sensor_offset", "angle_obs_limit", "obs_skip"}


def check_params(est, vec2=()):
    """Check an estimator's constructor parameters; return them as a dict of clean values.

    Floats must be finite and > 0 (>= 0 for fbias, noise floors, min_range, blend_near);
    ``vec2`` names hold 2-vectors. Raises ``ValueError``/``TypeError`` naming the parameter.
    The result is remembered with an exact fingerprint of the values it was computed from
    (every update asks again, and the answer changes only when a parameter does).
    """
    memo = est.__dict__.get("_checked_memo")
    vals = [getattr(est, k) for k in est._PARAMS]
    if memo is not None and all(a is b and type(a) not in (np.ndarray, list)
                                for a, b in zip(vals, memo[0])):
        return dict(memo[2])            # the very same immutable objects: nothing changed
    key = _fingerprint(est)
    if key is not None and memo is not None and memo[1] == key:
        est.__dict__["_checked_memo"] = (vals, key, memo[2])
        return dict(memo[2])
    out = _check(est, vec2)
    if key is not None:
        est.__dict__["_checked_memo"] = (vals, key, out)
    return dict(out)


def _fingerprint(est):
    """The parameters' values with their types (arrays by dtype, shape and bytes); None when a
    value is of another kind (it is then checked afresh every time)."""
    key = []
    for k in est._PARAMS:
        v = getattr(est, k)
        if isinstance(v, np.ndarray):
            key.append((k, np.ndarray, v.dtype.str, v.shape, v.tobytes()))
        elif isinstance(v, (tuple, list)) and all(type(x) in _PLAIN for x in v):
            key.append((k, type(v), tuple((type(x), x) for x in v)))
        elif type(v) in _PLAIN:
            key.append((k, type(v), v))
        else:
            return None
    return tuple(key)


_PLAIN = (bool, int, float, str, type(None), np.float64, np.int64, np.bool_)


def _check(est, vec2):
    out = {}
    for k in est._PARAMS:
        v = getattr(est, k)
        if k in getattr(est, "CHOICES", {}):
            allowed = est.CHOICES[k]
            if not isinstance(v, str) or v not in allowed:
                raise ValueError(f"{k}: expected one of {', '.join(map(repr, allowed))}, got {v!r}")
            out[k] = v
        elif k == "legacy":
            if not isinstance(v, (bool, np.bool_)):
                raise TypeError(f"legacy: expected a bool, got {type(v).__name__}")
            out[k] = bool(v)
        elif k in vec2:
            a = as_float_array(v, k)
            if a.shape != (2,) or not np.isfinite(a).all():
                raise ValueError(f"{k}: expected 2 finite numbers, got {v!r}")
            out[k] = a
        elif k == "obs_skip":
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"obs_skip: expected an integer >= 1, got {v!r}")
            out[k] = int(v)
        elif k == "train_cap":
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer))
                                  or not 1 <= v <= MAX_TRAIN_CAP):
                raise ValueError(f"train_cap: expected None or an integer in [1, {MAX_TRAIN_CAP}] "
                                 f"(MAX_TRAIN_CAP), got {v!r}")
            out[k] = None if v is None else int(v)
        elif k in _OPTIONAL and v is None:
            out[k] = None
        else:
            out[k] = as_positive_float(v, k, allow_zero=k in _ALLOW_ZERO)
            _check_limit(k, out[k])
    if "angle_obs_limit" in out and not out["angle_obs_limit"][0] < out["angle_obs_limit"][1]:
        raise ValueError("angle_obs_limit: expected (low, high) with low < high")
    lo = "min_range" if "min_range" in out else "min_depth"
    hi = "max_range" if "max_range" in out else "max_depth"
    if not out[lo] < out[hi]:
        raise ValueError(f"{lo}/{hi}: expected {lo} < {hi}, got {out[lo]} and {out[hi]}")
    if not out["blend_near"] < out["blend_far"]:
        raise ValueError("blend_near/blend_far: expected blend_near < blend_far")
    if not out["min_half"] <= out["cluster_half"] <= out["init_half"] <= out["max_half"] * 2:
        raise ValueError("min_half <= cluster_half <= init_half <= 2*max_half is required")
    # a cluster owns a complete subtree down to leaves below min_half (min_half / 2 for the
    # faces of thin walls): its node count must stay bounded
    lvl, h = 0, out["cluster_half"]
    while not h < 0.5 * out["min_half"] and lvl <= 64:
        h, lvl = h / 2.0, lvl + 1
    B = 1 << int(est.dim)
    if (B ** (lvl + 1) - 1) // (B - 1) > MAX_CLUSTER_NODES:
        raise ValueError(f"cluster_half/min_half: {out['cluster_half']} / {out['min_half']} gives "
                         f"clusters of more than {MAX_CLUSTER_NODES} tree nodes (the limit); "
                         "raise min_half or lower cluster_half")
    r = out["init_half"] / out["cluster_half"]
    if abs(np.log2(r) - round(np.log2(r))) > 1e-9:
        raise ValueError("init_half / cluster_half must be a power of two")
    return out


def _check_limit(k, v):
    """The limits of range_noise and sample_spacing (see MAX_RANGE_NOISE, MIN_SAMPLE_SPACING)."""
    if k == "range_noise" and v > MAX_RANGE_NOISE:
        raise ValueError(f"range_noise: expected at most {MAX_RANGE_NOISE:g} m (MAX_RANGE_NOISE), got {v!r}")
    if k == "sample_spacing" and v < MIN_SAMPLE_SPACING:
        raise ValueError(f"sample_spacing: expected at least {MIN_SAMPLE_SPACING:g} m (MIN_SAMPLE_SPACING), "
                         f"got {v!r}")


def as_directions(x, name, *, n=None):
    """Return unit ray directions (n, 3) as float64; zero-length or non-finite rows raise."""
    a = as_float_array(x, name)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (n, 3), got {a.shape}")
    if n is not None and a.shape[0] != n:
        raise ValueError(f"{name}: expected {n} rows to match the ranges, got {a.shape[0]}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: contains NaN or inf")
    L = np.linalg.norm(a, axis=1)
    if (L < 1e-12).any():
        raise ValueError(f"{name}: contains zero-length directions")
    return a / L[:, None]
