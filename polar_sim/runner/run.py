"""Running an experiment: trials in this process, on a local pool of worker processes or on Ray,
rows written as they finish, then the summary, the figures, the checks and the findings.

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
import multiprocessing as mp
import multiprocessing.connection as mpc
import os
import time
import traceback
from pathlib import Path

from tqdm.auto import tqdm

import polar_sim
from polar_sim.fileio import write_text
from polar_sim.runner.experiment import Check, RunContext, TrialContext
from polar_sim.runner.registry import get_experiment
from polar_sim.runner.results import RESERVED, ResultsFile, trial_dir, trial_key

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


def _base_row(params, seed, size, split):
    row = dict(params)
    row.update(seed=int(seed), split=split, size=size)
    return row


def _error_row(params, seed, size, split, error, elapsed):
    row = _base_row(params, seed, size, split)
    row.update(status="error", error=error, elapsed_s=round(elapsed, 4), trial_key=trial_key(params, seed))
    return row


def _execute(exp, params, seed, tdir, size, split, run_params=None):
    """Run one trial (in this process or a worker). ``exp`` is an Experiment or a registered
    name (workers re-import registered experiments by name). Returns the result row."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    exp = get_experiment(exp)
    tdir = Path(tdir)
    tdir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    row = _base_row(params, seed, size, split)
    try:
        metrics = exp.trial(dict(params), int(seed), TrialContext(tdir, size, split, dict(run_params or {})))
        if not isinstance(metrics, dict):
            raise TypeError(f"trial returned {type(metrics).__name__}, expected a dict of metrics")
        clash = set(metrics) & (set(params) | RESERVED)
        if clash:
            raise ValueError(f"trial metrics reuse reserved or parameter names: {sorted(clash)}")
        row.update(status="ok", error="")
        row.update(metrics)
    except Exception as exc:  # a failed trial is recorded, not fatal to the sweep
        row.update(status="error", error=f"{type(exc).__name__}: {exc}")
        (tdir / "error.txt").write_text(traceback.format_exc())
    row["elapsed_s"] = round(time.perf_counter() - t0, 4)
    row["trial_key"] = trial_key(params, seed)
    return row


def _portable(exp):
    """What to send to a worker: the registered name if there is one, else the object itself
    (its functions must then be importable module-level functions)."""
    from polar_sim.runner.registry import list_experiments

    return exp.name if exp.name in list_experiments() and get_experiment(exp.name) is exp else exp


# -- backends -------------------------------------------------------------------------------------
def _run_serial(exp, todo, out_dir, size, split, run_params, workers, timeout, address):
    for p, s in todo:
        yield _execute(exp, p, s, str(trial_dir(out_dir, trial_key(p, s))), size, split, run_params)


def _worker_main(conn):
    """A pool worker: runs the trials it is sent, one at a time, until it gets ``None``."""
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg is None:
            return
        conn.send(_execute(*msg))


class _Worker:
    def __init__(self, ctx):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child,), daemon=True)
        self.proc.start()
        child.close()
        self.task = None      # (params, seed, started_at)

    def stop(self, kill=False):
        if kill and self.proc.is_alive():
            self.proc.kill()
        else:
            try:
                self.conn.send(None)
            except (BrokenPipeError, OSError):
                pass
        self.proc.join(timeout=5)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.conn.close()


def _run_pool(exp, todo, out_dir, size, split, run_params, workers, timeout, address):
    # spawn: a forked child of a parent that holds a GL context deadlocks.
    ctx = mp.get_context("spawn")
    portable = _portable(exp)
    queue = list(todo)
    pool = [_Worker(ctx) for _ in range(min(workers, max(len(queue), 1)))]
    try:
        while queue or any(w.task for w in pool):
            for w in pool:
                if w.task is None and queue:
                    p, s = queue.pop(0)
                    w.conn.send((portable, p, s, str(trial_dir(out_dir, trial_key(p, s))), size, split, run_params))
                    w.task = (p, s, time.monotonic())
            busy = [w for w in pool if w.task]
            wait_s = 1.0 if timeout is None else max(0.05, min(w.task[2] + timeout for w in busy) - time.monotonic())
            mpc.wait([w.conn for w in busy] + [w.proc.sentinel for w in busy], timeout=min(wait_s, 5.0))
            for i, w in enumerate(pool):
                if w.task is None:
                    continue
                p, s, t0 = w.task
                row, restart = None, False
                got = w.conn.poll()
                if got:
                    try:
                        row = w.conn.recv()
                    except (EOFError, OSError):   # the worker's end closed: it died
                        w.proc.join(timeout=5)
                        got = False
                if got:
                    pass
                elif not w.proc.is_alive():
                    row, restart = _error_row(p, s, size, split, f"worker process died (exit code {w.proc.exitcode})",
                                              time.monotonic() - t0), True
                elif timeout is not None and time.monotonic() - t0 > timeout:
                    row, restart = _error_row(p, s, size, split, f"timed out after {timeout:g} s (trial_timeout)",
                                              time.monotonic() - t0), True
                if row is None:
                    continue
                w.task = None
                if restart:
                    w.stop(kill=True)
                    pool[i] = _Worker(ctx)
                yield row
    finally:
        for w in pool:
            w.stop(kill=bool(w.task))


def _ray_init(workers, address):
    try:
        import ray
    except ImportError as exc:
        raise ValueError("backend: 'ray' needs the cluster extra: pip install 'polar-sim[cluster]'") from exc
    if ray.is_initialized():
        return ray
    address = address or os.environ.get("RAY_ADDRESS") or None
    _check_reachable(address)
    try:
        # With an address (or RAY_ADDRESS) this joins a running cluster; otherwise a local one starts.
        ray.init(address=address, num_cpus=None if address else workers, log_to_driver=False,
                 include_dashboard=False, ignore_reinit_error=True)
    except (ConnectionError, RuntimeError, ValueError, TimeoutError) as exc:
        raise ValueError(f"address: cannot join the Ray cluster at {address!r}: {type(exc).__name__}: "
                         f"{str(exc).splitlines()[0] if str(exc) else ''}") from None
    return ray


def _check_reachable(address, timeout=5.0):
    """Fail fast on a HOST:PORT nobody listens at (ray.init would retry for minutes)."""
    import socket

    if not address or address == "auto" or "://" in address:
        return
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"address: expected 'auto' or HOST:PORT, got {address!r}")
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as exc:
        raise ValueError(f"address: cannot reach the Ray cluster at {address!r} ({exc.strerror or exc}); "
                         "start it with `ray start --head` or check the address") from None


def _run_ray(exp, todo, out_dir, size, split, run_params, workers, timeout, address):
    ray = _ray_init(workers, address)
    remote = ray.remote(num_cpus=1, max_retries=0)(_execute)
    portable = _portable(exp)
    queue = list(todo)
    in_flight = max(1, int(workers)) if address is None and not os.environ.get("RAY_ADDRESS") else \
        max(1, int(ray.cluster_resources().get("CPU", workers)))
    pending = {}
    try:
        while queue or pending:
            while queue and len(pending) < in_flight:
                p, s = queue.pop(0)
                ref = remote.remote(portable, p, s, str(trial_dir(out_dir, trial_key(p, s))), size, split, run_params)
                pending[ref] = (p, s, time.monotonic())
            done, _ = ray.wait(list(pending), num_returns=1, timeout=1.0 if timeout is not None else None)
            for ref in done:
                p, s, t0 = pending.pop(ref)
                try:
                    yield ray.get(ref)
                except ray.exceptions.RayError as exc:
                    yield _error_row(p, s, size, split, f"worker failed: {type(exc).__name__}: "
                                     f"{str(exc).splitlines()[0] if str(exc) else ''}", time.monotonic() - t0)
            if timeout is not None:
                for ref, (p, s, t0) in list(pending.items()):
                    if time.monotonic() - t0 > timeout:
                        ray.cancel(ref, force=True)
                        pending.pop(ref)
                        yield _error_row(p, s, size, split, f"timed out after {timeout:g} s (trial_timeout)",
                                         time.monotonic() - t0)
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)


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


def _read_config(out_dir, config):
    """The folder's earlier config.json, or ``{}``. Refuses a folder that holds another
    experiment, size or split (rows would mix), and a corrupt config.json (left as it is)."""
    path = out_dir / "config.json"
    if not path.is_file():
        return {}
    try:
        old = json.loads(path.read_text())
    except json.JSONDecodeError:
        raise ValueError(f"out: {path} is corrupt; choose another --out (it was left as it is)") from None
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
                   address=None, overrides=None, trial_timeout=None, progress=True):
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
    """
    exp = get_experiment(name)
    if backend not in ("local", "ray"):
        raise ValueError(f"backend: unknown backend {backend!r}; expected 'local' or 'ray'")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: expected an integer >= 1, got {workers!r}")
    if trial_timeout is not None and not (isinstance(trial_timeout, (int, float)) and trial_timeout > 0):
        raise ValueError(f"trial_timeout: expected a positive number of seconds, got {trial_timeout!r}")
    if backend == "ray":
        _check_reachable(address or os.environ.get("RAY_ADDRESS") or None)
    size = exp.pick_size(size or ("quick" if quick else "full"))
    split = exp.pick_split(split)
    grid, seeds = exp.resolve(size, split, overrides)
    run_params = exp.resolve_params(size, split, overrides)
    _check_axes(exp, grid)
    points = exp.points(size, split, overrides)
    out_dir = Path(out) if out is not None else default_out_dir(exp.name)
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"out: {out_dir} exists and is not a folder")
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
    history = _history(_read_config(out_dir, config))   # another size, split or params: refused
    done = results.done_keys(size, split)  # reads (and checks) the file before anything is written
    todo = [(p, s) for p, s in points if trial_key(p, s) not in done]
    this_run = {"git_commit": config["provenance"]["git_commit"], "started": config["provenance"]["started"],
                "wall_s": None, "trials_todo": len(todo)}
    config["history"] = history + [this_run]
    _write_config(out_dir, config)
    if backend == "ray":
        runner = _run_ray
    else:
        runner = _run_pool if (workers > 1 or trial_timeout is not None) else _run_serial
    bar = tqdm(total=len(points), initial=len(points) - len(todo), desc=exp.name, unit="trial",
               disable=not progress)
    try:
        for row in runner(exp, todo, out_dir, size, split, run_params, int(workers), trial_timeout, address):
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
    from polar_sim.runner.experiment import Finding

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
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
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
    return RunResult(out_dir, table, checks, failures, findings, config)


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
        lines += ["", "## Findings", "", "| source | published | ours | verdict | note |", "|---|---|---|---|---|"]
        lines += [f"| {_cell(f.source)} | {_cell(f.claim)} | {_cell(f.ours)} | {f.verdict} | {_cell(f.note)} |"
                  for f in findings]
    write_text(out_dir / "summary.md", "\n".join(lines) + "\n", "out")
    write_text(out_dir / "checks.json", json.dumps([dict(dataclasses.asdict(c), status=c.status) for c in checks],
                                                   indent=2, default=str), "out")
    write_text(out_dir / "findings.json", json.dumps([dataclasses.asdict(f) for f in findings], indent=2), "out")
