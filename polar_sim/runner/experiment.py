"""The declarative experiment format.

An experiment is a module in ``experiments/`` (shipped as ``polar_sim.experiments``) that defines
one module-level ``EXPERIMENT = Experiment(...)``::

    from polar_sim.runner import Experiment, Check

    def trial(params, seed, ctx):
        # params: one point of the grid (dict); seed: int; ctx.out_dir: a folder for this
        # trial's artefacts (npz, png); ctx.quick: True in the CI size.
        ...
        return {"rmse_m": 0.01, "hausdorff_m": 0.05}      # flat dict of scalars/strings

    def summarize(table, out_dir, quick):
        # table: list of row dicts (params + "seed" + metrics); write figures into out_dir,
        # return the markdown body of summary.md
        ...

    def checks(table, quick):
        # the headline inequalities, evaluated on the finished table
        return [Check("gpis beats grid on Hausdorff", ok, "0.05 m < 0.09 m")]

    EXPERIMENT = Experiment(
        name="surface_accuracy",
        description="GPIS vs grid maps against exact SDF, versus data rate",
        grid={"method": ["gpis", "grid5", "grid10", "edt"], "spacing_m": [0.1, 0.25, 0.5, 1.0]},
        seeds=range(5),
        quick_grid={"method": ["gpis", "grid10"], "spacing_m": [1.0]},
        quick_seeds=[0],
        trial=trial, summarize=summarize, checks=checks,
    )

Every trial must be deterministic given ``(params, seed)``; the runner may run trials in any
order, in other processes, or on a Ray cluster.
"""

from __future__ import annotations

import dataclasses
import itertools
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

__all__ = ["Experiment", "Check", "TrialContext"]


@dataclasses.dataclass(frozen=True)
class Check:
    """One headline inequality of an experiment: its name, whether it held, and the figures."""

    name: str
    passed: bool
    detail: str = ""


@dataclasses.dataclass(frozen=True)
class TrialContext:
    """What a trial gets besides its parameters: a folder for its artefacts and the size flag."""

    out_dir: Path
    quick: bool


@dataclasses.dataclass(frozen=True)
class Experiment:
    """A declared sweep: the parameter grid, the seeds, the trial, the summary and the checks.

    Parameters
    ----------
    name : str
        Registry name, the module's file name by convention.
    description : str
        One line for ``polar-sim list``.
    grid : mapping of str to list
        Full parameter grid; the trials are its Cartesian product times ``seeds``.
    seeds : iterable of int
    trial : callable ``(params, seed, ctx) -> dict``
    summarize : callable ``(table, out_dir, quick) -> str`` (markdown), optional
    checks : callable ``(table, quick) -> list[Check]``, optional
    quick_grid, quick_seeds : the CI size (must finish in under 2 minutes on 2 cores).
    """

    name: str
    description: str
    grid: Mapping[str, list]
    seeds: Iterable[int]
    trial: Callable[[dict, int, TrialContext], dict]
    summarize: Callable[[list, Path, bool], str] | None = None
    checks: Callable[[list, bool], list] | None = None
    quick_grid: Mapping[str, list] | None = None
    quick_seeds: Iterable[int] | None = None

    def points(self, quick: bool = False, overrides: Mapping[str, Any] | None = None):
        """The list of ``(params, seed)`` trials, in a fixed order.

        ``overrides`` replaces grid axes (a scalar or a list); an unknown key raises ``ValueError``
        listing the valid ones.
        """
        grid = dict(self.quick_grid if (quick and self.quick_grid is not None) else self.grid)
        seeds = list(self.quick_seeds if (quick and self.quick_seeds is not None) else self.seeds)
        for key, value in (overrides or {}).items():
            if key == "seed":
                seeds = list(value) if isinstance(value, (list, tuple, range)) else [value]
                continue
            if key not in self.grid:
                valid = ", ".join(sorted(self.grid)) + ", seed"
                raise ValueError(f"{self.name}: unknown parameter {key!r}; valid: {valid}")
            grid[key] = list(value) if isinstance(value, (list, tuple)) else [value]
        keys = list(grid)
        out = []
        for combo in itertools.product(*(list(grid[k]) for k in keys)):
            for seed in seeds:
                out.append((dict(zip(keys, combo)), int(seed)))
        return out
