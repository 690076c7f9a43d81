"""The types of an experiment's params and grid axes, and ``--set`` values checked against them.

A param's or an axis's type is read from the values the experiment declares for it (in
``params``/``grid``, and in every split and size): a param declared ``2`` takes integers, one
declared ``0.5`` takes numbers (an integer is converted, so ``config.json`` records what ran), one
declared ``None`` at full size and ``300`` at quick size takes ``null`` or an integer; a list takes
lists whose elements have the types of the declared elements. ``True`` is not an integer here, and
``2.5`` is not an integer (a trial would run ``int(2.5)`` while ``config.json`` said 2.5).

>>> kinds = declared_kinds([2, 4])
>>> conform(3, kinds, "param 'every'")
3
>>> conform(2.5, kinds, "param 'every'", [2, 4])
Traceback (most recent call last):
TypeError: param 'every': expected an integer (declared: 2, 4), got 2.5 (a number with a fraction)
"""

from __future__ import annotations

import json
import math

__all__ = ["declared_kinds", "conform"]

_NAMES = {"bool": "a boolean", "int": "an integer", "float": "a number", "str": "a string", "none": "null",
          "dict": "a JSON object", "list": "a list"}


def _kind(v) -> str:
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "bool"
    if isinstance(v, int):
        return "int"
    if isinstance(v, float):
        return "float"
    if isinstance(v, str):
        return "str"
    if isinstance(v, dict):
        return "dict"
    if isinstance(v, (list, tuple, range)):
        return "list"
    return type(v).__name__


def _json(v) -> str:
    """A value as ``--set`` spells it (JSON), cut to 60 characters."""
    try:
        text = json.dumps(v)
    except (TypeError, ValueError):
        text = repr(v)
    return text if len(text) <= 60 else text[:57] + "..."


def declared_kinds(values) -> dict:
    """The kinds of the declared ``values`` of one param or axis: ``{kind: None}``, and for lists
    ``{"list": kinds of their elements}`` (``{}`` when no element was declared: any)."""
    out = {}
    for v in values:
        k = _kind(v)
        if k == "list":
            out["list"] = {**out.get("list", {}), **declared_kinds(list(v))}
        else:
            out.setdefault(k, None)
    return out


def _describe(kinds) -> str:
    parts = []
    for k, sub in kinds.items():
        if k == "list":
            parts.append("a list" + (f" of {_describe(sub)} elements" if sub else ""))
        else:
            parts.append(_NAMES.get(k, k))
    return " or ".join(parts)


def conform(value, kinds, what, declared=None):
    """``value`` if its kind is one of ``kinds`` (lists element by element; an integer where
    only numbers are declared becomes a float), else ``TypeError`` naming ``what``, the expected
    type and the value. ``declared``: the declared values, shown in the message."""
    if not kinds:
        return value
    k = _kind(value)
    if k == "list" and "list" in kinds:
        return [conform(x, kinds["list"], f"{what} element", None) for x in value]
    if k in kinds:
        return value
    if k == "int" and "float" in kinds:
        return float(value)
    shown = ""
    if declared is not None:
        uniq = list(dict.fromkeys(_json(v) for v in declared))
        shown = f" (declared: {', '.join(uniq[:6])}{', ...' if len(uniq) > 6 else ''})"
    fraction = k == "float" and "int" in kinds and math.isfinite(value) and value != int(value)
    got = f"{_json(value)} ({'a number with a fraction' if fraction else _NAMES.get(k, k)})"
    raise TypeError(f"{what}: expected {_describe(kinds)}{shown}, got {got}")
