"""State fingerprints: equal digests mean equal state (arrays, generators, MuJoCo data, attributes)."""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np

__all__ = ["state_digest", "TIMING_FIELDS"]

_MJDATA_FIELDS = ("time", "qpos", "qvel", "act", "ctrl", "mocap_pos", "mocap_quat", "qacc_warmstart", "xpos",
                  "userdata", "plugin_state")


def state_digest(obj, *, ignore=()) -> str:
    """SHA-256 over an object's state: its attributes, recursively (arrays by dtype, shape and
    bytes; generators by their bit-generator state; MuJoCo ``MjData`` by its state arrays).
    Attribute names in ``ignore`` (caches) are skipped. Equal digests mean equal state."""
    h = hashlib.sha256()
    _feed(h, obj, 0, set(), frozenset(ignore))
    return h.hexdigest()


def _feed(h, x, depth, seen, ignore):
    if depth > 8:
        return
    if x is None or isinstance(x, (bool, int, float, complex, str, bytes, np.generic)):
        h.update(repr((type(x).__name__, x)).encode())
        return
    if isinstance(x, np.ndarray):
        h.update(f"nd{x.dtype.str}{x.shape}".encode())
        if x.dtype.hasobject:
            for e in x.flat:
                _feed(h, e, depth + 1, seen, ignore)
        else:
            h.update(np.ascontiguousarray(x).tobytes())
        return
    if id(x) in seen:
        h.update(b"<seen>")
        return
    seen.add(id(x))
    if isinstance(x, np.random.Generator):
        h.update(repr(x.bit_generator.state).encode())
        return
    if isinstance(x, np.random.RandomState):
        _feed(h, x.get_state(legacy=False), depth + 1, seen, ignore)
        return
    if isinstance(x, dict):
        for k in sorted(x, key=repr):
            h.update(repr(k).encode())
            _feed(h, x[k], depth + 1, seen, ignore)
        return
    if isinstance(x, (list, tuple, set, frozenset)):
        items = sorted(x, key=repr) if isinstance(x, (set, frozenset)) else x
        h.update(f"{type(x).__name__}{len(items)}".encode())
        for e in items:
            _feed(h, e, depth + 1, seen, ignore)
        return
    tname = type(x).__name__
    mod = type(x).__module__ or ""
    if tname == "MjData":
        for f in _MJDATA_FIELDS:
            if hasattr(x, f):
                _feed(h, np.asarray(getattr(x, f)), depth + 1, seen, ignore)
        return
    if mod.startswith(("mujoco", "scipy", "trimesh", "cv2", "threading", "_thread", "numba")) or callable(x) and not hasattr(x, "__dict__"):
        h.update(tname.encode())
        return
    d = getattr(x, "__dict__", None)
    if d is None and hasattr(type(x), "__slots__"):
        d = {s: getattr(x, s) for s in type(x).__slots__ if hasattr(x, s)}
    if d is None:
        h.update(tname.encode())
        return
    h.update(tname.encode())
    for k in sorted(d):
        if k in ignore:
            continue
        h.update(k.encode())
        _feed(h, d[k], depth + 1, seen, ignore)


#: Result fields that measure wall time, not output: left out of "same output" comparisons.
TIMING_FIELDS = frozenset({"time_s", "stage_times", "timings", "timing", "elapsed", "elapsed_s", "seconds",
                           "cpu_s", "wall_s", "times_s", "runtime_s"})


def flatten(x, out=None):
    """Arrays and scalars of a result, in a fixed order, for bit-identical comparisons (timing
    fields, :data:`TIMING_FIELDS`, left out)."""
    out = [] if out is None else out
    if isinstance(x, np.ndarray):
        out.append(x)
    elif isinstance(x, (int, float, bool, str, np.generic)) or x is None:
        out.append(np.asarray(x if x is not None else np.nan))
    elif isinstance(x, dict):
        for k in sorted(x, key=repr):
            if k not in TIMING_FIELDS:
                flatten(x[k], out)
    elif isinstance(x, (list, tuple)):
        for e in x:
            flatten(e, out)
    elif dataclasses.is_dataclass(x):
        for f in dataclasses.fields(x):
            if f.name not in TIMING_FIELDS:
                flatten(getattr(x, f.name), out)
    elif hasattr(x, "__dict__"):
        for k in sorted(vars(x)):
            if k not in TIMING_FIELDS:
                flatten(getattr(x, k), out)
    return out


def output_digest(x):
    """SHA-256 of a result's flattened arrays (dtype, shape, bytes; timing fields left out): what
    a subprocess prints so that its result is compared bit for bit without pickling it."""
    h = hashlib.sha256()
    for a in flatten(x):
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes() if a.dtype.kind not in "OUS" else repr(a.tolist()).encode())
    return h.hexdigest()


def same_output(a, b):
    """True when two results flatten to the same arrays, bit for bit (NaN equal to NaN)."""
    fa, fb = flatten(a), flatten(b)
    if len(fa) != len(fb):
        return False
    for x, y in zip(fa, fb):
        x, y = np.asarray(x), np.asarray(y)
        if x.shape != y.shape or x.dtype != y.dtype:
            return False
        if x.dtype.kind in "fc":
            if not np.array_equal(x, y, equal_nan=True):
                return False
        elif not np.array_equal(x, y):
            return False
    return True
