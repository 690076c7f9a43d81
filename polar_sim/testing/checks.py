"""Named checks: :func:`check_module` (after scikit-learn's ``check_estimator``) and
:func:`check_polar_env` (after gymnasium's ``check_env``)."""

from __future__ import annotations

import functools

from polar_sim.testing.battery import run_battery
from polar_sim.testing.contract import Subject, module_checks
from polar_sim.testing.entries import _env_ids, _module_class, entry_points_of
from polar_sim.testing.env_checks import ENV_CHECKS

__all__ = ["Check", "check_module", "check_entry_points", "check_polar_env", "env_ids"]


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


def check_module(obj, *, n_bad=None, isolate=True):
    """Named checks of a module instance (``check_module(GPISMap2D())``), as scikit-learn's
    ``check_estimator`` takes an estimator: the module contract that applies to the instance's
    tags (:mod:`polar_sim.testing.contract`, run on clones), then the hostile battery of each of
    its class's entry points.

    Yields :class:`Check` objects (``check.name``; call it to run it). ``n_bad`` hostile inputs per
    entry point (default 200, the full size); ``isolate`` runs them in a worker subprocess.
    """
    subject = Subject(obj)
    for cname, fn in module_checks(subject.tags):
        yield Check(f"{subject.name}:{cname}", functools.partial(fn, subject))
    cls = type(obj)
    path = f"{cls.__module__}:{cls.__qualname__}"
    n = 200 if n_bad is None else n_bad
    for entry in entry_points_of(subject.name if _module_class(subject.name) is cls else path):
        yield Check(f"{subject.name}:hostile[{entry}]", _hostile_check(entry, n, isolate))


def check_entry_points(name, *, n_bad=None, isolate=True):
    """The hostile battery of every entry point of ``name``: a module class's name, or a family
    of calls that is not a module (``"World"``, ``"Recording"``, ``"metrics.kitti_errors"``,
    ``"localize"``, ``"cli"``). Yields :class:`Check` objects."""
    n = 200 if n_bad is None else n_bad
    for entry in entry_points_of(name):
        yield Check(f"{name}:hostile[{entry}]", _hostile_check(entry, n, isolate))


def check_polar_env(env_id, *, n_steps=5, n_bad=None, isolate=True):
    """Named checks of a registered env id (:data:`~polar_sim.testing.env_checks.ENV_CHECKS`, after
    gymnasium's ``check_env``), then the hostile battery of its ``reset`` and ``step``; yields
    :class:`Check` objects."""
    for cname, fn in ENV_CHECKS:
        yield Check(f"{env_id}:{cname}", functools.partial(fn, env_id, n_steps))
    yield from check_entry_points(env_id, n_bad=n_bad, isolate=isolate)


def env_ids():
    """The registered polar_sim env ids."""
    return _env_ids()

