"""Running an experiment: trials in this process, on a local pool of worker processes or on Ray
(:mod:`polar_sim.runner.backends`), rows written as they finish, then the summary, the figures, the checks and the findings.

A run folder holds ``config.json`` (what was run, and where: version, commit, packages, machine;
and ``history``, every invocation on the folder with its commit, so a run resumed at another commit
says so),
``results.csv`` (one row per trial, appended as each finishes, so an interrupted run loses nothing
and running again resumes it), ``trials/`` (per-trial artefacts), ``summary.md``, figures,
``checks.json`` and ``findings.json``. One folder holds one (split, size): running another size
or split into it is refused.

A trial that raises, runs past ``trial_timeout`` seconds, or kills its worker process is recorded
as an ``error`` row; the sweep goes on.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import logging
import time
from pathlib import Path

import polar_sim
from polar_sim.fileio import write_text
from polar_sim.progress import progress_bar
from polar_sim.runner.backends import BACKENDS, Running, ray_connect
from polar_sim.runner.experiment import Check, RunContext
from polar_sim.runner.findings import Finding, findings_table, weigh
from polar_sim.runner.registry import get_experiment
from polar_sim.runner.results import ResultsFile, trial_key

__all__ = ["run_experiment", "load_run", "RunResult", "default_out_dir", "run_commits"]

logger = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class RunResult:
    """What a run produced: its folder, the rows, the checks, the findings and the failed trials."""

    out_dir: Path
    table: list
    checks: list
    failures: list
    findings: list = dataclasses.field(default_factory=list)
    config: dict = dataclasses.field(default_factory=dict)

    @property
    def passed(self) -> bool:
        """No failed trial and no failed check other than a recorded miss or a slow timing."""
        return not self.failures and all(c.status != "FAIL" for c in self.checks)

    @property
    def strict_passed(self) -> bool:
        """No failed trial and every check met (recorded misses and slow timings count as failures)."""
        return not self.failures and all(c.passed for c in self.checks)

    @property
    def misses(self) -> list:
        return [c for c in self.checks if c.status == "missed"]


def default_out_dir(name, root="polar_sim_out"):
    """``<root>/runs/<name>/<timestamp>``, and a ``latest`` link beside it."""
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path(root) / "runs" / name / stamp


# -- the run --------------------------------------------------------------------------------------
def _check_axes(exp, grid):
    """Method axes name known methods or importable factories; axes with ``choices`` hold only
    those values. Raises ``ValueError`` listing the valid ones, before any trial runs."""
    from polar_sim.runner.methods import get_method

    for axis, kind in exp.methods.items():
        for value in grid[axis]:
            get_method(kind, value)   # raises ValueError listing the valid names
    for axis, valid in exp.choices.items():
        valid = list(valid() if callable(valid) else valid)
        bad = [v for v in grid[axis] if v not in valid]
        if bad:
            raise ValueError(f"{axis}: {exp.name} has no {axis} {bad[0]!r}; valid: {', '.join(map(str, valid))}")


def read_folder_config(out_dir, config):
    """The run folder's earlier config.json, or ``{}``. Refuses (``ValueError`` naming ``out``) a
    folder that holds another experiment, size, split or params than ``config``'s (rows would
    mix), and a corrupt config.json (left as it is)."""
    path = Path(out_dir) / "config.json"
    if not path.is_file():
        return {}
    try:
        old = json.loads(path.read_text())
    except ValueError:                      # not JSON, or not UTF-8
        old = None
    if not isinstance(old, dict):
        raise ValueError(f"out: {path} is corrupt; choose another --out (it was left as it is)")
    for key in ("experiment", "size", "split", "params"):
        # a folder written before params existed has none to compare, and its trials' keys decide
        if key in old and old[key] != config[key]:
            raise ValueError(f"out: {out_dir} holds a run of {old.get('experiment')!r} with {key} "
                             f"{old[key]!r}, not {config[key]!r}; choose another --out")
    return old


def _history(old):
    """The earlier invocations on a folder: a resumed run's rows may come from other commits,
    so every invocation is kept (commit, start, wall time in s, and the trials it set out to run;
    an interrupted one keeps wall time ``None``). A config.json written
    before the history existed counts as one invocation."""
    if "history" in old:
        return list(old["history"])
    if "provenance" in old:
        pv = old["provenance"]
        return [{"git_commit": pv.get("git_commit"), "started": pv.get("started"),
                 "wall_s": old.get("wall_s"), "trials_todo": None}]
    return []


def run_commits(config):
    """The distinct commits whose invocations ran trials into a run folder, in order
    (``None`` for an unknown commit; an entry with an unknown trial count counts)."""
    seen = []
    for h in config.get("history", []):
        if h.get("trials_todo") != 0 and h.get("git_commit") not in seen:
            seen.append(h.get("git_commit"))
    return seen


def _write_config(out_dir, config):
    write_text(out_dir / "config.json", json.dumps(config, indent=2, default=str), "out")


def run_experiment(name, *, quick=False, size=None, split=None, out=None, workers=1, backend="local",
                   address=None, overrides=None, trial_timeout=None, progress=True, label=None):
    """Run (or resume) an experiment and write its results, summary, figures, checks, findings.

    Parameters
    ----------
    name : str or Experiment
    quick : bool
        Shorthand for ``size="quick"`` (the CI size).
    size : str, optional
        A size the experiment declares (``"quick"``, ``"full"``); default ``"full"``.
    split : str, optional
        ``"dev"`` (tuning) or ``"test"`` (held out); default the experiment's (``test`` if it has one).
    out : path, optional
        Run folder; default ``polar_sim_out/runs/<name>/<timestamp>``. A folder with a
        ``results.csv`` of the same size and split is resumed: finished trials are not run again.
    workers : int
        Parallel trials (local worker processes, or Ray tasks in flight).
    backend : {"local", "ray"}
    address : str, optional
        Ray cluster to join (``"auto"``, ``"HOST:PORT"``); default ``$RAY_ADDRESS`` or a local one.
    overrides : dict, optional
        Replace grid axes or seeds, e.g. ``{"spacing_m": [1.0], "seed": [3]}``; unknown keys raise.
    trial_timeout : float, optional
        Seconds a trial may run before it is stopped and recorded as failed (runs trials in worker
        processes even with one worker).
    progress : bool
        Show a progress bar of the trials on stderr (only on a terminal, and never with
        ``POLAR_SIM_QUIET=1``: :mod:`polar_sim.progress`); with worker processes it shows how long
        the running trials have run.
    label : str, optional
        The bar's label (default: the experiment's name).
    """
    exp = get_experiment(name)
    if backend not in ("local", "ray"):
        raise ValueError(f"backend: unknown backend {backend!r}; expected 'local' or 'ray'")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: expected an integer >= 1, got {workers!r}")
    if trial_timeout is not None and not (isinstance(trial_timeout, (int, float)) and trial_timeout > 0):
        raise ValueError(f"trial_timeout: expected a positive number of seconds, got {trial_timeout!r}")
    size = exp.pick_size(size or ("quick" if quick else "full"))
    split = exp.pick_split(split)
    grid, seeds = exp.resolve(size, split, overrides)
    run_params = exp.resolve_params(size, split, overrides)
    _check_axes(exp, grid)
    points = exp.points(size, split, overrides)
    out_dir = Path(out) if out is not None else default_out_dir(exp.name)
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"out: {out_dir} exists and is not a folder")
    if backend == "ray":
        ray_connect(int(workers), address)   # before the folder is touched: no cluster, one line, in seconds
    out_dir.mkdir(parents=True, exist_ok=True)
    if out is None:
        latest = out_dir.parent / "latest"
        try:
            if latest.is_symlink() or latest.exists():
                latest.unlink()
            latest.symlink_to(out_dir.name)
        except OSError:
            pass
    from polar_sim.runner.provenance import provenance

    t_start = time.time()
    config = {"experiment": exp.name, "description": exp.description, "size": size, "split": split,
              "quick": size == "quick", "overrides": overrides or {}, "n_trials": len(points),
              "grid": grid, "params": run_params, "seeds": seeds, "backend": backend, "workers": int(workers),
              "polar_sim": polar_sim.__version__, "provenance": provenance()}
    results = ResultsFile(out_dir / "results.csv")
    history = _history(read_folder_config(out_dir, config))   # another size, split or params: refused
    done = results.done_keys(size, split)  # reads (and checks) the file before anything is written
    todo = [(p, s) for p, s in points if trial_key(p, s) not in done]
    this_run = {"git_commit": config["provenance"]["git_commit"], "started": config["provenance"]["started"],
                "wall_s": None, "trials_todo": len(todo)}
    config["history"] = history + [this_run]
    _write_config(out_dir, config)
    runner = BACKENDS["ray" if backend == "ray" else "pool" if (workers > 1 or trial_timeout is not None) else "serial"]
    bar = progress_bar(total=len(points), initial=len(points) - len(todo), desc=label or exp.name, unit="trial",
                       enabled=progress)
    try:
        for row in runner(exp, todo, out_dir, size, split, run_params, int(workers), trial_timeout, address):
            if isinstance(row, Running):          # a heartbeat: the bar's clock moves during long trials
                bar.set_postfix_str(row.describe(), refresh=True)
                continue
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
    rctx = RunContext(out_dir, size, split, run_params)
    body = exp.summarize(ok_rows, rctx) if (exp.summarize and ok_rows) else ""
    checks = list(exp.checks(ok_rows, rctx)) if (exp.checks and ok_rows) else []
    findings = list(exp.findings(ok_rows, rctx)) if (exp.findings and ok_rows) else []
    findings = _weighed(exp, findings, config, len(ok_rows))
    if failures:
        checks.append(Check("every trial ran", False, f"{len(failures)} of {len(table)} trials failed; "
                                                      f"first: {failures[0]['error']}"))
    config["wall_s"] = this_run["wall_s"] = round(time.time() - t_start, 1)
    _write_config(out_dir, config)
    _write_summary(out_dir, exp, size, split, seeds, ok_rows, body, checks, findings, run_params)
    return RunResult(out_dir, table, checks, failures, findings, config)


def load_run(out, name=None):
    """The :class:`RunResult` of a finished run folder, read back without running or summarising.

    Reads ``config.json``, ``results.csv``, ``checks.json`` and ``findings.json`` as the run wrote
    them; the per-trial artefacts (``trials/``) are not needed, so a folder can be shared or
    committed without them. ``name`` (optional; a name or an :class:`Experiment`) is the experiment
    the folder must hold, by default the one its ``config.json`` names. A folder
    that is not a finished run (a file missing or corrupt, or trials of its grid still to run)
    raises ``ValueError`` naming the folder and what is missing; it is read only, never changed.
    """
    out_dir = Path(out)
    need = ["config.json", "results.csv", "checks.json", "findings.json"]
    missing = [f for f in need if not (out_dir / f).is_file()]
    if missing:
        raise ValueError(f"out: {out_dir} is not a finished run folder (no {', '.join(missing)})")
    try:
        config = json.loads((out_dir / "config.json").read_text())
        raw_checks = json.loads((out_dir / "checks.json").read_text())
        raw_findings = json.loads((out_dir / "findings.json").read_text())
        checks = [Check(c["name"], bool(c["passed"]), c.get("detail", ""), bool(c.get("known_miss", False)),
                        bool(c.get("timing", False))) for c in raw_checks]
        findings = [Finding(**f) for f in raw_findings]
    except (ValueError, KeyError, TypeError) as exc:  # not JSON, a field missing, or of a wrong type
        raise ValueError(f"out: {out_dir} holds a corrupt config.json, checks.json or findings.json ({exc})") from None
    exp = get_experiment(config.get("experiment") if name is None else name)
    if config.get("experiment") != exp.name:
        raise ValueError(f"out: {out_dir} holds a run of {config.get('experiment')!r}, not {exp.name!r}")
    if "size" not in config or "split" not in config:
        raise ValueError(f"out: {out_dir}'s config.json names no size or split (written by an older polar_sim); "
                         "run the experiment into a new folder")
    points = exp.points(config["size"], config["split"], config.get("overrides") or None)
    keys = {trial_key(p, s) for p, s in points}
    table = [r for r in ResultsFile(out_dir / "results.csv").read() if r.get("trial_key") in keys]
    todo = len(keys - {r["trial_key"] for r in table})
    if todo:
        raise ValueError(f"out: {out_dir} is not finished: {todo} of {len(keys)} trials of its grid have not run "
                         "(run the experiment into it again to resume)")
    # config.json is rewritten without wall_s when an invocation starts, and gets it back only once
    # the summary, checks and findings are written: without it the last invocation was interrupted.
    if config.get("wall_s") is None or not (out_dir / "summary.md").is_file():
        raise ValueError(f"out: {out_dir} was interrupted before its summary was written "
                         "(run the experiment into it again to summarise)")
    failures = [r for r in table if r.get("status") != "ok"]
    findings = _weighed(exp, findings, config, len(table) - len(failures))   # folders written before weighing
    return RunResult(out_dir, table, checks, failures, findings, config)


def _weighed(exp, findings, config, n_ok):
    """The findings with their verdicts weighed against the run's size, seeds and sample
    (:func:`polar_sim.runner.findings.weigh`)."""
    full_seeds = len(exp.resolve("full", config["split"])[1])
    return [weigh(f, size=config["size"], n_trials=n_ok, seeds=len(config.get("seeds") or []) or None,
                  full_seeds=full_seeds) for f in findings]


def _cell(text):
    return str(text).replace("|", "\\|").replace("\n", " ")


def _write_summary(out_dir, exp, size, split, seeds, ok_rows, body, checks, findings, run_params=None):
    seed_txt = f"{seeds[0]}" if len(seeds) == 1 else f"{seeds[0]}..{seeds[-1]} ({len(seeds)})"
    proto = ("Protocol at this size: " + ", ".join(f"`{k}={json.dumps(v)}`" for k, v in run_params.items()) + "."
             if run_params else "")
    lines = [f"# {exp.name}", "", exp.description, "",
             f"{len(ok_rows)} trials, **{split}** split (seeds {seed_txt}), {size} size, polar_sim "
             f"{polar_sim.__version__}.", "", proto, "", body, "", "## Checks", "", "| check | result | figures |", "|---|---|---|"]
    lines += [f"| {_cell(c.name)} | {c.status if c.status != 'FAIL' else '**FAIL**'} | {_cell(c.detail)} |"
              for c in checks]
    if findings:
        lines += ["", "## Findings", ""] + findings_table(findings)
    write_text(out_dir / "summary.md", "\n".join(lines) + "\n", "out")
    write_text(out_dir / "checks.json", json.dumps([dict(dataclasses.asdict(c), status=c.status) for c in checks],
                                                   indent=2, default=str), "out")
    write_text(out_dir / "findings.json", json.dumps([dataclasses.asdict(f) for f in findings], indent=2), "out")
