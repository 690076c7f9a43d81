"""Entry points of a module class derived from its signature and its :class:`~polar_sim.params.Tags`:
the hostile battery of its constructor, per-frame method, query, ``save`` and ``load``, built from
its check data, with no hand-written table.

An argument's kind (what :func:`~polar_sim.testing.inputs.bad_inputs` attacks it with) comes from
its name, by the project's naming convention (:data:`ARG_KINDS`: ``angles``, ``ranges``, ``pose2d``,
``depth``, ``K``, ``rgb``, ...), else from its valid value (bool, int, float, str, a stage config or
another object). An argument of neither kind (a tuple of numbers with no conventional name) is
passed its valid value and not attacked.
"""

from __future__ import annotations

import copy
import dataclasses
import inspect
import numbers
from pathlib import Path

import numpy as np

from polar_sim.testing.contract import _CACHES, _check_data, example
from polar_sim.testing.entry import EntryPoint

__all__ = ["ARG_KINDS", "ARG_ALIASES", "kind_of", "module_entry_points"]

#: Argument kinds by argument name: the naming convention of every module's public calls.
ARG_KINDS = {
    "angles": "angles", "ranges": "ranges", "pose2d": "pose2d", "odom_pose2d": "pose2d", "depth": "depth",
    "K": "K", "T_world_cam": "pose", "T_world_sensor": "pose", "initial_pose": "pose", "rgb": "image",
    "t": "float", "points": "points", "model_points": "points", "scan": "scan2d",
    "occupied": "grid", "origin": "vector", "camera_height": "float+", "fps": "float+", "cell_size": "float+",
}
#: Other names an error about an argument may use: a scan's error names its angles or ranges; model
#: points and normals that disagree in length may be reported as either.
ARG_ALIASES = {"scan": ("angles", "ranges"), "model_points": ("model_normals",)}
#: Seconds one hostile call may take before it counts as a hang (a tracker's frame takes seconds).
_TIMEOUT = 120.0


def kind_of(name, value, *, random_state=None):
    """The :func:`~polar_sim.testing.inputs.bad_inputs` kind of argument ``name`` whose valid
    value is ``value``, or None (not attacked)."""
    if name == random_state:
        return "seed"
    kind = ARG_KINDS.get(name)
    if kind == "pose" and np.shape(value) == (3,):
        return "pose2d"
    if kind is not None:
        return kind
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, numbers.Integral):
        return "int0"
    if isinstance(value, numbers.Real):
        return "float"
    if isinstance(value, str):
        return "choice"
    if dataclasses.is_dataclass(value) or callable(getattr(value, "get_params", None)):
        return "object"
    return None


def _by_name(fn, args):
    """Positional ``args`` of callable ``fn`` as a dict by parameter name."""
    names = [p.name for p in inspect.signature(fn).parameters.values() if p.name != "self"]
    return dict(zip(names, args))


def _entry(name, setup, valid, call, tags, **kw):
    """An :class:`EntryPoint` whose valid arguments are ``valid`` (a dict, copied for every call)."""
    kinds = {k: kind for k, v in valid.items() if (kind := kind_of(k, v, random_state=tags.random_state))}
    return EntryPoint(name, setup=setup, args=lambda t, tmp: copy.deepcopy(valid), call=call, kinds=kinds,
                      names={k: ARG_ALIASES[k] for k in kinds if k in ARG_ALIASES}, timeout=_TIMEOUT, **kw)


def _seeded(params, tags):
    """``params`` with a random-state parameter left at None set to 0 (as the checks' clones)."""
    if tags.random_state is not None and params.get(tags.random_state) is None:
        params[tags.random_state] = 0
    return params


def _build_and_use(cls, params):
    """``cls(**params)``, prepared, fed the first frame of its check data and queried: a class may
    check its parameters in the constructor or when first used (scikit-learn checks them in
    ``fit``); either way a bad one must be refused by then."""
    from polar_sim.testing.contract import Subject

    from polar_sim.errors import NotUpdatedError

    m = cls(**params)
    s = Subject(m)
    s.prepare(m)
    if s.tags.update:
        s.feed(m, s.data().frames[:1])
    try:
        return s.query(m) if s.tags.query else m
    except NotUpdatedError:   # the parameters were taken; the first frame just left no data (min_range=1e300)
        return m


def _fitted(cls, frames=None):
    """An example of ``cls`` prepared and fed ``frames`` (default: all of its check data's)."""
    from polar_sim.testing.contract import Subject

    s = Subject(example(cls))
    m = s.fresh()
    s.feed(m, frames)
    return m


def module_entry_points(cls, prefix=None):
    """{entry point name: builder} of module class ``cls``: its constructor (``prefix``), its
    per-frame method, its query, and ``save``/``load`` when it saves (``prefix.method``).
    ``prefix`` defaults to the class name. Calls without an attackable argument are left out."""
    prefix = prefix or cls.__name__
    tags, data = cls.TAGS, _check_data(cls.TAGS)
    out = {prefix: lambda: _entry(prefix, lambda tmp: None, _seeded(example(cls).get_params(deep=False), tags),
                                  lambda t, a: _build_and_use(cls, a), tags)}
    if tags.update:
        last = data.frames[-1]
        out[f"{prefix}.{tags.update}"] = lambda: _entry(
            f"{prefix}.{tags.update}", lambda tmp: _fitted(cls, data.frames[:-1]),
            _by_name(getattr(cls, tags.update), last), lambda t, a: getattr(t, tags.update)(**a), tags)
    if tags.query:
        out[f"{prefix}.{tags.query}"] = lambda: _entry(
            f"{prefix}.{tags.query}", lambda tmp: _fitted(cls), _by_name(getattr(cls, tags.query), data.query),
            lambda t, a: getattr(t, tags.query)(**a), tags, pure=True, ignore=_CACHES)
    if tags.saves:
        out[f"{prefix}.save"] = lambda: EntryPoint(
            f"{prefix}.save", setup=lambda tmp: _fitted(cls), args=lambda t, tmp: {"path": str(Path(tmp) / "ok.npz")},
            call=lambda t, a: t.save(a["path"]), kinds={"path": "path_out"}, timeout=_TIMEOUT)
        out[f"{prefix}.load"] = lambda: _load_entry(cls, f"{prefix}.load")
    return {k: v for k, v in out.items() if v().kinds}


def _load_entry(cls, name):
    def path(t, tmp):
        p = Path(tmp) / f"valid_{cls.__name__}.npz"
        if not p.exists():
            _fitted(cls).save(p)
        return {"path": str(p)}

    return EntryPoint(name, setup=lambda tmp: None, args=path, call=lambda t, a: cls.load(a["path"]),
                      kinds={"path": "path_in"}, timeout=_TIMEOUT)
