"""Discovery of the experiments shipped in ``polar_sim.experiments`` (the ``experiments/`` folder)."""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path

from polar_sim.runner.experiment import Experiment

__all__ = ["list_experiments", "get_experiment", "experiments_dir"]


def experiments_dir() -> Path:
    """The folder of the shipped experiment files (``experiments/``, imported as ``polar_sim.experiments``)."""
    return Path(_package().__path__[0])


def _package():
    # One import path in a source checkout and in an install: polar_sim/experiments is a link to
    # experiments/ in the repository, and the same folder packaged as polar_sim.experiments in a wheel.
    return importlib.import_module("polar_sim.experiments")


def list_experiments():
    """Names of the shipped experiments, sorted."""
    pkg = _package()
    return sorted(m.name for m in pkgutil.iter_modules(pkg.__path__) if not m.name.startswith("_"))


def get_experiment(name) -> Experiment:
    """The :class:`Experiment` declared by ``experiments/<name>.py``.

    Raises ``ValueError`` listing the valid names for an unknown one.
    """
    if isinstance(name, Experiment):
        return name
    names = list_experiments()
    if name not in names:
        raise ValueError(f"experiment: unknown experiment {name!r}; valid: {', '.join(names)}")
    mod = importlib.import_module(f"polar_sim.experiments.{name}")
    exp = getattr(mod, "EXPERIMENT", None)
    if not isinstance(exp, Experiment):
        raise ValueError(f"experiment: experiments/{name}.py defines no EXPERIMENT = Experiment(...)")
    return exp
