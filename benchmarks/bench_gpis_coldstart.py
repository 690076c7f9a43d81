"""GPIS cold start and near-surface query time (issue 14, items 5 and 7; issue 35 item 4).

    polar-sim compile                                    # first: the compiled kernels
    python benchmarks/bench_gpis_coldstart.py            # cold with them, cold and warm JIT, query
    python benchmarks/bench_gpis_coldstart.py --no-cold  # query timing only

Cold: a fresh interpreter with NUMBA_CACHE_DIR pointing at a new, empty temporary folder (so
every numba kernel it needs compiles), with the kernels ``polar-sim compile`` built (found in
``POLAR_SIM_NATIVE_DIR`` or the default folder) and without them (``POLAR_SIM_NATIVE=0``, JIT
only), timed from just before the process is started to the end of its first ``GPISMap2D.update`` (one 270-beam scan of the room scene in tests/gpis/scenes.py), then
to the end of its first ``query`` (1,000 points). Warm: the same with the cache that the cold run
filled. Query: a map of 60 room scans; 1,000 points within 5 cm of the map's samples (seeded),
median wall and thread-CPU time of 30 calls after 3 untimed ones. The machine is shared: wall
includes waiting for a CPU, thread CPU does not.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

def first_update_query():
    """The cold-start scenario: one 270-beam scan of the room scene (tests/gpis/scenes.py) into a
    new ``GPISMap2D``, then a query of 1,000 points. Returns the ``perf_counter`` times (s) before
    the update, after it, and after the query (the imports come before the first)."""
    sys.path.insert(0, str(ROOT / "tests" / "gpis"))
    from scenes import room_path, scan_2d

    from polar_sim.gpis import GPISMap2D

    ang = np.deg2rad(np.arange(-135.0, 135.0, 1.0))
    pose = room_path(4)[0]
    r = scan_2d(pose, ang)
    t0 = time.perf_counter()
    m = GPISMap2D().update(ang, r, pose)
    t1 = time.perf_counter()
    m.query(np.random.default_rng(0).uniform(-1, 5, (1000, 2)))
    return t0, t1, time.perf_counter()


# a fresh interpreter: the clock starts before anything is imported
_CHILD = """
import time, sys
t_imp = time.perf_counter()
sys.path.insert(0, sys.argv[1])
from bench_gpis_coldstart import first_update_query
print(t_imp, *first_update_query(), time.time())
"""


def one_start(cache, native=True):
    """One fresh interpreter; ``native``: it may use the kernels ``polar-sim compile`` built
    (``POLAR_SIM_NATIVE_DIR`` or the default folder), else numba's JIT only."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "POLAR_SIM_NATIVE": "1" if native else "0",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    w0 = time.time()
    p = subprocess.run([sys.executable, "-c", _CHILD, str(ROOT / "benchmarks")], capture_output=True,
                       text=True, env=env, check=True)
    t_imp, t0, t1, t2, w_end = (float(x) for x in p.stdout.split())
    # child clocks: perf_counter deltas; process start -> end via wall clock
    total = w_end - w0
    return {"to_first_update_s": round(total - (t2 - t1), 2), "to_first_query_s": round(total, 2),
            "first_update_s": round(t1 - t0, 3), "first_query_s": round(t2 - t1, 3)}


def query_time(n_scans=60, n=1000, reps=30):
    sys.path.insert(0, str(ROOT / "tests" / "gpis"))
    from scenes import room_path, scan_2d

    from polar_sim.gpis import GPISMap2D

    ang = np.deg2rad(np.arange(-135.0, 135.0, 1.0))
    m = GPISMap2D()
    for pose in room_path(n_scans):
        m.update(ang, scan_2d(pose, ang), pose)
    rng = np.random.default_rng(0)
    s = m.samples()["points"]
    P = s[rng.integers(0, len(s), n)] + rng.uniform(-0.05, 0.05, (n, 2))
    for _ in range(3):
        m.query(P)
    wall, cpu = [], []
    for _ in range(reps):
        w, c = time.perf_counter(), time.thread_time()
        m.query(P)
        wall.append(time.perf_counter() - w)
        cpu.append(time.thread_time() - c)
    return {"n_samples": len(s), "median_wall_ms": round(1e3 * float(np.median(wall)), 3),
            "median_cpu_ms": round(1e3 * float(np.median(cpu)), 3), "load": os.getloadavg()[0]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-cold", action="store_true")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    out = {}
    if not args.no_cold:
        with tempfile.TemporaryDirectory() as td:
            out["cold_compiled"] = one_start(Path(td) / "numba1")
            print("cold, compiled kernels (polar-sim compile):", out["cold_compiled"], flush=True)
            out["cold_jit"] = one_start(Path(td) / "numba2", native=False)
            print("cold, JIT only:", out["cold_jit"], flush=True)
            out["warm_jit"] = [one_start(Path(td) / "numba2", native=False) for _ in range(2)]
            print("warm, JIT only (the cache the cold run filled):", out["warm_jit"], flush=True)
    out["query"] = query_time()
    print("query 1000 near-surface points:", out["query"], flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
