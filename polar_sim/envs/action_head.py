"""How a learned policy's last layer becomes ``(v, omega)``: a regression of the two values, or a
discrete head over bins of them (numpy only; torch trains, numpy acts).

An expert's actions are multimodal where it turns round an obstacle (left or right): a regression
by mean squared error averages the two modes into a stall, while a classifier over action bins keeps
them apart and acts in one. A head is ``None`` (regression: 2 outputs) or ``{"name": "bins", "v":
[...], "omega": [...]}``: a softmax over the ``len(v) * len(omega)`` joint bins (``v`` major). It is
trained on two-hot labels (each action value split linearly between its two nearest bin centres,
the joint label their outer product), so the probability-weighted mean of a unimodal prediction
recovers a continuous action; it acts in the mode of the most probable bin (:func:`decode`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["BINS", "check_head", "head_outputs", "decode", "two_hot"]

#: The default bins: the experts drive forward at up to 0.9 of ``max_speed`` and turn in place
#: (v = 0, 25 % of ``SDFNavigator``'s steps on Room-v2 training worlds), and use the whole yaw-rate range.
BINS = {"name": "bins", "v": [0.0, 0.3, 0.6, 0.9], "omega": [-1.0, -0.75, -0.5, -0.25, 0.0, 0.25, 0.5, 0.75, 1.0]}


def check_head(head):
    """``head`` if valid (None, or ``{"name": "bins", "v": centres, "omega": centres}`` with 2 to 64
    strictly increasing centres in [-1, 1] each), with the centres as lists of floats; else ``ValueError``."""
    if head is None:
        return None
    if not isinstance(head, dict) or head.get("name") != "bins" or set(head) != {"name", "v", "omega"}:
        raise ValueError(f"head: expected None or {{'name': 'bins', 'v': [...], 'omega': [...]}}, got {head!r}")
    out = {"name": "bins"}
    for k in ("v", "omega"):
        try:
            c = np.asarray(head[k], np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"head: {k} must be a list of numbers, got {head[k]!r}") from None
        if c.ndim != 1 or not 2 <= len(c) <= 64 or not np.isfinite(c).all() or (np.abs(c) > 1).any() \
                or (np.diff(c) <= 0).any():
            raise ValueError(f"head: {k} must hold 2 to 64 strictly increasing bin centres in [-1, 1], got {head[k]!r}")
        out[k] = [float(x) for x in c]
    return out


def head_outputs(head):
    """The number of values the last layer outputs for ``head``."""
    return 2 if head is None else len(head["v"]) * len(head["omega"])


def decode(head, out):
    """The action ``(v, omega)`` (2,) of the last layer's output ``out``.

    Regression (``head`` None): ``out`` itself. Bins: the softmax's most probable joint bin, refined
    by the probability-weighted mean of the bin centres over it and its neighbours (one bin either
    way on each axis), so the action stays within one mode.
    """
    out = np.asarray(out, np.float64)
    if head is None:
        return out
    v, w = np.asarray(head["v"]), np.asarray(head["omega"])
    p = np.exp(out - out.max()).reshape(len(v), len(w))
    i, j = np.unravel_index(int(np.argmax(p)), p.shape)
    rows, cols = slice(max(i - 1, 0), i + 2), slice(max(j - 1, 0), j + 2)
    q = p[rows, cols] / p[rows, cols].sum()
    return np.array([q.sum(1) @ v[rows], q.sum(0) @ w[cols]])


def _two_hot_axis(centres, x):
    """(n, len(centres)): each of ``x`` (n,) split linearly between its two nearest centres."""
    c = np.asarray(centres, np.float64)
    x = np.clip(np.asarray(x, np.float64), c[0], c[-1])
    hi = np.clip(np.searchsorted(c, x, side="right"), 1, len(c) - 1)
    t = (x - c[hi - 1]) / (c[hi] - c[hi - 1])
    out = np.zeros((len(x), len(c)))
    rows = np.arange(len(x))
    out[rows, hi - 1] = 1.0 - t
    out[rows, hi] += t
    return out


def two_hot(head, actions):
    """The training labels (n, ``head_outputs``) of the expert's ``actions`` (n, 2): per axis two-hot
    (values outside the centres' range go to the end centre), the joint label their outer product."""
    a = np.asarray(actions, np.float64).reshape(-1, 2)
    pv, pw = _two_hot_axis(head["v"], a[:, 0]), _two_hot_axis(head["omega"], a[:, 1])
    return (pv[:, :, None] * pw[:, None, :]).reshape(len(a), -1)
