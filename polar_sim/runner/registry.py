"""Discovery of the experiments shipped in ``polar_sim.experiments`` (the ``experiments/`` folder)."""

from __future__ import annotations

import importlib
import pkgutil
import sys
from pathlib import Path

from polar_sim.runner.experiment import Experiment

__all__ = ["list_experiments", "get_experiment", "experiments_dir"]


def experiments_dir() -> Path:
    try:
        import polar_sim.experiments as pkg

        return Path(pkg.__path__[0])
    except ModuleNotFoundError:
        return Path(__file__).resolve().parents[2] / "experiments"


def _package():
    try:
        return importlib.import_module("polar_sim.experiments")
    except ModuleNotFoundError:
        # Source checkout without an install: expose experiments/ under the package name.
        d = experiments_dir()
        spec = importlib.util.spec_from_file_location("polar_sim.experiments", d / "__init__.py",
                                                      submodule_search_locations=[str(d)])
        mod = importlib.util.module_from_spec(spec)
        sys.modules["polar_sim.experiments"] = mod
        spec.loader.exec_module(mod)
        return mod


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
