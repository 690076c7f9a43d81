"""The module contract's checks, after scikit-learn's ``check_estimator``: each check takes a
:class:`Subject` (a module instance, its :class:`~polar_sim.params.Tags` and its
:class:`~polar_sim.params.CheckData`) and raises ``AssertionError`` on a failure.

Every check works on clones, ``type(obj)(**obj.get_params(deep=False))``, never on the instance
it was given. :func:`module_checks` lists the checks that apply to a subject's tags: a class
without a query has no query checks, one that does not save no save check (none returns early).
"""

from __future__ import annotations

import copy
import functools
import importlib
import inspect
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from polar_sim.errors import NotUpdatedError
from polar_sim.testing.digest import flatten, output_digest, same_output, state_digest

__all__ = ["MODULE_CLASSES", "Subject", "example", "module_checks", "module_instances"]

#: The module classes held to the contract, as ``"package.module:Class"`` (imported on demand).
MODULE_CLASSES = tuple(f"{package}:{name}" for package, names in (
    ("polar_sim.gpis", ("GPISMap2D", "GPISMap3D")), ("polar_sim.ground", ("GroundVO",)),
    ("polar_sim.tracking", ("ObjectTracker",)),
    ("polar_sim.baselines", ("OccupancyGrid2D", "DiscreteSDF2D", "DiscreteSDF3D", "LikelihoodField",
                             "ParticleFilterLocalizer", "ICPLocalizer", "RoomSDF2D", "RoomSDF3D"))) for name in names)

#: A lazily built search index is a cache, not state: left out of "the state did not change".
_CACHES = ("_kd_tree", "_kd_idx", "_kd_version")


@functools.lru_cache(maxsize=16)
def _check_data(tags):
    return tags.check_data()


class Subject:
    """One module under check: clones of ``obj``, fed with its class's check data."""

    def __init__(self, obj):
        if not (hasattr(obj, "get_params") and hasattr(obj, "__polar_tags__")) or isinstance(obj, type):
            raise TypeError(f"obj: a module instance with get_params() and __polar_tags__() is needed "
                            f"(polar_sim.params.Parameterised), got {obj!r}")
        self.obj, self.tags, self.name = obj, obj.__polar_tags__(), type(obj).__name__

    def data(self):
        """A private copy of the class's :class:`~polar_sim.params.CheckData` (inputs may be kept)."""
        return copy.deepcopy(_check_data(self.tags))

    def clone(self):
        """A new instance with the same parameters, unfed; a random-state parameter left at None
        (fresh OS entropy) is set to 0, as scikit-learn's ``set_random_state`` does."""
        params = copy.deepcopy(self.obj.get_params(deep=False))
        if self.tags.random_state is not None and params.get(self.tags.random_state) is None:
            params[self.tags.random_state] = 0
        return type(self.obj)(**params)

    def fresh(self):
        """A clone with the data's ``prepare`` calls made: ready for its first frame."""
        m = self.clone()
        self.prepare(m)
        return m

    def prepare(self, m):
        for method, args in self.data().prepare:
            getattr(m, method)(*args)

    def feed(self, m, frames=None):
        """The per-frame method's results over ``frames`` (default: all of the data's frames)."""
        frames = self.data().frames if frames is None else frames
        return [getattr(m, self.tags.update)(*f) for f in frames]

    def query(self, m, args=None):
        return getattr(m, self.tags.query)(*(self.data().query if args is None else args))

    def outputs(self, m):
        """Everything ``m`` answers to the data: per-frame results, then the query's."""
        out = self.feed(m) if self.tags.update else []
        return out + ([self.query(m)] if self.tags.query else [])


def _learned(m):
    """The instance's learned attributes (scikit-learn's trailing underscore)."""
    return [k for k in vars(m) if k.endswith("_") and not k.startswith("__")]


def _constructor_names(cls):
    sig = inspect.signature(cls.__init__)
    return [p.name for p in sig.parameters.values()
            if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]


def check_params_stored(s):
    """Every constructor parameter is stored under its name and returned by ``get_params()``; a
    clone built from them has the same parameters; ``set_params`` of them changes nothing."""
    names, got = _constructor_names(type(s.obj)), s.obj.get_params(deep=False)
    assert sorted(got) == sorted(names), f"get_params(deep=False) keys {sorted(got)} != constructor's {sorted(names)}"
    for k in names:
        assert same_output(getattr(s.obj, k), got[k]), f"get_params()[{k!r}] differs from the attribute {k!r}"
    c = type(s.obj)(**copy.deepcopy(got))
    assert same_output(c.get_params(deep=False), got), "a clone's get_params() differs from the original's"
    assert c.set_params(**got) is c, "set_params() does not return self"
    assert same_output(c.get_params(deep=False), got), "set_params(**get_params()) changed the parameters"
    if s.tags.random_state is not None:
        assert s.tags.random_state in names, f"random_state {s.tags.random_state!r} is not a parameter"


def check_no_state_before_update(s):
    learned = _learned(s.clone())
    assert not learned, f"learned attributes before any {s.tags.update}(): {learned}"


def check_query_before_update(s):
    """Before any update the query raises ``NotUpdatedError`` (or, for a class whose query needs
    no update, answers without changing the state)."""
    m = s.fresh()
    before = state_digest(m, ignore=_CACHES)
    try:
        s.query(m)
    except NotUpdatedError:
        assert s.tags.requires_update, f"{s.tags.query}() before any update raised NotUpdatedError"
        return
    assert not s.tags.requires_update, f"{s.tags.query}() before any {s.tags.update}() did not raise NotUpdatedError"
    assert state_digest(m, ignore=_CACHES) == before, f"{s.tags.query}() before any update changed the state"


def check_query_pure(s):
    """The query leaves the state as it was and returns arrays that do not share its inputs' memory."""
    m = s.fresh()
    s.feed(m)
    before = state_digest(m, ignore=_CACHES)
    args = s.data().query
    out = s.query(m, args)
    assert state_digest(m, ignore=_CACHES) == before, f"{s.tags.query}() changed the state"
    for o in flatten(out):
        for a in args:
            assert not np.shares_memory(o, a), f"{s.tags.query}() output shares memory with its input"


def check_outputs_do_not_alias_inputs(s):
    m = s.fresh()
    for f in s.data().frames:
        for o in flatten(s.feed(m, [f])):
            for a in f:
                if isinstance(a, np.ndarray) and o.size > 1:
                    assert not np.shares_memory(o, a), f"{s.tags.update}() output shares memory with an input"


def check_same_seed_same_output(s):
    assert same_output(s.outputs(s.fresh()), s.outputs(s.fresh())), \
        "two clones (same parameters, same seed) gave different outputs for the same data"


def _json_params(obj, init):
    """The instance's parameters a subprocess can rebuild from JSON: numbers, strings, None."""
    return {k: v for k, v in obj.get_params(deep=False).items()
            if k not in init and (v is None or isinstance(v, (bool, int, float, str)))}


def _import(cls_path):
    module, _, qual = cls_path.partition(":")
    return functools.reduce(getattr, qual.split("."), importlib.import_module(module))


def example(cls, **params):
    """An instance of module class ``cls`` that fits its check data: ``cls(**init, **params)``."""
    return cls(**{**_check_data(cls.TAGS).init, **params})


def module_instances():
    """One :func:`example` instance of every class in :data:`MODULE_CLASSES`."""
    return [example(_import(p)) for p in MODULE_CLASSES]


def example_outputs(cls_path, params_json):
    """Digest of the outputs of :func:`example` (with the JSON ``params``) over its check data;
    ``cls_path`` is ``"package.module:Class"`` (what a subprocess runs)."""
    s = Subject(example(_import(cls_path), **json.loads(params_json)))
    return output_digest(s.outputs(s.fresh()))


def check_across_processes(s):
    """The class's check data give bit-identical outputs in a fresh process (its hash seed random,
    so another than this process's) and in this one, with the instance's number, string and None
    parameters (arrays and stage configs come from the check data or the defaults)."""
    cls = type(s.obj)
    path = f"{cls.__module__}:{cls.__qualname__}"
    params = json.dumps(_json_params(s.clone(), s.data().init))
    code = f"from polar_sim.testing.contract import example_outputs; print(example_outputs({path!r}, {params!r}))"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                       env=dict(os.environ, PYTHONHASHSEED="random"), check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip().splitlines()[-1] == example_outputs(path, params), \
        "a fresh process and this one gave different outputs for the same seed and data"


def check_reset_replay(s):
    m = s.fresh()
    s.feed(m)
    assert m.reset() is m, "reset() does not return self"
    learned = _learned(m)
    assert not learned, f"reset() kept learned attributes {learned}"
    s.prepare(m)
    assert same_output(s.outputs(m), s.outputs(s.fresh())), "reset() then replay differs from a fresh clone"


def check_deep_copies(s):
    """A deep copy taken mid-sequence is independent and equal: both continue alike, and feeding
    the copy leaves the original as it was."""
    frames = s.data().frames
    half = max(1, len(frames) // 2)
    m = s.fresh()
    s.feed(m, frames[:half])
    m2 = copy.deepcopy(m)
    before = state_digest(m)
    rest2 = s.feed(m2, frames[half:])
    assert state_digest(m) == before, "feeding the deep copy changed the original"
    assert same_output(s.feed(m, frames[half:]), rest2), "the original and its deep copy continue differently"
    if s.tags.query:
        assert same_output(s.query(m), s.query(m2)), "the original and its deep copy answer differently"


def check_saves_without_pickle(s):
    """``save`` writes one file that loads with ``allow_pickle=False``; ``load`` answers alike."""
    m = s.fresh()
    s.feed(m)
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "m.npz"
        m.save(p)
        try:
            with np.load(p, allow_pickle=False) as z:
                for k in z.files:
                    z[k]
        except ValueError as exc:
            raise AssertionError(f"the saved file needs pickle to load: {exc}") from None
        m2 = type(m).load(p)
        if s.tags.query:
            assert same_output(s.query(m), s.query(m2)), "the loaded copy answers differently"
        assert [q.name for q in Path(d).iterdir()] == ["m.npz"], "save() left stray files"


def module_checks(tags):
    """(name, check) pairs of the module contract that apply to ``tags``, in order."""
    checks = [("builds_and_stores_params", check_params_stored)]
    if tags.update:
        checks.append(("no_learned_state_before_update", check_no_state_before_update))
    if tags.query:
        checks += [("query_before_update_raises" if tags.requires_update else "query_before_update_answers",
                    check_query_before_update), ("query_is_pure", check_query_pure)]
    if tags.update:
        checks.append(("outputs_do_not_alias_inputs", check_outputs_do_not_alias_inputs))
    checks += [("same_seed_same_output", check_same_seed_same_output),
               ("same_output_across_processes", check_across_processes)]
    if tags.update:
        checks += [("reset_then_replay", check_reset_replay), ("deep_copies", check_deep_copies)]
    if tags.saves:
        checks.append(("saves_without_pickle", check_saves_without_pickle))
    return checks
