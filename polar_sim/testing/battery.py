"""Running hostile inputs: one call's outcome, and whole batteries in a worker subprocess that a
crash or a hang cannot take down."""

from __future__ import annotations

import dataclasses
import json
import os
import select
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

import numpy as np

from polar_sim.testing.digest import state_digest
from polar_sim.testing.entry import EntryPoint, Graceful
from polar_sim.testing.inputs import BadInput, bad_inputs

__all__ = ["EntryPoint", "Counts", "OUTCOMES", "FAILURES", "generate", "run_battery"]

OUTCOMES = ("clear", "graceful", "unclear", "accepted", "state", "crash", "hang")
FAILURES = ("unclear", "accepted", "state", "crash", "hang")


def _fresh_tmp(prefix="polar_battery_"):
    return tempfile.mkdtemp(prefix=prefix)


def generate(ep: EntryPoint, target, tmp, n, seed=0):
    """The first ``n`` hostile inputs of entry point ``ep``, as (BadInput, full args dict) pairs;
    the same ``seed`` gives the same inputs (families cycled over the arguments, then repeated
    with new random positions)."""
    if hasattr(ep, "cases"):          # the CLI: whole command lines
        cases = [BadInput("argv", label, (flag, label, argv), "refuse") for flag, label, argv in ep.cases(tmp)]
        return cases[:n]
    out = []
    rnd = 0
    while len(out) < n:
        rng = np.random.default_rng([seed, rnd])
        pools = []
        for arg, kind in ep.kinds.items():
            valid = ep.args(target, tmp)
            ok = set(ep.graceful.get(arg, ()))
            pool = [dataclasses.replace(b, expect="either") if b.label in ok else b
                    for b in bad_inputs(kind, valid[arg], arg, rng, tmp=tmp)]
            pools.append((arg, pool))
        if ep.extra is not None:
            pools.append(("extra", ep.extra(target, tmp, rng)))
        i = 0
        progressed = True
        while progressed and len(out) < n:
            progressed = False
            for arg, pool in pools:
                if i < len(pool) and len(out) < n:
                    out.append(pool[i])
                    progressed = True
            i += 1
        rnd += 1
    return out[:n]


def _names_ok(ep, bad, exc):
    msg = str(exc)
    names = (bad.arg,) + tuple(ep.names.get(bad.arg, ()))
    return any(nm in msg for nm in names)


class _QuietFds:
    """Point file descriptors 0, 1 and 2 at /dev/null during a hostile call: an integer "path"
    is a file descriptor, and a save to fd 1 would write into (and close) our stdout."""

    def __enter__(self):
        sys.stdout.flush()
        sys.stderr.flush()
        self._saved = [os.dup(fd) for fd in (0, 1, 2)]
        null = os.open(os.devnull, os.O_RDWR)
        for fd in (0, 1, 2):
            os.dup2(null, fd)
        os.close(null)
        return self

    def __exit__(self, *exc):
        for fd, saved in zip((0, 1, 2), self._saved):
            os.dup2(saved, fd)
            os.close(saved)


def _classify(ep, bad, target, tmp):
    """Outcome, detail of one hostile call (in this process), with fds 0-2 at /dev/null."""
    with _QuietFds():
        return _classify_call(ep, bad, target, tmp)


def _classify_call(ep, bad, target, tmp):
    args = ep.args(target, tmp)
    args[bad.arg] = bad.value
    fp = ep.state or (lambda t: state_digest(t, ignore=ep.ignore))
    before = fp(target) if target is not None else None
    try:
        ep.call(target, args)
    except Graceful:
        return "graceful", "a documented graceful outcome"
    except (ValueError, TypeError, FileNotFoundError) as exc:
        if not _names_ok(ep, bad, exc):
            return "unclear", f"{type(exc).__name__} not naming {bad.arg!r}: {str(exc)[:160]}"
        if target is not None and fp(target) != before:
            return "state", f"refused ({type(exc).__name__}) but the state changed"
        return "clear", f"{type(exc).__name__}: {str(exc)[:120]}"
    except SystemExit as exc:             # argparse (CLI entry points handle this themselves)
        return "unclear", f"SystemExit {exc.code}"
    except MemoryError:
        return "unclear", "MemoryError"
    except Exception as exc:  # noqa: BLE001 - every other type is a finding
        tb = traceback.extract_tb(exc.__traceback__)[-1]
        return "unclear", f"{type(exc).__name__} at {Path(tb.filename).name}:{tb.lineno}: {str(exc)[:120]}"
    if bad.expect == "either":
        return "graceful", "accepted"
    return "accepted", "accepted silently"


@dataclasses.dataclass
class Counts:
    """Outcomes of one entry point's battery, and the failing inputs."""

    name: str
    n: int = 0
    counts: dict = dataclasses.field(default_factory=lambda: dict.fromkeys(OUTCOMES, 0))
    failures: list = dataclasses.field(default_factory=list)   # (index, arg, label, outcome, detail)
    seconds: float = 0.0

    def add(self, i, bad, outcome, detail):
        self.n += 1
        self.counts[outcome] += 1
        if outcome in FAILURES:
            self.failures.append((i, bad.arg, bad.label, outcome, detail))

    @property
    def ok(self):
        return all(self.counts[k] == 0 for k in FAILURES)

    def report(self, limit=30):
        c = self.counts
        lines = [f"{self.name}: {self.n} inputs: " + ", ".join(f"{k} {c[k]}" for k in OUTCOMES)]
        for f in self.failures[:limit]:
            lines.append(f"  #{f[0]} {f[1]}={f[2]}: {f[3]}: {f[4]}")
        if len(self.failures) > limit:
            lines.append(f"  ... {len(self.failures) - limit} more")
        return "\n".join(lines)


def _run_inprocess(ep, n, seed, start=0, emit=None):
    tmp = _fresh_tmp()
    target = ep.setup(tmp)
    cases = generate(ep, target, tmp, n, seed)
    res = Counts(ep.name)
    t0 = time.perf_counter()
    for i in range(start, len(cases)):
        bad = cases[i]
        if emit:
            emit(f"B {i}")
        outcome, detail = _classify(ep, bad, target, tmp)
        if emit:
            emit("R " + json.dumps([i, bad.arg, bad.label, outcome, detail]))
        res.add(i, bad, outcome, detail)
        if outcome in ("graceful", "accepted") and not ep.pure:
            _close(target)
            target = ep.setup(tmp)
    _close(target)
    res.seconds = time.perf_counter() - t0
    return res


def _close(target):
    close = getattr(target, "close", None)
    if callable(close):
        try:
            close()
        except Exception:  # noqa: BLE001
            pass


def _entry(name):
    """The :class:`EntryPoint` of a registered or derived name (:data:`ENTRY_POINTS`), or of
    ``"package.module:builder"`` (a user's entry point, importable in the worker process too)."""
    from polar_sim.testing.entries import ENTRY_POINTS

    try:
        builder = ENTRY_POINTS[name]
    except KeyError:
        if ":" in name and not name.startswith("polar_sim/"):
            import importlib

            mod, _, attr = name.partition(":")
            return getattr(importlib.import_module(mod), attr)()
        raise ValueError(f"name: unknown entry point {name!r}; known: {sorted(dict.keys(ENTRY_POINTS))}, "
                         "the module classes' (entry_point_names()) and ID.reset / ID.step of every env id") from None
    return builder()


def run_battery(name, n=200, *, seed=0, isolate=True, timeout=None, setup_timeout=600.0):
    """Run ``n`` hostile inputs against entry point ``name`` (a key of :data:`ENTRY_POINTS`, or
    ``"package.module:builder"`` returning an :class:`EntryPoint`) and return its :class:`Counts`.

    ``isolate=True`` runs the calls in a worker subprocess: a call that kills the interpreter is
    a ``crash``, one that runs past ``timeout`` seconds (default the entry point's) a ``hang``;
    either way a new worker continues from the next input.
    """
    ep = _entry(name)
    if not isolate:
        return _run_inprocess(ep, n, seed)
    timeout = ep.timeout if timeout is None else timeout
    res = Counts(name)
    start = 0
    t0 = time.perf_counter()
    labels = {}
    while start < n:
        cmd = [sys.executable, "-m", "polar_sim.testing", "--worker", name, str(n), str(seed), str(start)]
        env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
                                env=env, bufsize=0)
        reader = _LineReader(proc.stdout.fileno())
        current, limit = None, time.monotonic() + setup_timeout
        try:
            while True:
                line = reader.next(limit)
                if line is None:                                  # over the time limit
                    proc.kill()
                    proc.wait()
                    if current is None:
                        raise RuntimeError(f"{name}: the worker did not answer within {setup_timeout} s")
                    res.add(current, labels.get(current, BadInput("?", "?", None, "refuse")), "hang",
                            f"no answer within {timeout} s")
                    start = current + 1
                    break
                if line == "":                                    # the worker died
                    rc = proc.wait()
                    if current is None:
                        raise RuntimeError(f"{name}: the worker exited with {rc} outside a call")
                    res.add(current, labels.get(current, BadInput("?", "?", None, "refuse")), "crash",
                            f"the interpreter died (exit {rc})")
                    start = current + 1
                    break
                if line.startswith("L "):
                    i, arg, label = json.loads(line[2:])
                    labels[i] = BadInput(arg, label, None, "refuse")
                elif line.startswith("B "):
                    current = int(line[2:])
                    limit = time.monotonic() + timeout
                elif line.startswith("R "):
                    i, arg, label, outcome, detail = json.loads(line[2:])
                    res.add(i, BadInput(arg, label, None, "refuse"), outcome, detail)
                    current, start = None, i + 1
                    limit = time.monotonic() + setup_timeout      # a rebuild of the target may follow
                elif line.startswith("END"):
                    proc.wait()
                    start = n
                    break
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            proc.stdout.close()
    res.seconds = time.perf_counter() - t0
    return res


class _LineReader:
    """Lines from a pipe with a deadline (select on the raw fd: no hidden buffering)."""

    def __init__(self, fd):
        self.fd, self.buf = fd, b""

    def next(self, deadline):
        """The next line; None past ``deadline`` (time.monotonic), "" at end of file."""
        while b"\n" not in self.buf:
            r, _, _ = select.select([self.fd], [], [], max(0.0, deadline - time.monotonic()))
            if not r:
                return None
            chunk = os.read(self.fd, 65536)
            if not chunk:
                return ""
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        return line.decode()


def _worker(name, n, seed, start):
    os.environ.setdefault("MUJOCO_GL", "egl")
    ep = _entry(name)
    proto = os.fdopen(os.dup(1), "w")       # the protocol keeps its own copy of the pipe

    def emit(s):
        proto.write(s + "\n")
        proto.flush()

    tmp = _fresh_tmp()
    target = ep.setup(tmp)
    cases = generate(ep, target, tmp, n, seed)
    for i in range(start, len(cases)):
        emit("L " + json.dumps([i, cases[i].arg, cases[i].label]))
        emit(f"B {i}")
        outcome, detail = _classify(ep, cases[i], target, tmp)
        emit("R " + json.dumps([i, cases[i].arg, cases[i].label, outcome, detail]))
        if outcome in ("graceful", "accepted") and not ep.pure:
            _close(target)
            target = ep.setup(tmp)
    _close(target)
    emit("END")
