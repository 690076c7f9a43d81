"""Running an experiment: trials on a local process pool or on Ray, rows written as they finish,
then the summary, the figures and the headline checks.

A run folder holds ``config.json`` (what was run), ``results.csv`` (one row per trial, appended
as each finishes, so an interrupted run loses nothing and ``run`` resumes it), ``trials/``
(per-trial artefacts), ``summary.md``, figures, and ``checks.json``.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import datetime as _dt
import json
import logging
import multiprocessing as mp
import os
import time
import traceback
from pathlib import Path

from tqdm.auto import tqdm

import polar_sim
from polar_sim.runner.experiment import Check, TrialContext
from polar_sim.runner.registry import get_experiment
from polar_sim.runner.results import ResultsFile, trial_key

__all__ = ["run_experiment", "RunResult", "default_out_dir"]

logger = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class RunResult:
    """What a run produced: its folder, the table of rows, the checks and the failed trials."""

    out_dir: Path
    table: list
    checks: list
    failures: list

    @property
    def passed(self):
        return all(c.passed for c in self.checks) and not self.failures


def default_out_dir(name, root="polar_sim_out"):
    """``<root>/runs/<name>/<timestamp>``, and a ``latest`` link beside it."""
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path(root) / "runs" / name / stamp


def _trial_dir(out_dir, params, seed):
    slug = "_".join(f"{k}-{v}" for k, v in params.items()).replace("/", "-").replace(" ", "")
    return out_dir / "trials" / f"{slug}_seed-{seed}"[:180]


def _execute(exp, params, seed, trial_dir, quick):
    """Run one trial (in this process or a worker). ``exp`` is an Experiment or a registered
    name (workers re-import registered experiments by name). Returns the result row."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    exp = get_experiment(exp)
    trial_dir = Path(trial_dir)
    trial_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    row = dict(params)
    row["seed"] = seed
    try:
        metrics = exp.trial(dict(params), seed, TrialContext(trial_dir, quick))
        if not isinstance(metrics, dict):
            raise TypeError(f"trial returned {type(metrics).__name__}, expected a dict of metrics")
        clash = set(metrics) & (set(params) | {"seed", "status", "error", "elapsed_s", "trial_key"})
        if clash:
            raise ValueError(f"trial metrics reuse reserved or parameter names: {sorted(clash)}")
        row.update(status="ok", error="")
        row.update(metrics)
    except Exception as exc:  # a failed trial is recorded, not fatal to the sweep
        row.update(status="error", error=f"{type(exc).__name__}: {exc}")
        (trial_dir / "error.txt").write_text(traceback.format_exc())
    row["elapsed_s"] = round(time.perf_counter() - t0, 4)
    row["trial_key"] = trial_key(params, seed)
    return row


def _portable(exp):
    """What to send to a worker: the registered name if there is one, else the object itself
    (its functions must then be importable module-level functions)."""
    from polar_sim.runner.registry import list_experiments

    return exp.name if exp.name in list_experiments() and get_experiment(exp.name) is exp else exp


def _run_ray(exp, todo, out_dir, quick, workers):
    try:
        import ray
    except ImportError as exc:
        raise ValueError("backend: 'ray' needs the cluster extra: pip install 'polar-sim[cluster]'") from exc
    if not ray.is_initialized():
        # RAY_ADDRESS in the environment joins an existing cluster; otherwise a local one starts.
        ray.init(num_cpus=workers if not os.environ.get("RAY_ADDRESS") else None, log_to_driver=False,
                 include_dashboard=False, ignore_reinit_error=True)
    remote = ray.remote(num_cpus=1)(_execute)
    pending = {remote.remote(_portable(exp), p, s, str(_trial_dir(out_dir, p, s)), quick): (p, s) for p, s in todo}
    while pending:
        done, _ = ray.wait(list(pending), num_returns=1)
        for ref in done:
            pending.pop(ref)
            yield ray.get(ref)


def _run_local(exp, todo, out_dir, quick, workers):
    if workers <= 1:
        for p, s in todo:
            yield _execute(exp, p, s, str(_trial_dir(out_dir, p, s)), quick)
        return
    # spawn: a forked child of a parent that holds a GL context deadlocks.
    ctx = mp.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        futs = [pool.submit(_execute, _portable(exp), p, s, str(_trial_dir(out_dir, p, s)), quick) for p, s in todo]
        for f in cf.as_completed(futs):
            yield f.result()


def run_experiment(name, *, quick=False, out=None, workers=1, backend="local", overrides=None,
                   progress=True):
    """Run (or resume) an experiment and write its results, summary, figures and checks.

    Parameters
    ----------
    name : str or Experiment
    quick : bool
        The CI size (small grid and seeds).
    out : path, optional
        Run folder; default ``polar_sim_out/runs/<name>/<timestamp>``. An existing folder with a
        ``results.csv`` is resumed: finished trials are not run again.
    workers : int
        Parallel trials (local process pool or Ray tasks).
    backend : {"local", "ray"}
    overrides : dict, optional
        Replace grid axes, e.g. ``{"spacing_m": [1.0]}``; unknown keys raise ``ValueError``.
    """
    exp = get_experiment(name)
    if backend not in ("local", "ray"):
        raise ValueError(f"backend: unknown backend {backend!r}; expected 'local' or 'ray'")
    if int(workers) < 1:
        raise ValueError(f"workers: expected an integer >= 1, got {workers}")
    points = exp.points(quick=quick, overrides=overrides)
    out_dir = Path(out) if out is not None else default_out_dir(exp.name)
    out_dir.mkdir(parents=True, exist_ok=True)
    if out is None:
        latest = out_dir.parent / "latest"
        try:
            if latest.is_symlink() or latest.exists():
                latest.unlink()
            latest.symlink_to(out_dir.name)
        except OSError:
            pass
    config = {"experiment": exp.name, "description": exp.description, "quick": bool(quick),
              "overrides": overrides or {}, "n_trials": len(points), "polar_sim": polar_sim.__version__,
              "backend": backend, "workers": int(workers),
              "grid": {k: list(v) for k, v in (exp.quick_grid if quick and exp.quick_grid else exp.grid).items()}}
    (out_dir / "config.json").write_text(json.dumps(config, indent=2, default=str))
    results = ResultsFile(out_dir / "results.csv")
    done = results.done_keys()
    todo = [(p, s) for p, s in points if trial_key(p, s) not in done]
    runner = _run_ray if backend == "ray" else _run_local
    bar = tqdm(total=len(points), initial=len(points) - len(todo), desc=exp.name, unit="trial",
               disable=not progress)
    try:
        for row in runner(exp, todo, out_dir, quick, int(workers)):
            results.append(row)
            bar.update(1)
            if row["status"] != "ok":
                logger.warning("trial %s failed: %s", row["trial_key"], row["error"])
    finally:
        bar.close()
    keys = {trial_key(p, s) for p, s in points}
    table = [r for r in results.read() if r.get("trial_key") in keys]
    ok_rows = [r for r in table if r.get("status") == "ok"]
    failures = [r for r in table if r.get("status") != "ok"]
    body = exp.summarize(ok_rows, out_dir, quick) if (exp.summarize and ok_rows) else ""
    checks = list(exp.checks(ok_rows, quick)) if (exp.checks and ok_rows) else []
    if failures:
        checks.append(Check("every trial ran", False, f"{len(failures)} of {len(table)} trials failed; "
                                                      f"first: {failures[0]['error']}"))
    lines = [f"# {exp.name}", "", exp.description, "",
             f"{len(ok_rows)} trials ({'quick' if quick else 'full'} size), polar_sim {polar_sim.__version__}.", "",
             body, "", "## Checks", "", "| check | result | figures |", "|---|---|---|"]
    lines += [f"| {c.name} | {'pass' if c.passed else '**FAIL**'} | {c.detail} |" for c in checks]
    (out_dir / "summary.md").write_text("\n".join(lines) + "\n")
    (out_dir / "checks.json").write_text(json.dumps([dataclasses.asdict(c) for c in checks], indent=2, default=str))
    return RunResult(out_dir, table, checks, failures)
