"""The declarative experiment format.

An experiment is a module in ``experiments/`` (shipped as ``polar_sim.experiments``) that defines
one module-level ``EXPERIMENT = Experiment(...)``. It declares; the library does the work::

    from polar_sim.runner import Check, Experiment, Finding, get_method

    def trial(params, seed, ctx):
        # params: one point of the grid (a dict); seed: an int of the split;
        # ctx: TrialContext (out_dir for artefacts, size, split, save_arrays)
        loc = get_method("localizer2d", params["method"])()
        ...
        ctx.save_arrays(errors=errs)                  # per-trial arrays for the summary
        return {"pos_median_m": 0.004}                # one row: flat dict of scalars/strings

    def summarize(table, ctx):                        # ctx: RunContext (out_dir, size, split, arrays)
        errs = [ctx.arrays(r)["errors"] for r in table]
        return "markdown body of summary.md"

    def checks(table, ctx):                           # the headline inequalities
        return [Check("ICP-G median <= 5 cm", ok, "0.34 cm")]

    def findings(table, ctx):                         # the dissertation's findings, for reproduce
        return [Finding("Ch. 7, Fig. 7.20", "ICP-G beats the PF", "0.34 vs 1.5 cm", "held")]

    EXPERIMENT = Experiment(
        name="localisation", description="PF vs ICP-D vs ICP-G on office2d",
        grid={"method": ["pf1000", "icpd", "icpg"], "duration_s": [60.0]},
        methods={"method": "localizer2d"},            # axis -> plug-in kind (validated up front)
        splits={"dev": {"seeds": range(20)}, "test": {"seeds": range(10_000, 10_020)}},
        sizes={"quick": {"n_seeds": 1, "grid": {"method": ["icpg"], "duration_s": [20.0]}}, "full": {}},
        trial=trial, summarize=summarize, checks=checks, findings=findings,
    )

**Resolution.** The grid of a run is ``grid``, then the split's ``"grid"`` overrides, then the
size's, then the user's ``overrides`` (``--set``). Its seeds are the split's ``"seeds"``, cut to
the size's first ``"n_seeds"``, unless ``overrides`` has ``"seed"``. Parameters and defaults are
chosen on ``dev``; headline figures come from ``test`` (seeds >= 10,000, held-out families).

Every trial must be deterministic given ``(params, seed)``; the runner may run trials in any
order, in other processes, or on a Ray cluster.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
from pathlib import Path
from typing import Any
from collections.abc import Callable, Mapping

import numpy as np

from polar_sim.fileio import atomic_write
from polar_sim.runner.findings import VERDICTS, Finding
from polar_sim.runner.overrides import conform, declared_kinds

__all__ = ["Experiment", "Check", "Finding", "TrialContext", "RunContext", "VERDICTS", "SIZES"]

SIZES = ("quick", "full")


@dataclasses.dataclass(frozen=True)
class Check:
    """One headline inequality of an experiment: its name, whether it held, and the figures.

    ``known_miss=True`` marks a target recorded as missed in ``benchmarks/RESULTS.md``: a failed
    known miss is reported as *missed*, not as a failure, and fails a run only under ``--strict``.

    ``timing=True`` marks a check on CPU or wall time measured inside the run. A shared machine's
    speed swings 2-3x from hour to hour, so a failed timing check is reported as *slow* with its
    figure, and like a miss fails a run only under ``--strict``; speed targets are judged by the
    benchmarks, measured side by side on quiet cores (``benchmarks/RESULTS.md``).
    """

    name: str
    passed: bool
    detail: str = ""
    known_miss: bool = False
    timing: bool = False

    @property
    def status(self) -> str:
        """``"pass"``, ``"missed"`` (a recorded miss), ``"slow"`` (a timing check not met on this
        run's machine) or ``"FAIL"`` (a regression)."""
        if self.passed:
            return "pass"
        if self.known_miss:
            return "missed"
        return "slow" if self.timing else "FAIL"


def _save_npz_atomic(path: Path, arrays: Mapping[str, Any]):
    clean = {}
    for k, v in arrays.items():
        a = np.asarray(v)
        if a.dtype == object:
            raise TypeError(f"{k}: object arrays cannot be saved (they would need pickle)")
        clean[k] = a
    with atomic_write(path, "name") as fh:
        np.savez_compressed(fh, **clean)
    return path


def _check_array_name(name):
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"name: expected an identifier-like string, got {name!r}")


@dataclasses.dataclass(frozen=True)
class _Context:
    """A folder, the size (``"full"`` or ``"quick"``), the split and the run's protocol parameters
    (``params``: durations, frame counts, resolutions; see :class:`Experiment`)."""

    out_dir: Path
    size: str = "full"
    split: str = "dev"
    params: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def quick(self) -> bool:
        return self.size == "quick"


@dataclasses.dataclass(frozen=True)
class TrialContext(_Context):
    """What a trial gets besides its parameters: its artefact folder (``out_dir``), the size, the
    split and the run's protocol parameters."""

    def save_arrays(self, name: str = "arrays", **arrays) -> Path:
        """Save per-trial arrays to ``<out_dir>/<name>.npz`` (atomically, no pickle), for the
        summary to read back with :meth:`RunContext.arrays`."""
        _check_array_name(name)
        return _save_npz_atomic(Path(self.out_dir) / f"{name}.npz", arrays)


@dataclasses.dataclass(frozen=True)
class RunContext(_Context):
    """What ``summarize``, ``checks`` and ``findings`` get: the run folder (``out_dir``), size,
    split and protocol parameters, and access to each row's saved arrays."""

    def trial_dir(self, row) -> Path:
        """The artefact folder of the trial that produced ``row``."""
        from polar_sim.runner.results import trial_dir

        return trial_dir(self.out_dir, row["trial_key"])

    def arrays(self, row, name: str = "arrays") -> dict:
        """The arrays the trial of ``row`` saved with ``ctx.save_arrays(name, ...)``."""
        _check_array_name(name)
        path = self.trial_dir(row) / f"{name}.npz"
        if not path.is_file():
            raise FileNotFoundError(f"row: trial {row['trial_key']} saved no arrays named {name!r} ({path})")
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}


def _as_list(v):
    return list(v) if isinstance(v, (list, tuple, range)) else [v]


@dataclasses.dataclass(frozen=True)
class Experiment:
    """A declared sweep: the grid, splits, sizes, the trial, the summary, checks and findings.

    Parameters
    ----------
    name : str
        Registry name, the module's file name by convention.
    description : str
        One line for ``polar-sim list``.
    grid : mapping of str to list
        The parameter grid; the trials are its Cartesian product times the seeds.
    trial : callable ``(params, seed, ctx: TrialContext) -> dict``
    splits : mapping of split name to ``{"seeds": iterable of int, "grid": {axis: values}, "params": {...}}``
        ``dev`` (tuning) and ``test`` (held out: seeds >= 10,000, families never tuned on).
    sizes : mapping of size name to ``{"n_seeds": int, "grid": {axis: values}, "params": {...}}``
        ``quick`` (the CI size) and ``full``.
    params : mapping of str to JSON value
        The protocol's fixed settings (drive length, frames, resolution, strides) at the full size;
        a split's or size's ``"params"`` override them, and ``--set KEY=VALUE`` overrides a run's.
        Trials and summaries read them as ``ctx.params``; a run folder records them in
        ``config.json`` and refuses to be resumed with other values. Unlike grid axes they are
        not swept and are not part of a trial's key.
    methods : mapping of axis name to plug-in kind
        Axes whose values are methods (``polar_sim.runner.methods``); checked before any trial.
    choices : mapping of axis name to a list, or to a callable returning one
        The values other axes accept (scenes, routes, sequences); a ``--set`` value outside them
        is refused before any trial, with the valid ones listed. A callable is called only then
        (it may import the simulator).
    summarize : callable ``(table, ctx: RunContext) -> str`` (markdown), optional
    checks : callable ``(table, ctx: RunContext) -> list[Check]``, optional
    findings : callable ``(table, ctx: RunContext) -> list[Finding]``, optional
    default_split : str, optional
        The split a run uses unless told; ``"test"`` when there is one.
    """

    name: str
    description: str
    grid: Mapping[str, list]
    trial: Callable[[dict, int, TrialContext], dict]
    splits: Mapping[str, Mapping] = dataclasses.field(default_factory=lambda: {"dev": {"seeds": [0]}})
    sizes: Mapping[str, Mapping] = dataclasses.field(default_factory=lambda: {"quick": {}, "full": {}})
    methods: Mapping[str, str] = dataclasses.field(default_factory=dict)
    choices: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    summarize: Callable[[list, RunContext], str] | None = None
    checks: Callable[[list, RunContext], list] | None = None
    findings: Callable[[list, RunContext], list] | None = None
    default_split: str | None = None
    params: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        for split, spec in self.splits.items():
            bad = set(spec) - {"seeds", "grid", "params"}
            if bad or "seeds" not in spec:
                raise ValueError(f"{self.name}: split {split!r} must give 'seeds' (and optionally 'grid' and "
                                 f"'params'); got {sorted(spec)}")
        for size, spec in self.sizes.items():
            bad = set(spec) - {"n_seeds", "grid", "params"}
            if bad:
                raise ValueError(f"{self.name}: size {size!r} takes 'n_seeds', 'grid' and 'params', not {sorted(bad)}")
        clash = set(self.params) & (set(self.grid) | {"seed"})
        if clash:
            raise ValueError(f"{self.name}: params {sorted(clash)} are also grid axes (or 'seed')")
        for where, spec in [(f"split {k}", v) for k, v in self.splits.items()] + [(f"size {k}", v) for k, v in self.sizes.items()]:
            unknown = set(spec.get("params", {})) - set(self.params)
            if unknown:
                raise ValueError(f"{self.name}: {where} overrides unknown params {sorted(unknown)}")
        for where, g in [("grid", {"": self.grid})] + [(f"split {k}", {"": v.get("grid", {})}) for k, v in self.splits.items()] \
                + [(f"size {k}", {"": v.get("grid", {})}) for k, v in self.sizes.items()]:
            unknown = set(g[""]) - set(self.grid)
            if unknown:
                raise ValueError(f"{self.name}: {where} overrides unknown axes {sorted(unknown)}")
        for field in ("methods", "choices"):
            unknown = set(getattr(self, field)) - set(self.grid)
            if unknown:
                raise ValueError(f"{self.name}: {field} names axes not in the grid: {sorted(unknown)}")
        if self.default_split is not None and self.default_split not in self.splits:
            raise ValueError(f"{self.name}: default_split {self.default_split!r} is not a split")

    @property
    def split_names(self):
        return list(self.splits)

    def pick_split(self, split=None) -> str:
        """The split to run: ``split`` if given (checked), else the default."""
        if split is None:
            split = self.default_split or ("test" if "test" in self.splits else next(iter(self.splits)))
        if split not in self.splits:
            raise ValueError(f"split: {self.name} has no split {split!r}; valid: {', '.join(self.splits)}")
        return split

    def pick_size(self, size) -> str:
        if size not in self.sizes:
            raise ValueError(f"size: {self.name} has no size {size!r}; valid: {', '.join(self.sizes)}")
        return size

    def resolve(self, size="full", split=None, overrides=None):
        """The grid (dict of axis -> list) and the seeds (list of int) of one run."""
        size, split = self.pick_size(size), self.pick_split(split)
        grid = {k: _as_list(v) for k, v in self.grid.items()}
        for layer in (self.splits[split].get("grid", {}), self.sizes[size].get("grid", {})):
            grid.update({k: _as_list(v) for k, v in layer.items()})
        seeds = [int(s) for s in self.splits[split]["seeds"]]
        n = self.sizes[size].get("n_seeds")
        if n is not None:
            seeds = seeds[: int(n)]
        for key, value in (overrides or {}).items():
            if key == "seed":
                seeds = [_as_seed(s) for s in _as_list(value)]
                if not seeds:
                    raise ValueError(f"seed: {self.name}: --set seed={value!r} gives no seeds to run")
                continue
            if key in self.params:
                continue  # a protocol parameter: resolve_params
            if key not in self.grid:
                valid = ", ".join(sorted(self.grid) + ["seed"] + sorted(self.params))
                raise ValueError(f"{self.name}: unknown parameter {key!r}; valid: {valid}")
            declared = self.declared_values(key)
            grid[key] = [conform(v, declared_kinds(declared), f"{self.name}: axis {key!r}", declared)
                         for v in _as_list(value)]
        for key, values in grid.items():
            if not values:
                raise ValueError(f"{self.name}: axis {key!r} has no values")
            for v in values:
                try:
                    json.dumps(v)
                except TypeError:
                    raise ValueError(f"{self.name}: value {v!r} of axis {key!r} is not JSON-serialisable") from None
        if not seeds:
            raise ValueError(f"{self.name}: no seeds to run (split {split!r}, size {size!r})")
        return grid, seeds

    def resolve_params(self, size="full", split=None, overrides=None) -> dict:
        """The protocol parameters of one run: ``params``, then the split's, the size's, then
        ``overrides`` (``--set``) for the keys that are params."""
        size, split = self.pick_size(size), self.pick_split(split)
        out = dict(self.params)
        out.update(self.splits[split].get("params", {}))
        out.update(self.sizes[size].get("params", {}))
        for key, v in (overrides or {}).items():
            if key in self.params:
                if isinstance(v, list) and len(v) == 1 and not isinstance(self.params[key], list):
                    v = v[0]     # --set KEY=[x] for a scalar param
                declared = self.declared_values(key)
                out[key] = conform(v, declared_kinds(declared), f"{self.name}: param {key!r}", declared)
        for key, v in out.items():
            try:
                json.dumps(v)
            except TypeError:
                raise ValueError(f"{self.name}: value {v!r} of param {key!r} is not JSON-serialisable") from None
        return out

    def declared_values(self, key) -> list:
        """Every value the experiment declares for param or grid axis ``key`` (in ``params`` or
        ``grid``, then in each split and size): what a ``--set`` value's type is checked against."""
        field = "params" if key in self.params else "grid"
        layers = [getattr(self, field)] + [spec.get(field, {}) for spec in (*self.splits.values(), *self.sizes.values())]
        out = []
        for layer in layers:
            if key in layer:
                out += [layer[key]] if field == "params" else _as_list(layer[key])
        return out

    def points(self, size="full", split=None, overrides=None):
        """The list of ``(params, seed)`` trials of one run, in a fixed order."""
        grid, seeds = self.resolve(size, split, overrides)
        keys = list(grid)
        return [(dict(zip(keys, combo)), seed)
                for combo in itertools.product(*(grid[k] for k in keys)) for seed in seeds]

    def seeds_of(self, split) -> list:
        return [int(s) for s in self.splits[self.pick_split(split)]["seeds"]]


def _as_seed(s):
    """A ``--set seed=...`` value: an int >= 0 (not 1.5, "abc", True or a dict)."""
    from polar_sim._validation import as_int

    return as_int(s, "seed", minimum=0)
