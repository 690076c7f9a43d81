"""How the runner executes trials: in this process, on a pool of spawned worker processes, or
as Ray tasks. Every backend takes ``(exp, todo, out_dir, size, split, run_params, workers,
timeout, address)`` and yields each trial's result row as it finishes, and between rows
:class:`Running` heartbeats (the trials still running), so a progress bar moves during long
trials. A trial that raises, runs past ``timeout`` seconds, or kills its worker becomes an
``error`` row; the sweep goes on.

Joining a Ray cluster (:func:`ray_connect`) fails within seconds, in one line, when no cluster
answers at the address (:func:`check_reachable`: nothing listens, or something that is not Ray
does), before ``ray.init`` would retry for 20 s or minutes with a warning a second.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import multiprocessing.connection as mpc
import os
import re
import socket
import sys
import tempfile
import time
import traceback
from pathlib import Path

from polar_sim.progress import QUIET_ENV
from polar_sim.runner.experiment import TrialContext
from polar_sim.runner.registry import get_experiment
from polar_sim.runner.results import RESERVED, trial_dir, trial_key

__all__ = ["BACKENDS", "Running", "execute", "error_row", "ray_connect", "check_reachable", "grpc_status"]


class Running:
    """A heartbeat a backend yields between rows: the start times (``time.monotonic()``) of the
    trials still running."""

    def __init__(self, started):
        self.started = list(started)

    def describe(self) -> str:
        """``"2 running, longest 43 s"`` (empty when nothing runs)."""
        if not self.started:
            return ""
        return f"{len(self.started)} running, longest {time.monotonic() - min(self.started):.0f} s"


def _base_row(params, seed, size, split):
    row = dict(params)
    row.update(seed=int(seed), split=split, size=size)
    return row


def error_row(params, seed, size, split, error, elapsed):
    row = _base_row(params, seed, size, split)
    row.update(status="error", error=error, elapsed_s=round(elapsed, 4), trial_key=trial_key(params, seed))
    return row


def execute(exp, params, seed, tdir, size, split, run_params=None):
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


# -- local backends ------------------------------------------------------------------------------
def run_serial(exp, todo, out_dir, size, split, run_params, workers, timeout, address):
    for p, s in todo:
        yield execute(exp, p, s, str(trial_dir(out_dir, trial_key(p, s))), size, split, run_params)


#: What a pool worker sends when it has a trial in hand and its experiment imported: the trial's
#: clock (``trial_timeout``) starts then, not when the trial was sent to a worker still starting.
_STARTED = "started"
#: Seconds a new worker may take to start (spawn, imports) before its trial is recorded as failed.
STARTUP_S = 300.0


def _deadline(task, timeout):
    """When a pool task (params, seed, sent, started) times out: ``timeout`` after it started, or
    :data:`STARTUP_S` after it was sent while its worker has not started it."""
    _, _, sent, started = task
    return started + timeout if started is not None else sent + STARTUP_S


def _worker_main(conn):
    """A pool worker: runs the trials it is sent, one at a time, until it gets ``None``. Its
    progress bars stay off (several processes drawing on one terminal garble it): the parent's
    bar shows how long the running trials have run."""
    os.environ[QUIET_ENV] = "1"
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg is None:
            return
        get_experiment(msg[0])   # import it first: a new worker's start-up is not the trial's time
        conn.send(_STARTED)
        conn.send(execute(*msg))


class _Worker:
    def __init__(self, ctx):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child,), daemon=True)
        self.proc.start()
        child.close()
        self.task = None      # (params, seed, sent_at, started_at or None until the worker says so)

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


def run_pool(exp, todo, out_dir, size, split, run_params, workers, timeout, address):
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
                    w.task = (p, s, time.monotonic(), None)
            busy = [w for w in pool if w.task]
            wait_s = 1.0 if timeout is None else max(0.05, min(_deadline(w.task, timeout) for w in busy) - time.monotonic())
            mpc.wait([w.conn for w in busy] + [w.proc.sentinel for w in busy], timeout=min(wait_s, 5.0))
            for i, w in enumerate(pool):
                if w.task is None:
                    continue
                p, s, sent, t0 = w.task
                row, restart = None, False
                got = w.conn.poll()
                if got:
                    try:
                        row = w.conn.recv()
                    except (EOFError, OSError):   # the worker's end closed: it died
                        w.proc.join(timeout=5)
                        got = False
                if got and isinstance(row, str) and row == _STARTED:
                    w.task, row = (p, s, sent, time.monotonic()), None
                    continue
                now = time.monotonic()
                if got:
                    pass
                elif not w.proc.is_alive():
                    row, restart = error_row(p, s, size, split, f"worker process died (exit code {w.proc.exitcode})",
                                             now - (t0 or sent)), True
                elif timeout is not None and now > _deadline(w.task, timeout):
                    what = (f"timed out after {timeout:g} s (trial_timeout)" if t0 is not None else
                            f"the worker did not start within {STARTUP_S:g} s")
                    row, restart = error_row(p, s, size, split, what, now - (t0 or sent)), True
                if row is None:
                    continue
                w.task = None
                if restart:
                    w.stop(kill=True)
                    pool[i] = _Worker(ctx)
                yield row
            yield Running([w.task[3] or w.task[2] for w in pool if w.task])
    finally:
        for w in pool:
            w.stop(kill=bool(w.task))


# -- Ray -----------------------------------------------------------------------------------------
#: ``:status`` values of HTTP/2's static header table (RFC 7541, Appendix A), by their one-byte
#: indexed encoding: a server's first response header.
_STATUS = {0x88: 200, 0x89: 204, 0x8A: 206, 0x8B: 304, 0x8C: 400, 0x8D: 404, 0x8E: 500}


def _h2_frame(kind, flags, stream, payload=b""):
    return len(payload).to_bytes(3, "big") + bytes([kind, flags]) + stream.to_bytes(4, "big") + payload


def _hpack_int(value, prefix_bits):
    """An HPACK integer (RFC 7541, 5.1) with a ``prefix_bits``-bit prefix (flag bits left 0)."""
    top = (1 << prefix_bits) - 1
    if value < top:
        return bytes([value])
    out, value = [top], value - top
    while value >= 128:
        out.append((value & 127) | 128)
        value >>= 7
    return bytes(out + [value])


def _h2_literal(index, value):
    """A header field "literal without indexing" whose name is static-table entry ``index``."""
    v = value.encode()
    return _hpack_int(index, 4) + _hpack_int(len(v), 7) + v


def grpc_status(host, port, timeout=3.0):
    """The HTTP ``:status`` a gRPC call to a Ray cluster's control service (GCS) at ``host:port``
    gets: 200 from a gRPC server, another status from an HTTP/2 server that is not one (a proxy),
    ``None`` when no HTTP/2 answer comes within ``timeout`` seconds (something else listens), and
    -1 for a status this probe does not decode. One request over cleartext HTTP/2 (RFC 7540),
    ``GetClusterId`` as ``ray.init`` sends it first."""
    path = "/ray.rpc.NodeInfoGcsService/GetClusterId"
    block = (b"\x83\x86" + _h2_literal(4, path) + _h2_literal(1, f"{host}:{port}")     # POST, http, :path, :authority
             + _h2_literal(31, "application/grpc") + b"\x00\x02te\x08trailers")
    hello = (b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + _h2_frame(4, 0, 0) + _h2_frame(1, 4, 1, block)
             + _h2_frame(0, 1, 1, b"\x00" * 5))                                            # an empty gRPC message
    deadline = time.monotonic() + timeout
    with socket.create_connection((host, port), timeout=timeout) as s:
        s.sendall(hello)
        buf = b""
        while time.monotonic() < deadline:
            s.settimeout(max(0.05, deadline - time.monotonic()))
            try:
                chunk = s.recv(65536)
            except (TimeoutError, OSError):
                return None
            if not chunk:
                return None
            buf += chunk
            while len(buf) >= 9 and len(buf) >= 9 + int.from_bytes(buf[:3], "big"):
                n, kind, flags = int.from_bytes(buf[:3], "big"), buf[3], buf[4]
                stream, payload, buf = int.from_bytes(buf[5:9], "big") & 0x7FFFFFFF, buf[9:9 + n], buf[9 + n:]
                if kind == 1 and stream == 1:          # HEADERS of our request: skip padding, priority
                    start = (1 if flags & 0x8 else 0) + (5 if flags & 0x20 else 0)
                    return _STATUS.get(payload[start] if len(payload) > start else -1, -1)
    return None


def check_reachable(address, timeout=3.0):
    """Fail fast (``ValueError`` naming ``address``) on a ``HOST:PORT`` where no Ray cluster
    answers: nothing listens, or something that is not a Ray cluster's control service does (a web
    server, a proxy), which ``ray.init`` would retry for 20 s or minutes."""
    if not address or address == "auto" or "://" in address:
        return
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"address: expected 'auto' or HOST:PORT, got {address!r}")
    hint = "start it with `ray start --head` or check the address"
    try:
        status = grpc_status(host.strip("[]"), int(port), timeout)
    except OSError as exc:
        raise ValueError(f"address: cannot reach the Ray cluster at {address!r} ({exc.strerror or exc}); {hint}") from None
    if status is None:
        raise ValueError(f"address: what listens at {address!r} does not answer gRPC: not a Ray cluster; {hint}")
    if status != 200:
        raise ValueError(f"address: what listens at {address!r} is not a Ray cluster (an HTTP/2 server answering "
                         f"status {status if status > 0 else 'other than 200'}); {hint}")


@contextlib.contextmanager
def _quiet_stderr(sink):
    """Send file descriptor 2 to ``sink`` (Ray's C++ client writes its retries there, not to
    ``sys.stderr``)."""
    sys.stderr.flush()
    saved = os.dup(2)
    os.dup2(sink.fileno(), 2)
    try:
        yield
    finally:
        sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)


def _last_reason(text):
    """The most telling line of Ray's log output: its last warning or error, without the prefix."""
    lines = [ln for ln in text.splitlines() if re.search(r"\b(W|E|ERROR|WARNING)\b", ln)]
    if not lines:
        return ""
    return re.sub(r"^\[[^\]]*\]\s*\S+:\d+:\s*", "", lines[-1]).strip()[:200]


def ray_connect(workers, address):
    """``ray``, initialised: joined to ``address`` (or ``$RAY_ADDRESS``), or a local instance with
    ``workers`` CPUs. Raises ``ValueError`` naming ``address`` (or ``backend`` without Ray), in
    one line, within seconds when no Ray cluster answers at the address (:func:`check_reachable`);
    Ray's own log lines while joining are kept off the terminal and the last one is quoted."""
    try:
        import ray
    except ImportError as exc:
        raise ValueError("backend: 'ray' needs the cluster extra: pip install 'polar-sim[cluster]'") from exc
    if ray.is_initialized():
        return ray
    address = address or os.environ.get("RAY_ADDRESS") or None
    check_reachable(address)
    if address is None:            # a local instance
        ray.init(num_cpus=workers, log_to_driver=False, include_dashboard=False, ignore_reinit_error=True)
        return ray
    with tempfile.TemporaryFile("w+") as log:
        try:
            with _quiet_stderr(log):
                ray.init(address=address, log_to_driver=False, include_dashboard=False, ignore_reinit_error=True)
        except (ConnectionError, RuntimeError, ValueError, TimeoutError) as exc:
            log.seek(0)
            why = _last_reason(log.read()) or (str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
            raise ValueError(f"address: cannot join the Ray cluster at {address!r} ({why})") from None
    return ray


def run_ray(exp, todo, out_dir, size, split, run_params, workers, timeout, address):
    ray = ray_connect(workers, address)
    remote = ray.remote(num_cpus=1, max_retries=0)(execute)
    portable = _portable(exp)
    queue = list(todo)
    joined = address is not None or bool(os.environ.get("RAY_ADDRESS"))
    in_flight = max(1, int(ray.cluster_resources().get("CPU", workers))) if joined else max(1, int(workers))
    pending = {}
    try:
        while queue or pending:
            while queue and len(pending) < in_flight:
                p, s = queue.pop(0)
                ref = remote.remote(portable, p, s, str(trial_dir(out_dir, trial_key(p, s))), size, split, run_params)
                pending[ref] = (p, s, time.monotonic())
            done, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)
            for ref in done:
                p, s, t0 = pending.pop(ref)
                try:
                    yield ray.get(ref)
                except ray.exceptions.RayError as exc:
                    yield error_row(p, s, size, split, f"worker failed: {type(exc).__name__}: "
                                    f"{str(exc).splitlines()[0] if str(exc) else ''}", time.monotonic() - t0)
            if timeout is not None:
                for ref, (p, s, t0) in list(pending.items()):
                    if time.monotonic() - t0 > timeout:
                        ray.cancel(ref, force=True)
                        pending.pop(ref)
                        yield error_row(p, s, size, split, f"timed out after {timeout:g} s (trial_timeout)",
                                        time.monotonic() - t0)
            if pending:
                yield Running([t0 for _, _, t0 in pending.values()])
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)


#: The backends by name; ``"pool"`` is the local backend with worker processes.
BACKENDS = {"serial": run_serial, "pool": run_pool, "ray": run_ray}
