"""Runner overhead and parallel throughput (issue 16).

1. Per-trial overhead with a null trial (returns at once): the local 2-worker pool, and Ray with
   2 CPUs once warm (a first sweep starts the workers, the timed second sweep reuses them).
   Overhead = wall time of the sweep / trials.
2. Throughput of the local pool on CPU-bound trials (a single-threaded numpy loop of ~1 s of CPU):
   2 workers against 1, measured as pairs in one run (the order alternating), so both see the same
   machine; both sides run in spawn worker processes (the 1-worker side through ``trial_timeout``),
   16 trials a side, so that the workers' start-up (in the figure: it is part of a sweep) is amortised.

    python benchmarks/bench_runner.py [--quick] [--only overhead|throughput]

Needs both cores quiet for part 2 (`/work/tools/cpuslot -2` here); the ratio is only as good as
the second core is free.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from polar_sim.runner import Experiment, run_experiment  # noqa: E402


def null_trial(params, seed, ctx):
    return {"x": float(seed)}


def cpu_trial(params, seed, ctx):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(160, 160))
    t0 = time.process_time()
    acc = 0.0
    while time.process_time() - t0 < params["cpu_s"]:
        acc += float(np.linalg.norm(a @ a))
    return {"acc": acc}


def _sweep(exp, n, **kw):
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        run_experiment(exp, out=Path(d) / "run", overrides={"seed": list(range(n))}, progress=False, **kw)
        return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", choices=["overhead", "throughput"], default=None, help="one part (default both)")
    args = ap.parse_args()
    n_null = 40 if args.quick else 200
    null = Experiment("null", "null trial", grid={"a": [0]}, trial=null_trial, splits={"dev": {"seeds": [0]}})
    cpu = Experiment("cpu", "cpu-bound trial", grid={"cpu_s": [0.5 if args.quick else 1.0]}, trial=cpu_trial,
                     splits={"dev": {"seeds": [0]}})
    print(f"load average at start: {os.getloadavg()[0]:.2f}")
    if args.only != "throughput":
        overhead(null, n_null)
    if args.only != "overhead":
        throughput(cpu, *((4, 1) if args.quick else (16, 3)))


def overhead(null, n_null):
    serial = _sweep(null, n_null)
    pool = _sweep(null, n_null, workers=2)
    print(f"null trial, in-process: {1e3 * serial / n_null:.2f} ms/trial")
    print(f"null trial, local pool of 2 (incl. start-up of 2 spawn workers): {1e3 * pool / n_null:.1f} ms/trial")
    import ray

    try:
        _sweep(null, 8, backend="ray", workers=2)                     # warm-up: starts the Ray workers
        warm = _sweep(null, n_null, backend="ray", workers=2)
        print(f"null trial, Ray with 2 CPUs, warm: {1e3 * warm / n_null:.1f} ms/trial (target <= 50)")
    finally:
        ray.shutdown()


def throughput(cpu, n_cpu, pairs):
    ratios = []
    for k in range(pairs):
        # alternate which runs first, so that a drift in the machine's load does not favour one side
        order = (1, 2) if k % 2 == 0 else (2, 1)
        t = {w: _sweep(cpu, n_cpu, workers=w, trial_timeout=600) for w in order}   # both in worker processes
        one, two = t[1], t[2]
        ratios.append(one / two)
        print(f"pair {k} ({'1 then 2' if order[0] == 1 else '2 then 1'}): {n_cpu} CPU-bound trials, 1 worker {one:.1f} s, "
              f"2 workers {two:.1f} s, throughput ratio {one / two:.2f}; load average {os.getloadavg()[0]:.2f}")
    print(f"2-worker throughput / 1-worker: median {np.median(ratios):.2f} over {pairs} pairs (target >= 1.7); "
          f"load average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
