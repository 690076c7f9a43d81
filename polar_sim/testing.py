"""One hostile battery for every module and environment (after scikit-learn's ``check_estimator``
and gymnasium's ``check_env``).

>>> from polar_sim.testing import check_module, check_polar_env, run_battery
>>> for check in check_module("GPISMap2D"):       # small named checks; each raises AssertionError
...     check()
>>> for check in check_polar_env("polar_sim/GPISNav-v0"):
...     check()
>>> counts = run_battery("GPISMap2D.update", n=200)   # the full-size battery of one entry point

**Entry points** (:data:`ENTRY_POINTS`) are the public calls of the contract: ``World`` and its
sensors, ``GPISMap2D``/``3D``, ``localize``, ``GroundVO``, ``ObjectTracker``, the metrics,
``Recording``, every env and the CLI. Each knows how to build its target, a valid call, and the
*kind* of every argument. :func:`bad_inputs` turns a kind and a valid value into hostile inputs
(seeded, so a worker process regenerates the same ones): wrong shapes and dtypes (int, bool,
complex, object, str), NaN/inf, empty arrays, 1e300, negative ranges, non-SE(3) matrices (scaled,
sheared, reflected, NaN), wrong lengths, None, unicode and very long paths, missing, truncated and
foreign files. Every input is marked ``refuse`` (must raise a clear error) or ``either`` (a clear
error or a graceful answer: NaN in ranges means "no return", an int array is a valid array).

**Outcomes** of one call: ``clear`` (``ValueError``/``TypeError``, or ``FileNotFoundError`` for a
path, whose message names the argument, and the target's state unchanged), ``graceful`` (an
``either`` input accepted), ``unclear`` (another exception type, or a message that does not name
the argument), ``accepted`` (a ``refuse`` input accepted silently), ``state`` (refused, but the
target changed), ``crash`` (the interpreter died) and ``hang`` (over the time limit). Risky calls
run in a worker subprocess (:func:`run_battery` with ``isolate=True``): a crash or hang kills the
worker, is recorded against the input that caused it, and a new worker goes on from the next.

**Module checks** (:func:`check_module`): builds with its documented arguments; ``get_params()``
returns them unchanged; no ``_``-suffixed attributes before the first update; a query before any
update raises ``NotUpdatedError``; queries leave the state unchanged and return arrays that do not
share memory with the inputs; the same seed gives the same output, in one process and across
processes; ``reset()`` then replay equals a fresh instance; pickling round-trips in memory; saved
files load with ``allow_pickle=False``; plus the hostile battery of each of its entry points.

**Env checks** (:func:`check_polar_env`): gymnasium's ``check_env``; seeded resets give the same
observations, rewards and truth (also across processes); observations lie in their spaces; truth
is in ``info``; a rejected ``step``/``reset`` leaves the env as it was; double ``close()`` is
safe; the hostile battery of ``reset``, ``step`` and the constructor's keyword arguments.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import os
import pickle
import select
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any, Callable

import numpy as np

__all__ = [
    "BadInput", "EntryPoint", "ModuleCase", "Check", "Counts", "OUTCOMES",
    "bad_inputs", "state_digest", "run_battery", "check_module", "check_polar_env",
    "ENTRY_POINTS", "MODULES", "env_ids", "entry_points_of", "generate",
]

OUTCOMES = ("clear", "graceful", "unclear", "accepted", "state", "crash", "hang")
FAILURES = ("unclear", "accepted", "state", "crash", "hang")


# ---------------------------------------------------------------------------------------------------
# bad inputs


@dataclasses.dataclass(frozen=True)
class BadInput:
    """One hostile value for argument ``arg``: ``label`` names the family (``"nan"``,
    ``"shape:transposed"``, ...); ``expect`` is ``"refuse"`` or ``"either"``."""

    arg: str
    label: str
    value: Any
    expect: str


class _Foreign:
    """An arbitrary object that is not an array, a number or a path."""

    def __repr__(self):
        return "<foreign object>"


def _common(arg):
    """Values no numeric or path argument may take."""
    return [BadInput(arg, "None", None, "refuse"), BadInput(arg, "str", "abc", "refuse"),
            BadInput(arg, "numeric-str", "1.0", "refuse"), BadInput(arg, "bytes", b"\x00\x01", "refuse"),
            BadInput(arg, "dict", {"a": 1}, "refuse"), BadInput(arg, "object", _Foreign(), "refuse"),
            BadInput(arg, "bool", True, "refuse"), BadInput(arg, "complex", 1 + 2j, "refuse")]


def _at(v, rng, value):
    """A float copy of ``v`` with ``value`` at one random position."""
    a = np.array(v, dtype=np.float64, copy=True)
    if a.size:
        a.flat[rng.integers(a.size)] = value
    return a


def _array_families(arg, v, rng, *, nan="refuse", negative="either", dtype_int="either", empty="either",
                    huge="either", length="refuse"):
    v = np.asarray(v)
    out = [BadInput(arg, "dtype:bool", v.astype(bool), "refuse"),
           BadInput(arg, "dtype:complex", v.astype(np.complex128) + 1j, "refuse"),
           BadInput(arg, "dtype:complex0", v.astype(np.complex128), "refuse"),
           BadInput(arg, "dtype:str", v.astype(str), "refuse"),
           BadInput(arg, "dtype:object-None", _obj_none(v, rng), "refuse"),
           BadInput(arg, "dtype:int", np.round(v).astype(np.int64), dtype_int),
           BadInput(arg, "list", v.tolist(), "either"),
           BadInput(arg, "0-d", np.float64(1.0), "refuse"),
           BadInput(arg, "empty", np.zeros((0,) + v.shape[1:], v.dtype), empty),
           BadInput(arg, "nan", _at(v, rng, np.nan), nan),
           BadInput(arg, "inf", _at(v, rng, np.inf), nan),
           BadInput(arg, "-inf", _at(v, rng, -np.inf), "refuse" if negative == "refuse" else nan),
           BadInput(arg, "1e300", _at(v, rng, 1e300), huge),
           BadInput(arg, "-1e300", _at(v, rng, -1e300), "refuse" if negative == "refuse" else huge),
           BadInput(arg, "negative", _at(v, rng, -abs(float(rng.normal())) - 0.5), negative),
           BadInput(arg, "shape:extra-dim", v[None], "refuse"),
           BadInput(arg, "shape:trailing-dim", v[..., None], "refuse")]
    if v.ndim >= 1 and len(v) > 1:
        out.append(BadInput(arg, "shape:shorter", v[:-1], length))
        out.append(BadInput(arg, "shape:longer", np.concatenate([v, v[:1]]), length))
    if v.ndim >= 2:
        out.append(BadInput(arg, "shape:flat", v.reshape(-1), "refuse"))
        if v.shape[-1] > 1:
            out.append(BadInput(arg, "shape:last-axis", v[..., :-1], "refuse"))
        if v.shape[0] != v.shape[1]:
            out.append(BadInput(arg, "shape:transposed", np.swapaxes(v, 0, 1), "refuse"))
    return out


def _obj_none(v, rng):
    a = np.asarray(v).astype(object)
    if a.size:
        a.flat[rng.integers(a.size)] = None
    return a


def _pose_families(arg, T, rng):
    T = np.asarray(T, np.float64)
    out = []
    for label, M in (("pose:scaled", np.diag([2.0, 2.0, 2.0, 1.0])), ("pose:reflected", np.diag([1.0, 1.0, -1.0, 1.0])),
                     ("pose:sheared", np.array([[1, 0.3, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]))):
        out.append(BadInput(arg, label, T @ M, "refuse"))
    bad_row = T.copy()
    bad_row[3] = [0.0, 0.0, 0.1, 1.0]
    out.append(BadInput(arg, "pose:last-row", bad_row, "refuse"))
    out.append(BadInput(arg, "pose:3x3", T[:3, :3], "refuse"))
    out.append(BadInput(arg, "pose:3x4", T[:3], "refuse"))
    noisy = T.copy()
    noisy[:3, :3] += rng.normal(0.0, 0.05, (3, 3))
    out.append(BadInput(arg, "pose:not-orthonormal", noisy, "refuse"))
    far = T.copy()
    far[:3, 3] = [1e300, 0.0, 0.0]
    out.append(BadInput(arg, "pose:1e300", far, "either"))
    return out


def _path_in_families(arg, valid_path, tmp):
    tmp = Path(tmp)
    data = Path(valid_path).read_bytes()
    files = {}
    for label, content in (("file:empty", b""), ("file:text", b"hello, not an npz\n"),
                           ("file:truncated-half", data[: len(data) // 2]), ("file:truncated-end", data[:-7]),
                           ("file:head", data[:64])):
        p = tmp / f"{label.replace(':', '_')}.npz"
        p.write_bytes(content)
        files[label] = p
    flipped = bytearray(data)
    flipped[len(data) // 3] ^= 0xFF
    (tmp / "flipped.npz").write_bytes(bytes(flipped))
    out = [BadInput(arg, label, str(p), "refuse") for label, p in files.items()]
    out += [BadInput(arg, "file:bit-flip", str(tmp / "flipped.npz"), "either"),
            BadInput(arg, "path:missing", str(tmp / "missing.npz"), "refuse"),
            BadInput(arg, "path:missing-unicode", str(tmp / "ñandú √∂ 地图.npz"), "refuse"),
            BadInput(arg, "path:directory", str(tmp), "refuse"),
            BadInput(arg, "path:device", "/dev/null", "refuse"),
            BadInput(arg, "path:long", str(tmp / ("x" * 300 + ".npz")), "refuse"),
            BadInput(arg, "path:very-long", "/tmp/" + "y/" * 3000 + "m.npz", "refuse"),
            BadInput(arg, "path:nul", str(tmp / "a\x00b.npz"), "refuse"),
            BadInput(arg, "path:int", 1, "refuse"), BadInput(arg, "path:None", None, "refuse"),
            BadInput(arg, "path:empty", "", "refuse"), BadInput(arg, "path:object", _Foreign(), "refuse")]
    return out


def _path_out_families(arg, tmp):
    tmp = Path(tmp)
    fifo = tmp / "fifo"
    if not fifo.exists() and hasattr(os, "mkfifo"):
        os.mkfifo(fifo)
    (tmp / "adir").mkdir(exist_ok=True)
    return [BadInput(arg, "path:int", 1, "refuse"), BadInput(arg, "path:None", None, "refuse"),
            BadInput(arg, "path:empty", "", "refuse"), BadInput(arg, "path:directory", str(tmp / "adir"), "refuse"),
            BadInput(arg, "path:device", "/dev/null", "refuse"), BadInput(arg, "path:fifo", str(fifo), "refuse"),
            BadInput(arg, "path:long-name", str(tmp / ("x" * 300 + ".npz")), "refuse"),
            BadInput(arg, "path:very-long", "/tmp/" + "y/" * 3000 + "m.npz", "refuse"),
            BadInput(arg, "path:nul", str(tmp / "a\x00b.npz"), "refuse"),
            BadInput(arg, "path:object", _Foreign(), "refuse"), BadInput(arg, "path:bool", True, "refuse"),
            BadInput(arg, "path:unicode", str(tmp / "ñandú √∂ 地图.npz"), "either"),
            BadInput(arg, "path:new-folder", str(tmp / "new" / "deeper" / "m.npz"), "either"),
            BadInput(arg, "path:under-file", str(tmp / "file_as_dir" / "m.npz"), "refuse")]


def _scalar_families(arg, v, *, positive=False, integer=False, optional=False, unit=False):
    """Hostile values of a number argument (``positive``: > 0; ``integer``; ``unit``: in [0, 1])."""
    out = [BadInput(arg, "str", "abc", "refuse"), BadInput(arg, "numeric-str", str(v), "refuse"),
           BadInput(arg, "bool", True, "refuse"), BadInput(arg, "complex", complex(v or 1) + 1j, "refuse"),
           BadInput(arg, "list", [v], "refuse"), BadInput(arg, "array", np.array([v, v]), "refuse"),
           BadInput(arg, "object", _Foreign(), "refuse"), BadInput(arg, "nan", float("nan"), "refuse"),
           BadInput(arg, "inf", float("inf"), "refuse" if (integer or unit) else "either"),
           BadInput(arg, "1e300", 1e300, "refuse" if (integer or unit) else "either"),
           BadInput(arg, "-1e300", -1e300, "refuse" if (positive or unit) else "either"),
           BadInput(arg, "negative", -1 if integer else -1.5, "refuse" if (positive or unit) else "either"),
           BadInput(arg, "zero", 0 if integer else 0.0, "refuse" if positive else "either"),
           BadInput(arg, "huge-int", 10**30, "refuse" if unit else "either"),
           BadInput(arg, "tiny", 1e-300, "either")]
    if integer:
        out += [BadInput(arg, "float", float(v) + 0.5, "refuse"), BadInput(arg, "float-whole", float(v), "either")]
    if unit:
        out.append(BadInput(arg, "above-one", 1.5, "refuse"))
    if not optional:
        out.append(BadInput(arg, "None", None, "refuse"))
    return out


def _choice_families(arg, v):
    return [BadInput(arg, "choice:unknown", "no-such-choice", "refuse"), BadInput(arg, "choice:case", str(v).upper() + "_", "refuse"),
            BadInput(arg, "None", None, "either"), BadInput(arg, "int", 3, "refuse"), BadInput(arg, "bool", True, "refuse"),
            BadInput(arg, "list", [v], "refuse"), BadInput(arg, "unicode", "ñ√∂" * 50, "refuse"),
            BadInput(arg, "long", "x" * 10_000, "refuse"), BadInput(arg, "object", _Foreign(), "refuse")]


def bad_inputs(kind, valid, arg, rng, *, tmp=None):
    """Hostile inputs (list of :class:`BadInput`) for argument ``arg`` of ``kind`` whose valid value
    is ``valid``. Kinds: ``points``, ``angles``, ``ranges``, ``depth``, ``image``, ``mask``,
    ``pose``, ``poses``, ``pose2d``, ``K``, ``vector``, ``lengths``, ``float``, ``float+``,
    ``unit``, ``int+``, ``int0``, ``seed``, ``bool``, ``choice``, ``name``, ``path_in``,
    ``path_out``, ``frame`` (a recording frame dict), ``scan2d`` (an (angles, ranges) pair),
    ``object``."""
    c = _common(arg)
    if kind == "points":
        return c + _array_families(arg, valid, rng, length="either")
    if kind in ("angles", "vector"):
        return c + _array_families(arg, valid, rng)
    if kind == "ranges":
        return c + _array_families(arg, valid, rng, nan="either", negative="refuse", huge="either")
    if kind == "depth":
        v = np.asarray(valid)
        out = c + _array_families(arg, v, rng, nan="either", negative="refuse", empty="refuse", length="either")
        out.append(BadInput(arg, "dtype:float16", v.astype(np.float16), "either"))
        out.append(BadInput(arg, "zeros", np.zeros_like(v), "either"))
        return out
    if kind in ("image", "mask"):
        v = np.asarray(valid)
        out = [b for b in c + _array_families(arg, v, rng, empty="refuse", length="either" if kind == "image" else "refuse")
               if not (kind == "mask" and b.label == "dtype:bool")]
        out += [BadInput(arg, "dtype:float32", v.astype(np.float32), "either"),
                BadInput(arg, "dtype:uint16", v.astype(np.uint16), "either"),
                BadInput(arg, "non-contiguous", v[:, ::-1], "either")]
        if v.ndim == 3:
            out += [BadInput(arg, "channels:4", np.concatenate([v, v[..., :1]], -1), "refuse"),
                    BadInput(arg, "channels:gray", v[..., 0], "refuse")]
        return out
    if kind == "pose":
        return c + _array_families(arg, valid, rng, huge="refuse", empty="refuse") + _pose_families(arg, valid, rng)
    if kind == "poses":
        v = np.asarray(valid)
        out = c + _array_families(arg, v, rng, huge="either", empty="refuse")
        k = int(rng.integers(len(v)))
        for b in _pose_families(arg, v[k], rng):
            if b.value.shape == (4, 4):
                w = v.copy()
                w[k] = b.value
                out.append(BadInput(arg, b.label, w, b.expect))
        return out
    if kind == "pose2d":
        return c + _array_families(arg, valid, rng, huge="either", empty="refuse")
    if kind == "K":
        K = np.asarray(valid, np.float64)
        out = c + _array_families(arg, K, rng, huge="either", empty="refuse", negative="either")
        for label, (i, j, x) in (("K:fx-negative", (0, 0, -K[0, 0])), ("K:fy-zero", (1, 1, 0.0)),
                                 ("K:last-row", (2, 0, 1.0)), ("K:fx-nan", (0, 0, np.nan))):
            b = K.copy()
            b[i, j] = x
            out.append(BadInput(arg, label, b, "refuse"))
        return out
    if kind == "lengths":
        return c[:-2] + [BadInput(arg, "str-number", "100", "refuse"), BadInput(arg, "negative", [-100.0], "refuse"),
                         BadInput(arg, "zero", [0.0], "refuse"), BadInput(arg, "nan", [np.nan], "refuse"),
                         BadInput(arg, "inf", [np.inf], "refuse"), BadInput(arg, "empty", [], "refuse"),
                         BadInput(arg, "scalar", 100.0, "refuse"), BadInput(arg, "nested", [[100.0]], "refuse"),
                         BadInput(arg, "complex", [100 + 1j], "refuse"), BadInput(arg, "1e300", [1e300], "either")]
    if kind in ("float", "float+", "unit"):
        return _scalar_families(arg, valid, positive=kind == "float+", unit=kind == "unit")
    if kind in ("int+", "int0", "seed"):
        return _scalar_families(arg, valid, positive=kind == "int+", integer=True, optional=kind == "seed")
    if kind == "bool":
        return [BadInput(arg, "str", "no", "refuse"), BadInput(arg, "int", 2, "either"), BadInput(arg, "None", None, "either"),
                BadInput(arg, "array", np.array([True, False]), "refuse"), BadInput(arg, "object", _Foreign(), "refuse")]
    if kind in ("choice", "name"):
        return _choice_families(arg, valid)
    if kind == "path_in":
        return _path_in_families(arg, valid, tmp)
    if kind == "path_out":
        (Path(tmp) / "file_as_dir").write_bytes(b"x")
        return _path_out_families(arg, tmp)
    if kind == "frame":
        f = dict(valid)
        k = sorted(f)[0]
        return [BadInput(arg, "None", None, "refuse"), BadInput(arg, "list", list(f.values()), "refuse"),
                BadInput(arg, "empty", {}, "refuse"), BadInput(arg, "key:int", {**f, 3: f[k]}, "refuse"),
                BadInput(arg, "key:slash", {**f, "a/b": f[k]}, "refuse"), BadInput(arg, "key:empty", {**f, "": f[k]}, "refuse"),
                BadInput(arg, "value:object", {**f, k: np.array([None, 1], object)}, "refuse"),
                BadInput(arg, "value:str", {**f, k: "abc"}, "refuse"),
                BadInput(arg, "value:complex", {**f, k: np.asarray(f[k]) + 1j}, "refuse"),
                BadInput(arg, "value:None", {**f, k: None}, "refuse"),
                BadInput(arg, "schema:shape", {**f, k: np.zeros((2,) + np.shape(f[k]))}, "refuse"),
                BadInput(arg, "schema:dtype", {**f, k: np.asarray(f[k]).astype(np.complex64).real.astype(np.float16)}, "refuse"),
                BadInput(arg, "schema:missing-key", {kk: vv for kk, vv in f.items() if kk != k}, "refuse"),
                BadInput(arg, "schema:extra-key", {**f, "extra": 1.0}, "refuse")]
    if kind == "scan2d":
        a, r = valid
        out = [BadInput(arg, "None", None, "refuse"), BadInput(arg, "str", "abc", "refuse"),
               BadInput(arg, "tuple:1", (a,), "refuse"), BadInput(arg, "tuple:3", (a, r, r), "refuse"),
               BadInput(arg, "object", _Foreign(), "refuse")]
        out += [dataclasses.replace(b, value=(b.value, r)) for b in bad_inputs("angles", a, arg, rng)
                if not b.label.startswith(("None", "str", "bytes", "dict", "object", "bool", "complex", "numeric-str"))]
        out += [dataclasses.replace(b, value=(a, b.value)) for b in bad_inputs("ranges", r, arg, rng)
                if not b.label.startswith(("None", "str", "bytes", "dict", "object", "bool", "complex", "numeric-str"))]
        return out
    if kind == "object":
        return [BadInput(arg, "None", None, "refuse"), BadInput(arg, "str", "abc", "refuse"),
                BadInput(arg, "object", _Foreign(), "refuse"), BadInput(arg, "int", 3, "refuse")]
    raise ValueError(f"kind: unknown argument kind {kind!r}")


# ---------------------------------------------------------------------------------------------------
# state digests


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


# ---------------------------------------------------------------------------------------------------
# entry points


@dataclasses.dataclass
class EntryPoint:
    """A public call under test.

    ``setup(tmp) -> target`` builds what the call acts on (None for a plain function);
    ``args(target, tmp) -> dict`` gives a valid call's arguments by name; ``call(target, args)``
    makes it; ``kinds`` maps each argument to its kind for :func:`bad_inputs`; ``names`` lists
    other names an error may use for an argument (``scan`` may be reported as ``ranges``);
    ``state(target)`` fingerprints the target (default :func:`state_digest`). A call that accepts
    an input may move the target on, so the target is rebuilt after every accepted call.
    """

    name: str
    setup: Callable
    args: Callable
    call: Callable
    kinds: dict
    names: dict = dataclasses.field(default_factory=dict)
    state: Callable | None = None
    ignore: tuple = ()
    timeout: float = 60.0
    pure: bool = False          # an accepted call leaves the target as it was (a query)


def _fresh_tmp(prefix="polar_battery_"):
    return tempfile.mkdtemp(prefix=prefix)


def generate(ep: EntryPoint, target, tmp, n, seed=0):
    """The first ``n`` hostile inputs of entry point ``ep``, as (BadInput, full args dict) pairs;
    the same ``seed`` gives the same inputs (families cycled over the arguments, then repeated
    with new random positions)."""
    if hasattr(ep, "cases"):          # the CLI: whole command lines
        cases = [BadInput("argv", label, (flag, label, argv), "refuse") for flag, label, argv in ep.cases(tmp)]
        return cases[:n]
    out = []
    rnd = 0
    while len(out) < n:
        rng = np.random.default_rng([seed, rnd])
        pools = []
        for arg, kind in ep.kinds.items():
            valid = ep.args(target, tmp)
            pools.append((arg, bad_inputs(kind, valid[arg], arg, rng, tmp=tmp)))
        i = 0
        progressed = True
        while progressed and len(out) < n:
            progressed = False
            for arg, pool in pools:
                if i < len(pool) and len(out) < n:
                    out.append(pool[i])
                    progressed = True
            i += 1
        rnd += 1
    return out[:n]


def _names_ok(ep, bad, exc):
    msg = str(exc)
    names = (bad.arg,) + tuple(ep.names.get(bad.arg, ()))
    return any(nm in msg for nm in names)


class _QuietFds:
    """Point file descriptors 0, 1 and 2 at /dev/null during a hostile call: an integer "path"
    is a file descriptor, and a save to fd 1 would write into (and close) our stdout."""

    def __enter__(self):
        sys.stdout.flush()
        sys.stderr.flush()
        self._saved = [os.dup(fd) for fd in (0, 1, 2)]
        null = os.open(os.devnull, os.O_RDWR)
        for fd in (0, 1, 2):
            os.dup2(null, fd)
        os.close(null)
        return self

    def __exit__(self, *exc):
        for fd, saved in zip((0, 1, 2), self._saved):
            os.dup2(saved, fd)
            os.close(saved)


def _classify(ep, bad, target, tmp):
    """Outcome, detail of one hostile call (in this process), with fds 0-2 at /dev/null."""
    with _QuietFds():
        return _classify_call(ep, bad, target, tmp)


def _classify_call(ep, bad, target, tmp):
    args = ep.args(target, tmp)
    args[bad.arg] = bad.value
    fp = ep.state or (lambda t: state_digest(t, ignore=ep.ignore))
    before = fp(target) if target is not None else None
    try:
        ep.call(target, args)
    except (ValueError, TypeError, FileNotFoundError) as exc:
        if not _names_ok(ep, bad, exc):
            return "unclear", f"{type(exc).__name__} not naming {bad.arg!r}: {str(exc)[:160]}"
        if target is not None and fp(target) != before:
            return "state", f"refused ({type(exc).__name__}) but the state changed"
        return "clear", f"{type(exc).__name__}: {str(exc)[:120]}"
    except SystemExit as exc:             # argparse (CLI entry points handle this themselves)
        return "unclear", f"SystemExit {exc.code}"
    except MemoryError:
        return "unclear", "MemoryError"
    except Exception as exc:  # noqa: BLE001 - every other type is a finding
        tb = traceback.extract_tb(exc.__traceback__)[-1]
        return "unclear", f"{type(exc).__name__} at {Path(tb.filename).name}:{tb.lineno}: {str(exc)[:120]}"
    if bad.expect == "either":
        return "graceful", "accepted"
    return "accepted", "accepted silently"


@dataclasses.dataclass
class Counts:
    """Outcomes of one entry point's battery, and the failing inputs."""

    name: str
    n: int = 0
    counts: dict = dataclasses.field(default_factory=lambda: dict.fromkeys(OUTCOMES, 0))
    failures: list = dataclasses.field(default_factory=list)   # (index, arg, label, outcome, detail)
    seconds: float = 0.0

    def add(self, i, bad, outcome, detail):
        self.n += 1
        self.counts[outcome] += 1
        if outcome in FAILURES:
            self.failures.append((i, bad.arg, bad.label, outcome, detail))

    @property
    def ok(self):
        return all(self.counts[k] == 0 for k in FAILURES)

    def report(self, limit=30):
        c = self.counts
        lines = [f"{self.name}: {self.n} inputs: " + ", ".join(f"{k} {c[k]}" for k in OUTCOMES)]
        for f in self.failures[:limit]:
            lines.append(f"  #{f[0]} {f[1]}={f[2]}: {f[3]}: {f[4]}")
        if len(self.failures) > limit:
            lines.append(f"  ... {len(self.failures) - limit} more")
        return "\n".join(lines)


def _run_inprocess(ep, n, seed, start=0, emit=None):
    tmp = _fresh_tmp()
    target = ep.setup(tmp)
    cases = generate(ep, target, tmp, n, seed)
    res = Counts(ep.name)
    t0 = time.perf_counter()
    for i in range(start, len(cases)):
        bad = cases[i]
        if emit:
            emit(f"B {i}")
        outcome, detail = _classify(ep, bad, target, tmp)
        if emit:
            emit("R " + json.dumps([i, bad.arg, bad.label, outcome, detail]))
        res.add(i, bad, outcome, detail)
        if outcome in ("graceful", "accepted") and not ep.pure:
            _close(target)
            target = ep.setup(tmp)
    _close(target)
    res.seconds = time.perf_counter() - t0
    return res


def _close(target):
    close = getattr(target, "close", None)
    if callable(close):
        try:
            close()
        except Exception:  # noqa: BLE001
            pass


def run_battery(name, n=200, *, seed=0, isolate=True, timeout=None, setup_timeout=600.0):
    """Run ``n`` hostile inputs against entry point ``name`` (a key of :data:`ENTRY_POINTS`) and
    return its :class:`Counts`.

    ``isolate=True`` runs the calls in a worker subprocess: a call that kills the interpreter is
    a ``crash``, one that runs past ``timeout`` seconds (default the entry point's) a ``hang``;
    either way a new worker continues from the next input.
    """
    ep = ENTRY_POINTS[name]()
    if not isolate:
        return _run_inprocess(ep, n, seed)
    timeout = ep.timeout if timeout is None else timeout
    res = Counts(name)
    start = 0
    t0 = time.perf_counter()
    labels = {}
    while start < n:
        cmd = [sys.executable, "-m", "polar_sim.testing", "--worker", name, str(n), str(seed), str(start)]
        env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"), PYTHONFAULTHANDLER="")
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env, text=True, bufsize=1)
        current, limit = None, time.monotonic() + setup_timeout
        try:
            while True:
                r, _, _ = select.select([proc.stdout], [], [], max(0.0, limit - time.monotonic()))
                if not r:
                    proc.kill()
                    proc.wait()
                    if current is None:
                        raise RuntimeError(f"{name}: the worker did not start within {setup_timeout} s")
                    res.add(current, labels.get(current, BadInput("?", "?", None, "refuse")), "hang",
                            f"no answer within {timeout} s")
                    start = current + 1
                    break
                line = proc.stdout.readline()
                if not line:                                      # the worker died
                    rc = proc.wait()
                    if current is None:
                        raise RuntimeError(f"{name}: the worker exited with {rc} before its first input")
                    res.add(current, labels.get(current, BadInput("?", "?", None, "refuse")), "crash",
                            f"the interpreter died (exit {rc})")
                    start = current + 1
                    break
                if line.startswith("L "):
                    i, arg, label = json.loads(line[2:])
                    labels[i] = BadInput(arg, label, None, "refuse")
                elif line.startswith("B "):
                    current = int(line[2:])
                    limit = time.monotonic() + timeout
                elif line.startswith("R "):
                    i, arg, label, outcome, detail = json.loads(line[2:])
                    res.add(i, BadInput(arg, label, None, "refuse"), outcome, detail)
                    current, start = None, i + 1
                    limit = time.monotonic() + timeout
                elif line.startswith("END"):
                    proc.wait()
                    start = n
                    break
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    res.seconds = time.perf_counter() - t0
    return res


def _worker(name, n, seed, start):
    os.environ.setdefault("MUJOCO_GL", "egl")
    ep = ENTRY_POINTS[name]()
    proto = os.fdopen(os.dup(1), "w")       # the protocol keeps its own copy of the pipe

    def emit(s):
        proto.write(s + "\n")
        proto.flush()

    tmp = _fresh_tmp()
    target = ep.setup(tmp)
    cases = generate(ep, target, tmp, n, seed)
    for i in range(start, len(cases)):
        emit("L " + json.dumps([i, cases[i].arg, cases[i].label]))
        emit(f"B {i}")
        outcome, detail = _classify(ep, cases[i], target, tmp)
        emit("R " + json.dumps([i, cases[i].arg, cases[i].label, outcome, detail]))
        if outcome in ("graceful", "accepted") and not ep.pure:
            _close(target)
            target = ep.setup(tmp)
    _close(target)
    emit("END")


# ---------------------------------------------------------------------------------------------------
# data for the entry points (small, exact, numpy only)


def _scan_circle(n=180, radius=3.0, centre=(0.4, -0.2), pose=(0.0, 0.0, 0.0)):
    """Angles (n,) and exact ranges (n,) of a lidar at ``pose`` inside a circular wall."""
    ang = np.linspace(-np.pi, np.pi, n, endpoint=False)
    x, y, th = pose
    d = np.stack([np.cos(ang + th), np.sin(ang + th)], 1)
    o = np.array([x, y]) - np.asarray(centre)
    b = d @ o
    r = -b + np.sqrt(b * b - (o @ o - radius**2))
    return ang, r


def _depth_plane(h=24, w=32, z=1.0):
    K = np.array([[30.0, 0, (w - 1) / 2], [0, 30.0, (h - 1) / 2], [0, 0, 1.0]])
    v, u = np.mgrid[0:h, 0:w]
    # a plane tilted about the camera's x axis: depth grows towards the bottom rows
    depth = z / (1.0 - 0.3 * (v - K[1, 2]) / K[1, 1])
    return depth.astype(np.float64), K


def _poses_line(n=40, step=3.0):
    P = np.tile(np.eye(4), (n, 1, 1))
    P[:, 0, 3] = np.arange(n) * step
    th = 0.01 * np.arange(n)
    P[:, 0, 0], P[:, 0, 1], P[:, 1, 0], P[:, 1, 1] = np.cos(th), -np.sin(th), np.sin(th), np.cos(th)
    return P


def _gpis2d(n_scans=2):
    from polar_sim.gpis import GPISMap2D

    m = GPISMap2D()
    for k in range(n_scans):
        pose = (0.1 * k, 0.05 * k, 0.1 * k)
        a, r = _scan_circle(pose=pose)
        m.update(a, r, pose)
    return m


def _gpis3d():
    from polar_sim.gpis import GPISMap3D

    depth, K = _depth_plane()
    m = GPISMap3D()
    m.update(depth, K, np.eye(4))
    return m


def _vo_sequence(n=4):
    from polar_sim.ground.synthetic import make_sequence

    return make_sequence(n, width=160, height=120, speed=3.0, yaw_rate=0.05, camera_height=1.0, seed=0)


_CACHE: dict = {}


def _cached(key, fn):
    if key not in _CACHE:
        _CACHE[key] = fn()
    return _CACHE[key]


def _track_sequence():
    from polar_sim.tracking.synthetic import make_sequence

    seq = make_sequence(3, "mug", hand=False, seed=0, shape=(120, 160))
    pts, nrm = seq.model(800)
    return seq, pts, nrm, [seq.frame(i) for i in range(3)]


def _ep_gpis2d_update():
    return EntryPoint(
        "GPISMap2D.update", setup=lambda tmp: _gpis2d(1),
        args=lambda t, tmp: dict(zip(("angles", "ranges"), _scan_circle(pose=(0.2, 0.1, 0.3)))) | {"pose2d": np.array([0.2, 0.1, 0.3])},
        call=lambda t, a: t.update(a["angles"], a["ranges"], a["pose2d"]),
        kinds={"angles": "angles", "ranges": "ranges", "pose2d": "pose2d"})


def _ep_gpis2d_query():
    return EntryPoint(
        "GPISMap2D.query", setup=lambda tmp: _gpis2d(1), args=lambda t, tmp: {"points": np.array([[0.5, 0.5], [2.0, -1.0], [0.0, 3.0]])},
        call=lambda t, a: t.query(a["points"]), kinds={"points": "points"}, pure=True)


def _ep_gpis2d_save():
    return EntryPoint("GPISMap2D.save", setup=lambda tmp: _gpis2d(1), args=lambda t, tmp: {"path": str(Path(tmp) / "ok.npz")},
                      call=lambda t, a: t.save(a["path"]), kinds={"path": "path_out"})


def _gpis_file(tmp, cls="2d"):
    p = Path(tmp) / f"valid_{cls}.npz"
    if not p.exists():
        (_gpis2d(1) if cls == "2d" else _gpis3d()).save(p)
    return str(p)


def _ep_gpis2d_load():
    from polar_sim.gpis import GPISMap2D

    return EntryPoint("GPISMap2D.load", setup=lambda tmp: None, args=lambda t, tmp: {"path": _gpis_file(tmp)},
                      call=lambda t, a: GPISMap2D.load(a["path"]), kinds={"path": "path_in"})


def _ep_gpis3d_update():
    def args(t, tmp):
        depth, K = _depth_plane(z=1.1)
        T = np.eye(4)
        T[:3, 3] = [0.02, 0.0, 0.0]
        return {"depth": depth, "K": K, "T_world_cam": T}

    return EntryPoint("GPISMap3D.update", setup=lambda tmp: _gpis3d(), args=args,
                      call=lambda t, a: t.update(a["depth"], a["K"], a["T_world_cam"]),
                      kinds={"depth": "depth", "K": "K", "T_world_cam": "pose"})


def _ep_gpis3d_query():
    return EntryPoint("GPISMap3D.query", setup=lambda tmp: _gpis3d(),
                      args=lambda t, tmp: {"points": np.array([[0.0, 0.0, 0.9], [0.1, 0.05, 1.0]])},
                      call=lambda t, a: t.query(a["points"]), kinds={"points": "points"}, pure=True)


def _ep_localize():
    from polar_sim.gpis.localize import localize

    def args(t, tmp):
        return {"map": t, "scan": _scan_circle(pose=(0.05, 0.02, 0.05)), "initial_pose": np.array([0.0, 0.0, 0.0])}

    return EntryPoint("localize", setup=lambda tmp: _gpis2d(2), args=args,
                      call=lambda t, a: localize(a["map"], a["scan"], a["initial_pose"]),
                      kinds={"map": "object", "scan": "scan2d", "initial_pose": "pose2d"},
                      names={"scan": ("angles", "ranges"), "map": ("query",)})


def _ep_groundvo_init():
    from polar_sim.ground import GroundVO

    K = np.array([[100.0, 0, 79.5], [0, 100.0, 59.5], [0, 0, 1.0]])
    return EntryPoint("GroundVO", setup=lambda tmp: None,
                      args=lambda t, tmp: {"K": K.copy(), "camera_height": 1.0, "model": "6param", "sampling": "weighted", "seed": 0},
                      call=lambda t, a: GroundVO(a["K"], a["camera_height"], model=a["model"], sampling=a["sampling"], seed=a["seed"]),
                      kinds={"K": "K", "camera_height": "float+", "model": "choice", "sampling": "choice", "seed": "seed"})


def _ep_groundvo_process():
    from polar_sim.ground import GroundVO

    def setup(tmp):
        s = _cached("vo", _vo_sequence)
        vo = GroundVO(s["K"], s["camera_height"], seed=0)
        for i in range(2):
            vo.process(s["rgb"][i], float(s["times"][i]))
        return vo

    def args(t, tmp):
        s = _cached("vo", _vo_sequence)
        return {"rgb": s["rgb"][2].copy(), "t": float(s["times"][2])}

    return EntryPoint("GroundVO.process", setup=setup, args=args, call=lambda t, a: t.process(a["rgb"], a["t"]),
                      kinds={"rgb": "image", "t": "float"}, timeout=120.0)


def _ep_tracker_init():
    from polar_sim.tracking import ObjectTracker

    def args(t, tmp):
        seq, pts, nrm, _ = _cached("trk", _track_sequence)
        return {"model_points": pts.copy(), "K": seq.K.copy(), "initial_pose": seq.poses[0].copy()}

    return EntryPoint("ObjectTracker", setup=lambda tmp: None, args=args,
                      call=lambda t, a: ObjectTracker(a["model_points"], a["K"], a["initial_pose"]),
                      kinds={"model_points": "points", "K": "K", "initial_pose": "pose"})


def _ep_tracker_process():
    from polar_sim.tracking import ObjectTracker

    def setup(tmp):
        seq, pts, nrm, frames = _cached("trk", _track_sequence)
        tr = ObjectTracker(pts, seq.K, seq.poses[0], model_normals=nrm, random_state=0)
        tr.process(frames[0]["rgb"], frames[0]["depth"], 0.0)
        return tr

    def args(t, tmp):
        _, _, _, frames = _cached("trk", _track_sequence)
        return {"rgb": frames[1]["rgb"].copy(), "depth": frames[1]["depth"].copy(), "t": 1 / 30}

    return EntryPoint("ObjectTracker.process", setup=setup, args=args,
                      call=lambda t, a: t.process(a["rgb"], a["depth"], a["t"]),
                      kinds={"rgb": "image", "depth": "depth", "t": "float"}, timeout=120.0)


def _ep_metric(fname, kinds, make_args, names=None):
    def build():
        from polar_sim import metrics

        fn = getattr(metrics, fname)
        return EntryPoint(f"metrics.{fname}", setup=lambda tmp: None, args=lambda t, tmp: make_args(),
                          call=lambda t, a: fn(**a), kinds=kinds, names=names or {})
    return build


def _pose(t=(0.1, 0.0, 0.5), yaw=0.2):
    T = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = t
    return T


def _pts(n=50, seed=0):
    return np.random.default_rng(seed).normal(0, 0.05, (n, 3))


def _ep_recording_append():
    from polar_sim.sim.recording import Recording

    def frame():
        return {"depth": np.ones((8, 10), np.float32), "pose": np.eye(4), "t": 0.1}

    def setup(tmp):
        r = Recording(meta={"what": "battery"})
        r.append(frame())
        return r

    return EntryPoint("Recording.append", setup=setup, args=lambda t, tmp: {"frame": frame()},
                      call=lambda t, a: t.append(a["frame"]), kinds={"frame": "frame"})


def _recording(n=3):
    from polar_sim.sim.recording import Recording

    r = Recording(meta={"what": "battery"})
    for i in range(n):
        r.append({"rgb": np.full((12, 16, 3), 10 * i, np.uint8), "depth": np.full((12, 16), 1.0 + i, np.float32),
                  "pose": np.eye(4), "t": 0.1 * i})
    return r


def _ep_recording_save():
    return EntryPoint("Recording.save", setup=lambda tmp: _recording(), args=lambda t, tmp: {"path": str(Path(tmp) / "rec.npz")},
                      call=lambda t, a: t.save(a["path"]), kinds={"path": "path_out"})


def _ep_recording_load():
    from polar_sim.sim.recording import Recording

    def args(t, tmp):
        p = Path(tmp) / "valid_rec.npz"
        if not p.exists():
            _recording().save(p)
        return {"path": str(p)}

    return EntryPoint("Recording.load", setup=lambda tmp: None, args=args,
                      call=lambda t, a: Recording.load(a["path"]), kinds={"path": "path_in"})


def _world(scene="office2d", **kw):
    from polar_sim.sim import World

    return World(scene, seed=0, kinematic=True, **kw)


def _world_state(w):
    d = w.data
    return hashlib.sha256(b"".join(np.asarray(x).tobytes() for x in (d.qpos, d.qvel, d.ctrl, [d.time]))
                          + repr(w._rng.bit_generator.state).encode()
                          + repr(sorted(w._noise.items(), key=str)).encode()).hexdigest()


def _ep_world_init():
    def call(t, a):
        from polar_sim.sim import World

        w = World(a["scene"], seed=a["seed"], kinematic=a["kinematic"], control_dt=a["control_dt"],
                  camera_height=a["camera_height"])
        w.close()

    return EntryPoint("World", setup=lambda tmp: None,
                      args=lambda t, tmp: {"scene": "rover_flat", "seed": 0, "kinematic": True, "control_dt": 0.1,
                                           "camera_height": 1.2},
                      call=call, kinds={"scene": "name", "seed": "seed", "kinematic": "bool", "control_dt": "float+",
                                        "camera_height": "float+"}, timeout=120.0)


def _ep_world_step():
    return EntryPoint("World.step", setup=lambda tmp: _world(), args=lambda t, tmp: {"action": np.array([0.5, 0.1])},
                      call=lambda t, a: t.step(a["action"]), kinds={"action": "vector"}, state=_world_state)


def _ep_world_camera():
    return EntryPoint("World.camera", setup=lambda tmp: _world(),
                      args=lambda t, tmp: {"name": "front", "width": 32, "height": 24},
                      call=lambda t, a: t.camera(a["name"], width=a["width"], height=a["height"]),
                      kinds={"name": "name", "width": "int+", "height": "int+"}, state=_world_state, pure=True)


def _ep_world_lidar():
    return EntryPoint("World.lidar", setup=lambda tmp: _world(), args=lambda t, tmp: {"name": "lidar"},
                      call=lambda t, a: t.lidar(a["name"]), kinds={"name": "name"}, state=_world_state, pure=True)


def _ep_world_sdf():
    return EntryPoint("World.sdf", setup=lambda tmp: _world(), args=lambda t, tmp: {"points": np.array([[1.0, 2.0, 0.3], [5.0, 5.0, 0.5]])},
                      call=lambda t, a: t.sdf(a["points"]), kinds={"points": "points"}, state=_world_state, pure=True)


def _ep_world_noise():
    from polar_sim.sim.sensors import RangeNoise

    return EntryPoint("RangeNoise", setup=lambda tmp: None, args=lambda t, tmp: {"sigma": 0.01, "dropout": 0.05},
                      call=lambda t, a: RangeNoise(sigma=a["sigma"], dropout=a["dropout"]),
                      kinds={"sigma": "float+", "dropout": "unit"})


# -- envs -------------------------------------------------------------------------------------------


def _env_ids():
    from polar_sim.envs import ENV_IDS as ids

    return list(ids)


def _make_env(env_id, **kw):
    import gymnasium as gym

    import polar_sim.envs  # noqa: F401  (registers the ids)

    return gym.make(env_id, disable_env_checker=True, **kw)


def _env_state(env):
    return state_digest(env.unwrapped, ignore=("_rig", "_renderer", "renderer", "_viewer"))


def _ep_env_step(env_id):
    def setup(tmp):
        env = _make_env(env_id)
        env.reset(seed=0)
        return env

    def args(t, tmp):
        sp = t.action_space
        a = sp.sample() if not hasattr(sp, "low") else ((sp.low + sp.high) / 2).astype(sp.dtype)
        return {"action": a}

    def kinds():
        return {"action": "vector"}

    return EntryPoint(f"{env_id}.step", setup=setup, args=args, call=lambda t, a: t.step(a["action"]),
                      kinds=kinds(), state=_env_state, timeout=120.0)


def _ep_env_reset(env_id):
    def setup(tmp):
        env = _make_env(env_id)
        env.reset(seed=0)
        return env

    return EntryPoint(f"{env_id}.reset", setup=setup, args=lambda t, tmp: {"seed": 1},
                      call=lambda t, a: t.reset(seed=a["seed"]), kinds={"seed": "seed"}, state=_env_state, timeout=120.0)


# -- the CLI ----------------------------------------------------------------------------------------


def _cli_argvs(tmp):
    """Hostile command lines: each a (flag, label, argv, expect)."""
    out_ok = str(Path(tmp) / "out")
    bad_int = ["0", "-1", "abc", "1.5", "1e300", "", "nan", "99999999999999999999"]
    bad_out = ["/dev/null/x", "/tmp/" + "x" * 5000, str(Path(tmp) / "file_as_dir" / "o"), "\x00"]
    cases = []
    for v in bad_int:
        cases += [("--width", f"int:{v}", ["render", "office2d", "--width", v, "--height", "24", "--out", out_ok]),
                  ("--height", f"int:{v}", ["render", "office2d", "--width", "32", "--height", v, "--out", out_ok]),
                  ("--episodes", f"int:{v}", ["eval", "polar_sim/GPISNav-v0", "--policy", "random", "--episodes", v]),
                  ("--workers", f"int:{v}", ["run", "sensors", "--quick", "--workers", v, "--out", out_ok]),
                  ("--n-boot", f"int:{v}", ["compare", out_ok, out_ok, "--n-boot", v])]
    for v in ["-1", "abc", "1.5"]:
        cases += [("--steps", f"int:{v}", ["render", "office2d", "--steps", v, "--width", "32", "--height", "24", "--out", out_ok]),
                  ("--seed", f"int:{v}", ["render", "office2d", "--seed", v, "--width", "32", "--height", "24", "--out", out_ok])]
    for v in bad_out:
        cases += [("--out", f"out:{v[:12]}", ["render", "office2d", "--width", "32", "--height", "24", "--out", v]),
                  ("--out", f"out:{v[:12]}", ["demo", "--out", v])]
    for v in ["[1]", "{bad", "null", '"str"', "1", '{"no_such_kwarg": 1}']:
        cases.append(("--env-kwargs", f"json:{v}", ["eval", "polar_sim/GPISNav-v0", "--policy", "random", "--episodes", "1",
                                                    "--env-kwargs", v, "--out", out_ok]))
    for v in ["nope:thing", "os:getcwd", "random.x", ""]:
        cases.append(("--policy", f"policy:{v}", ["eval", "polar_sim/GPISNav-v0", "--policy", v, "--episodes", "1", "--out", out_ok]))
    for v in ["train", "", "ñ"]:
        cases.append(("--split", f"split:{v}", ["run", "sensors", "--quick", "--split", v, "--out", out_ok]))
    for v in ["-1", "abc", "0", "nan", "inf"]:
        cases.append(("--trial-timeout", f"float:{v}", ["run", "sensors", "--quick", "--trial-timeout", v, "--out", out_ok]))
    for v in ["bogus=1", "novalue", "=3", "seed=[", "seed=abc"]:
        cases.append(("--set", f"set:{v}", ["run", "sensors", "--quick", "--set", v, "--out", out_ok]))
    for v in ["moon_base", "x" * 5000, str(Path(tmp) / "missing.xml"), "ñ.xml", str(Path(tmp) / "file_as_dir")]:
        cases.append(("scene", f"scene:{v[:12]}", ["render", v, "--out", out_ok]))
    for v in ["nope", "", "x" * 3000]:
        cases.append(("experiment", f"exp:{v[:12]}", ["run", v, "--quick", "--out", out_ok]))
        cases.append(("env_id", f"env:{v[:12]}", ["eval", v, "--policy", "random"]))
    cases += [("run_a", "compare:missing", ["compare", str(Path(tmp) / "nope_a"), str(Path(tmp) / "nope_b")]),
              ("--size", "size:huge", ["run", "sensors", "--size", "huge", "--out", out_ok]),
              ("--backend", "backend:x", ["run", "sensors", "--quick", "--backend", "x"]),
              ("only", "bench:unknown", ["bench", "no_such_bench"])]
    return cases


def _ep_cli():
    """The CLI as one entry point: argument ``argv`` takes hostile command lines; a clear outcome
    is exit code 1 with one line on stderr naming the flag, or argparse's usage error (exit 2)."""

    def setup(tmp):
        (Path(tmp) / "file_as_dir").write_bytes(b"x")
        return None

    def call(t, a):
        import contextlib

        from polar_sim.cli import main

        flag, label, argv = a["argv"]
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                rc = main(argv)
            except SystemExit as exc:
                rc = exc.code
        text = err.getvalue().strip()
        if rc == 0:
            return rc
        bare = flag.lstrip("-")
        one_line = text.count("\n") == 0 if rc == 1 else "usage:" in text
        if rc in (1, 2) and one_line and (bare in text or flag in text or (rc == 2 and "argument" in text)):
            raise ValueError(f"argv: {flag}: exit {rc}: {text.splitlines()[-1][:160]}")
        raise RuntimeError(f"exit {rc}: {text[-300:]}")

    ep = EntryPoint("cli", setup=setup, args=lambda t, tmp: {"argv": None}, call=call, kinds={}, timeout=180.0)
    ep.cases = _cli_argvs
    return ep


# ---------------------------------------------------------------------------------------------------
# registry


_METRIC_ENTRIES = {
    "metrics.kitti_errors": _ep_metric(
        "kitti_errors", {"gt_poses": "poses", "est_poses": "poses", "lengths": "lengths", "step": "int+"},
        lambda: {"gt_poses": _poses_line(), "est_poses": _poses_line(), "lengths": [30.0, 60.0], "step": 5},
        names={"gt_poses": ("gt_poses", "est_poses"), "est_poses": ("gt_poses", "est_poses")}),
    "metrics.ate": _ep_metric("ate", {"gt_poses": "poses", "est_poses": "poses", "align": "choice"},
                              lambda: {"gt_poses": _poses_line(), "est_poses": _poses_line(), "align": "se3"},
                              names={"gt_poses": ("est_poses",), "est_poses": ("gt_poses",)}),
    "metrics.rpe": _ep_metric("rpe", {"gt_poses": "poses", "est_poses": "poses", "delta": "int+"},
                              lambda: {"gt_poses": _poses_line(), "est_poses": _poses_line(), "delta": 2},
                              names={"gt_poses": ("est_poses",), "est_poses": ("gt_poses",)}),
    "metrics.add": _ep_metric("add", {"model_points": "points", "T_gt": "pose", "T_est": "pose"},
                              lambda: {"model_points": _pts(), "T_gt": _pose(), "T_est": _pose(yaw=0.25)}),
    "metrics.adds": _ep_metric("adds", {"model_points": "points", "T_gt": "pose", "T_est": "pose"},
                               lambda: {"model_points": _pts(), "T_gt": _pose(), "T_est": _pose(yaw=0.25)}),
    "metrics.iou": _ep_metric("iou", {"mask_a": "mask", "mask_b": "mask"},
                              lambda: {"mask_a": np.eye(8, dtype=bool), "mask_b": np.tri(8, dtype=bool)},
                              names={"mask_a": ("mask_b",), "mask_b": ("mask_a",)}),
    "metrics.hausdorff": _ep_metric("hausdorff", {"points_a": "points", "points_b": "points"},
                                    lambda: {"points_a": _pts(30, 1), "points_b": _pts(40, 2)},
                                    names={"points_a": ("points_b",), "points_b": ("points_a",)}),
    "metrics.chamfer": _ep_metric("chamfer", {"points_a": "points", "points_b": "points"},
                                  lambda: {"points_a": _pts(30, 1), "points_b": _pts(40, 2)},
                                  names={"points_a": ("points_b",), "points_b": ("points_a",)}),
}

#: name -> builder of the :class:`EntryPoint` (builders import lazily).
ENTRY_POINTS: dict[str, Callable[[], EntryPoint]] = {
    "World": _ep_world_init, "World.step": _ep_world_step, "World.camera": _ep_world_camera,
    "World.lidar": _ep_world_lidar, "World.sdf": _ep_world_sdf, "RangeNoise": _ep_world_noise,
    "GPISMap2D.update": _ep_gpis2d_update, "GPISMap2D.query": _ep_gpis2d_query,
    "GPISMap2D.save": _ep_gpis2d_save, "GPISMap2D.load": _ep_gpis2d_load,
    "GPISMap3D.update": _ep_gpis3d_update, "GPISMap3D.query": _ep_gpis3d_query,
    "localize": _ep_localize,
    "GroundVO": _ep_groundvo_init, "GroundVO.process": _ep_groundvo_process,
    "ObjectTracker": _ep_tracker_init, "ObjectTracker.process": _ep_tracker_process,
    **_METRIC_ENTRIES,
    "Recording.append": _ep_recording_append, "Recording.save": _ep_recording_save,
    "Recording.load": _ep_recording_load,
    "cli": _ep_cli,
}


class _EnvEntries(dict):
    """Env entry points (``ID.step``, ``ID.reset``) resolved on demand, so listing the module entry
    points does not import gymnasium."""

    def __missing__(self, key):
        for suffix, fn in ((".step", _ep_env_step), (".reset", _ep_env_reset)):
            if key.startswith("polar_sim/") and key.endswith(suffix):
                env_id = key[: -len(suffix)]
                return lambda: fn(env_id)
        raise KeyError(key)


ENTRY_POINTS = _EnvEntries(ENTRY_POINTS)


def entry_points_of(name):
    """Entry point names belonging to module, function family or env ``name``."""
    if name.startswith("polar_sim/"):
        return [f"{name}.reset", f"{name}.step"]
    return [k for k in dict.keys(ENTRY_POINTS) if k == name or k.startswith(name + ".")]


# ---------------------------------------------------------------------------------------------------
# module checks


@dataclasses.dataclass
class ModuleCase:
    """How to exercise one module class with valid data.

    ``build(**params)`` makes an instance (``params`` are the documented constructor arguments
    that must come back from ``get_params()``); ``frames()`` gives the per-frame calls as a list
    of positional-argument tuples for ``method``; ``query`` is ``(method name, args tuple)`` or
    None; ``seed_param`` names the random-state parameter, if any; ``outputs(result)`` turns a
    per-frame result into arrays to compare bit for bit.
    """

    name: str
    build: Callable
    params: dict
    frames: Callable
    method: str
    query: tuple | None = None
    seed_param: str | None = None
    outputs: Callable = dataclasses.field(default=lambda r: r)
    savable: bool = False


def _flatten(x, out=None):
    """Arrays and scalars of a result, in a fixed order, for bit-identical comparisons."""
    out = [] if out is None else out
    if isinstance(x, np.ndarray):
        out.append(x)
    elif isinstance(x, (int, float, bool, str, np.generic)) or x is None:
        out.append(np.asarray(x if x is not None else np.nan))
    elif isinstance(x, dict):
        for k in sorted(x):
            _flatten(x[k], out)
    elif isinstance(x, (list, tuple)):
        for e in x:
            _flatten(e, out)
    elif dataclasses.is_dataclass(x):
        for f in dataclasses.fields(x):
            _flatten(getattr(x, f.name), out)
    elif hasattr(x, "__dict__"):
        for k in sorted(vars(x)):
            _flatten(getattr(x, k), out)
    return out


def _same(a, b):
    fa, fb = _flatten(a), _flatten(b)
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


def _mod_gpis2d():
    from polar_sim.gpis import GPISMap2D

    def frames():
        out = []
        for k in range(3):
            pose = np.array([0.1 * k, 0.05 * k, 0.1 * k])
            a, r = _scan_circle(pose=pose)
            out.append((a, r, pose))
        return out

    return ModuleCase("GPISMap2D", build=lambda **p: GPISMap2D(**p), params={"map_scale": 1.1, "obs_var_thre": 0.1},
                      frames=frames, method="update", query=("query", (np.array([[0.5, 0.5], [2.0, -1.0]]),)),
                      savable=True)


def _mod_gpis3d():
    from polar_sim.gpis import GPISMap3D

    def frames():
        out = []
        for k in range(2):
            depth, K = _depth_plane(z=1.0 + 0.05 * k)
            T = np.eye(4)
            T[:3, 3] = [0.01 * k, 0.0, 0.0]
            out.append((depth, K, T))
        return out

    return ModuleCase("GPISMap3D", build=lambda **p: GPISMap3D(**p), params={"map_scale": 0.05}, frames=frames,
                      method="update", query=("query", (np.array([[0.0, 0.0, 0.9], [0.05, 0.0, 1.0]]),)), savable=True)


def _mod_groundvo():
    from polar_sim.ground import GroundVO

    s = _cached("vo", _vo_sequence)
    return ModuleCase("GroundVO", build=lambda **p: GroundVO(s["K"], s["camera_height"], **p),
                      params={"model": "6param", "sampling": "weighted", "seed": 3},
                      frames=lambda: [(s["rgb"][i], float(s["times"][i])) for i in range(len(s["rgb"]))],
                      method="process", seed_param="seed")


def _mod_tracker():
    from polar_sim.tracking import ObjectTracker

    seq, pts, nrm, frames = _cached("trk", _track_sequence)
    return ModuleCase("ObjectTracker", build=lambda **p: ObjectTracker(pts, seq.K, seq.poses[0], model_normals=nrm, **p),
                      params={"appearance": "ww", "random_state": 3},
                      frames=lambda: [(f["rgb"], f["depth"], i / 30) for i, f in enumerate(frames)],
                      method="process", seed_param="random_state")


#: module name -> builder of its :class:`ModuleCase`.
MODULES: dict[str, Callable[[], ModuleCase]] = {
    "GPISMap2D": _mod_gpis2d, "GPISMap3D": _mod_gpis3d, "GroundVO": _mod_groundvo, "ObjectTracker": _mod_tracker,
}


class Check:
    """A named check: calling it runs the check and raises ``AssertionError`` on a failure."""

    def __init__(self, name, fn):
        self.name = name
        self._fn = fn

    def __call__(self):
        return self._fn()

    def __repr__(self):
        return f"Check({self.name!r})"


def _hostile_check(entry, n, isolate):
    def run():
        res = run_battery(entry, n=n, isolate=isolate)
        assert res.ok, res.report()
    return run


def _module_contract_checks(name, case_builder):
    def case():
        return _cached(("case", name), case_builder)

    def fresh(**extra):
        c = case()
        return c.build(**{**c.params, **extra})

    def feed(m, frames=None):
        c = case()
        return [getattr(m, c.method)(*f) for f in (frames if frames is not None else c.frames())]

    def params_stored():
        c = case()
        m = fresh()
        assert hasattr(m, "get_params"), f"{name} has no get_params()"
        got = m.get_params()
        for k, v in c.params.items():
            assert k in got and got[k] == v, f"get_params()[{k!r}] = {got.get(k)!r}, expected {v!r}"
        if hasattr(m, "set_params"):
            m.set_params(**c.params)

    def no_state_before_update():
        m = fresh()
        learned = [k for k in vars(m) if k.endswith("_") and not k.startswith("__")]
        assert not learned, f"learned attributes before the first {case().method}(): {learned}"

    def query_before_update():
        c = case()
        if c.query is None:
            return
        from polar_sim.errors import NotUpdatedError

        m = fresh()
        try:
            getattr(m, c.query[0])(*c.query[1])
        except NotUpdatedError:
            return
        raise AssertionError(f"{c.query[0]}() before any {c.method}() did not raise NotUpdatedError")

    def query_pure():
        c = case()
        if c.query is None:
            return
        m = fresh()
        feed(m)
        before = state_digest(m, ignore=("_kd_tree", "_kd_idx", "_kd_version"))
        args = tuple(np.array(a, copy=True) for a in c.query[1])
        out = getattr(m, c.query[0])(*args)
        assert state_digest(m, ignore=("_kd_tree", "_kd_idx", "_kd_version")) == before, f"{c.query[0]}() changed the state"
        for o in _flatten(out):
            for a in args:
                assert not np.shares_memory(o, a), f"{c.query[0]}() output shares memory with its input"

    def outputs_do_not_alias_inputs():
        m = fresh()
        frames = case().frames()
        for f in frames:
            r = getattr(m, case().method)(*f)
            for o in _flatten(r):
                for a in f:
                    if isinstance(a, np.ndarray) and isinstance(o, np.ndarray) and o.size > 1:
                        assert not np.shares_memory(o, a), f"{case().method}() output shares memory with an input"

    def same_seed_same_output():
        a, b = fresh(), fresh()
        ra, rb = feed(a), feed(b)
        assert _same(ra, rb), "two instances with the same parameters and data gave different outputs"
        c = case()
        if c.query is not None:
            assert _same(getattr(a, c.query[0])(*c.query[1]), getattr(b, c.query[0])(*c.query[1])), "queries differ"

    def across_processes():
        code = (f"import pickle,sys; from polar_sim.testing import _module_outputs; "
                f"sys.stdout.buffer.write(pickle.dumps(_module_outputs({name!r})))")
        outs = []
        for _ in range(2):
            r = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=600,
                               env=dict(os.environ, PYTHONHASHSEED="random"))
            assert r.returncode == 0, r.stderr.decode()[-2000:]
            outs.append(pickle.loads(r.stdout))
        assert _same(outs[0], outs[1]), "two processes gave different outputs for the same seed and data"
        assert _same(outs[0], _module_outputs(name)), "a subprocess and this process gave different outputs"

    def reset_replay():
        m = fresh()
        feed(m)
        assert hasattr(m, "reset"), f"{name} has no reset()"
        m.reset()
        learned = [k for k in vars(m) if k.endswith("_") and not k.startswith("__")]
        assert not learned, f"reset() kept learned attributes {learned}"
        assert _same(feed(m), feed(fresh())), "reset() then replay differs from a fresh instance"

    def pickles():
        m = fresh()
        ra = feed(m)
        m2 = pickle.loads(pickle.dumps(m))
        c = case()
        if c.query is not None:
            assert _same(getattr(m, c.query[0])(*c.query[1]), getattr(m2, c.query[0])(*c.query[1]))
        assert ra is not None

    def saves_without_pickle():
        c = case()
        if not c.savable:
            return
        m = fresh()
        feed(m)
        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / "m.npz"
            m.save(p)
            with np.load(p, allow_pickle=False) as z:
                for k in z.files:
                    z[k]
            m2 = type(m).load(p)
            assert _same(getattr(m, c.query[0])(*c.query[1]), getattr(m2, c.query[0])(*c.query[1])), "round trip differs"
            assert [q.name for q in Path(d).iterdir()] == ["m.npz"], "save() left stray files"

    return [("builds_and_stores_params", params_stored), ("no_learned_state_before_update", no_state_before_update),
            ("query_before_update_raises", query_before_update), ("query_is_pure", query_pure),
            ("outputs_do_not_alias_inputs", outputs_do_not_alias_inputs),
            ("same_seed_same_output", same_seed_same_output), ("same_output_across_processes", across_processes),
            ("reset_then_replay", reset_replay), ("pickles_in_memory", pickles), ("saves_without_pickle", saves_without_pickle)]


def _module_outputs(name):
    c = MODULES[name]()
    m = c.build(**c.params)
    out = [getattr(m, c.method)(*f) for f in c.frames()]
    if c.query is not None:
        out.append(getattr(m, c.query[0])(*c.query[1]))
    return _flatten(out)


def check_module(obj_or_factory, *, n_bad=None, isolate=True):
    """Named checks of a module (a name from :data:`MODULES`, a :class:`ModuleCase`, or an entry
    point family such as ``"metrics.kitti_errors"``, ``"World"``, ``"Recording"``, ``"cli"``).

    Yields :class:`Check` objects (``check.name``; call it to run it). ``n_bad`` hostile inputs per
    entry point (default 200, the full size); ``isolate`` runs them in a worker subprocess.
    """
    n = 200 if n_bad is None else n_bad
    if isinstance(obj_or_factory, ModuleCase):
        name, builder = obj_or_factory.name, (lambda c=obj_or_factory: c)
    else:
        name = obj_or_factory if isinstance(obj_or_factory, str) else getattr(obj_or_factory, "__name__", str(obj_or_factory))
        builder = MODULES.get(name)
    if builder is not None:
        for cname, fn in _module_contract_checks(name, builder):
            yield Check(f"{name}:{cname}", fn)
    for entry in entry_points_of(name):
        yield Check(f"{name}:hostile[{entry}]", _hostile_check(entry, n, isolate))


# ---------------------------------------------------------------------------------------------------
# env checks


def _rollout(env_id, seed, n_steps, kwargs=None):
    """Observations, rewards and truth of ``n_steps`` mid-range actions after ``reset(seed)``."""
    env = _make_env(env_id, **(kwargs or {}))
    try:
        obs, info = env.reset(seed=seed)
        out = [obs, _truth_of(info)]
        sp = env.action_space
        env.action_space.seed(seed)
        for _ in range(n_steps):
            a = sp.sample()
            obs, r, term, trunc, info = env.step(a)
            out += [obs, float(r), bool(term), bool(trunc), _truth_of(info)]
            if term or trunc:
                obs, info = env.reset()
                out += [obs, _truth_of(info)]
        return _flatten(out)
    finally:
        env.close()


def _truth_of(info):
    return {k: v for k, v in info.items() if isinstance(v, (np.ndarray, float, int, bool, np.generic, dict, list, tuple))}


def check_polar_env(env_id, *, n_steps=5, n_bad=None, isolate=True):
    """Named checks of a registered env id; yields :class:`Check` objects."""
    n = 200 if n_bad is None else n_bad

    def gym_check_env():
        from gymnasium.utils.env_checker import check_env

        env = _make_env(env_id)
        try:
            check_env(env.unwrapped, skip_render_check=True)
        finally:
            env.close()

    def seeded_reset():
        assert _same(_rollout(env_id, 7, n_steps), _rollout(env_id, 7, n_steps)), "same seed, different rollouts"

    def across_processes():
        code = (f"import pickle,sys; from polar_sim.testing import _rollout; "
                f"sys.stdout.buffer.write(pickle.dumps(_rollout({env_id!r}, 7, {n_steps})))")
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=900)
        assert r.returncode == 0, r.stderr.decode()[-2000:]
        assert _same(pickle.loads(r.stdout), _rollout(env_id, 7, n_steps)), "a subprocess gave a different rollout"

    def obs_in_space():
        env = _make_env(env_id)
        try:
            obs, info = env.reset(seed=3)
            assert env.observation_space.contains(obs), "reset() observation outside observation_space"
            for _ in range(n_steps):
                obs, r, term, trunc, info = env.step(env.action_space.sample())
                assert env.observation_space.contains(obs), "step() observation outside observation_space"
                assert np.isfinite(r), f"reward {r} is not finite"
                if term or trunc:
                    env.reset()
        finally:
            env.close()

    def truth_in_info():
        env = _make_env(env_id)
        try:
            _, info = env.reset(seed=3)
            assert isinstance(info, dict) and info, "reset() info holds no truth"
            _, _, _, _, info = env.step(env.action_space.sample())
            assert isinstance(info, dict) and info, "step() info holds no truth"
        finally:
            env.close()

    def double_close():
        env = _make_env(env_id)
        env.reset(seed=0)
        env.close()
        env.close()

    def rejected_step_keeps_state():
        env = _make_env(env_id)
        try:
            env.reset(seed=0)
            sp = env.action_space
            if not hasattr(sp, "high"):
                return
            before = _env_state(env)
            # a value just above the bound, as in issue 17 (finding 5)
            bad = (sp.high.astype(np.float64) * (1 + 1e-7) + 1e-7).astype(sp.dtype)
            for a in (bad, np.full(sp.shape, np.nan, sp.dtype), (sp.high * 2).astype(sp.dtype)):
                try:
                    env.step(a)
                except (ValueError, TypeError):
                    assert _env_state(env) == before, f"step({a!r}) was refused but changed the env"
                else:
                    return   # accepted (clipped); the hostile battery judges that
        finally:
            env.close()

    checks = [("check_env", gym_check_env), ("seeded_reset_determinism", seeded_reset),
              ("same_rollout_across_processes", across_processes), ("observations_in_space", obs_in_space),
              ("truth_in_info", truth_in_info), ("double_close", double_close),
              ("rejected_step_keeps_state", rejected_step_keeps_state)]
    for cname, fn in checks:
        yield Check(f"{env_id}:{cname}", fn)
    for entry in entry_points_of(env_id):
        yield Check(f"{env_id}:hostile[{entry}]", _hostile_check(entry, n, isolate))


def env_ids():
    """The registered polar_sim env ids."""
    return _env_ids()


if __name__ == "__main__":
    if len(sys.argv) >= 2 and sys.argv[1] == "--worker":
        _worker(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]))
