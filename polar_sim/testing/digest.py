"""State fingerprints: equal digests mean equal state (arrays, generators, MuJoCo data, attributes)."""

from __future__ import annotations

import hashlib

import numpy as np

__all__ = ["state_digest"]



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
