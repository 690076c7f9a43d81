"""Hostile inputs: :func:`bad_inputs` turns an argument's kind and a valid value into seeded bad values."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["BadInput", "bad_inputs"]



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


def _depth_families(arg, valid, rng, c, tmp):
    v = np.asarray(valid)
    out = c + _array_families(arg, v, rng, nan="either", negative="refuse", empty="refuse", length="either")
    # another image size is a valid depth image (K says where its pixels look)
    out = [dataclasses.replace(b, expect="either") if b.label in ("shape:last-axis", "shape:transposed") else b
           for b in out]
    out.append(BadInput(arg, "dtype:float16", v.astype(np.float16), "either"))
    out.append(BadInput(arg, "zeros", np.zeros_like(v), "either"))
    return out


def _grid_families(arg, valid, rng, c, tmp):
    out = c + _array_families(arg, valid, rng, empty="refuse", length="either")
    return [dataclasses.replace(b, expect="either") if b.label in ("shape:last-axis", "shape:transposed") else b
            for b in out if b.label != "dtype:bool"]


def _image_families(kind, arg, valid, rng, c, tmp):
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


def _pose_kind_families(kind, arg, valid, rng, c, tmp):
    # 1e300 at a random entry: in the rotation block it must be refused, in the translation
    # it is a valid (if absurd) pose, like "pose:1e300"; either answer is fine, a crash is not.
    out = c + _array_families(arg, valid, rng, huge="either", empty="refuse") + _pose_families(arg, valid, rng)
    if kind == "pose_or_stack":   # a (1, 4, 4) stack is a documented input of the stack metrics
        out = [dataclasses.replace(b, expect="either") if b.label == "shape:extra-dim" else b for b in out]
    return out


def _poses_families(arg, valid, rng, c, tmp):
    v = np.asarray(valid)
    out = c + _array_families(arg, v, rng, huge="either", empty="refuse")
    k = int(rng.integers(len(v)))
    for b in _pose_families(arg, v[k], rng):
        if b.value.shape == (4, 4):
            w = v.copy()
            w[k] = b.value
            out.append(BadInput(arg, b.label, w, b.expect))
    return out


def _K_families(arg, valid, rng, c, tmp):
    K = np.asarray(valid, np.float64)
    out = c + _array_families(arg, K, rng, huge="either", empty="refuse", negative="either")
    for label, (i, j, x) in (("K:fx-negative", (0, 0, -K[0, 0])), ("K:fy-zero", (1, 1, 0.0)),
                             ("K:last-row", (2, 0, 1.0)), ("K:fx-nan", (0, 0, np.nan))):
        b = K.copy()
        b[i, j] = x
        out.append(BadInput(arg, label, b, "refuse"))
    return out


def _lengths_families(arg, valid, rng, c, tmp):
    return c[:-2] + [BadInput(arg, "str-number", "100", "refuse"), BadInput(arg, "negative", [-100.0], "refuse"),
                     BadInput(arg, "zero", [0.0], "refuse"), BadInput(arg, "nan", [np.nan], "refuse"),
                     BadInput(arg, "inf", [np.inf], "refuse"), BadInput(arg, "empty", [], "refuse"),
                     BadInput(arg, "scalar", 100.0, "refuse"), BadInput(arg, "nested", [[100.0]], "refuse"),
                     BadInput(arg, "complex", [100 + 1j], "refuse"), BadInput(arg, "1e300", [1e300], "either")]


def _frame_families(arg, valid, rng, c, tmp):
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


def _scan2d_families(arg, valid, rng, c, tmp):
    a, r = valid
    out = [BadInput(arg, "None", None, "refuse"), BadInput(arg, "str", "abc", "refuse"),
           BadInput(arg, "tuple:1", (a,), "refuse"), BadInput(arg, "tuple:3", (a, r, r), "refuse"),
           BadInput(arg, "object", _Foreign(), "refuse")]
    out += [dataclasses.replace(b, value=(b.value, r)) for b in bad_inputs("angles", a, arg, rng)
            if not b.label.startswith(("None", "str", "bytes", "dict", "object", "bool", "complex", "numeric-str"))]
    out += [dataclasses.replace(b, value=(a, b.value)) for b in bad_inputs("ranges", r, arg, rng)
            if not b.label.startswith(("None", "str", "bytes", "dict", "object", "bool", "complex", "numeric-str"))]
    return out


def bad_inputs(kind, valid, arg, rng, *, tmp=None):
    """Hostile inputs (list of :class:`BadInput`) for argument ``arg`` of ``kind`` whose valid value
    is ``valid``. Kinds: ``points``, ``angles``, ``ranges``, ``depth``, ``image``, ``mask``,
    ``pose``, ``poses``, ``pose2d``, ``K``, ``grid`` (an occupancy array of any size), ``vector``,
    ``lengths``, ``float``, ``float+``, ``unit``, ``int+``, ``int0``, ``seed``, ``bool``, ``choice``, ``name``, ``path_in``,
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
        return _depth_families(arg, valid, rng, c, tmp)
    if kind == "grid":   # a whole occupancy array: any size with the same number of axes is a valid grid
        return _grid_families(arg, valid, rng, c, tmp)
    if kind in ("image", "mask"):
        return _image_families(kind, arg, valid, rng, c, tmp)
    if kind in ("pose", "pose_or_stack"):
        return _pose_kind_families(kind, arg, valid, rng, c, tmp)
    if kind == "poses":
        return _poses_families(arg, valid, rng, c, tmp)
    if kind == "pose2d":
        return c + _array_families(arg, valid, rng, huge="either", empty="refuse")
    if kind == "K":
        return _K_families(arg, valid, rng, c, tmp)
    if kind == "lengths":
        return _lengths_families(arg, valid, rng, c, tmp)
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
        return _frame_families(arg, valid, rng, c, tmp)
    if kind == "scan2d":
        return _scan2d_families(arg, valid, rng, c, tmp)
    if kind == "object":
        return [BadInput(arg, "None", None, "refuse"), BadInput(arg, "str", "abc", "refuse"),
                BadInput(arg, "object", _Foreign(), "refuse"), BadInput(arg, "int", 3, "refuse")]
    raise ValueError(f"kind: unknown argument kind {kind!r}")
