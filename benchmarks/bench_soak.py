"""Soak at full size (issue 17, item 8): every env for 20,000 steps with resets, a GPIS map over
10,000 scans of a tiled world, 200 world build/render/close cycles, and vector-env workers; each
run in a fresh process; prints the RSS after warm-up, at the end, and the growth (limit 10 %).

    python benchmarks/bench_soak.py                 # full size
    python benchmarks/bench_soak.py --quick         # the CI size (tests/test_soak.py)
    python benchmarks/bench_soak.py --env-steps 5000 --only polar_sim/GPISNav-v0 gpis
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time


def run(expr):
    code = ("import json, time; from polar_sim.testing.soak import *; t0 = time.process_time(); r = " + expr + "; "
            "print(json.dumps({'ok': r.ok, 'growth': r.growth, 'warm_mib': r.warm / 2**20, 'final_mib': r.final / 2**20, "
            "'n': r.n, 'warmup': r.warmup, 'cpu_s': time.process_time() - t0, 'report': r.report()}))")
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if p.returncode != 0:
        return {"ok": False, "report": f"{expr}: failed: {p.stderr.strip().splitlines()[-1][:300]}", "wall_s": 0}
    out = json.loads(p.stdout.strip().splitlines()[-1])
    out["wall_s"] = time.perf_counter() - t0
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--env-steps", type=int, default=None)
    ap.add_argument("--scans", type=int, default=None)
    ap.add_argument("--cycles", type=int, default=None)
    ap.add_argument("--only", nargs="*", help="env ids, 'gpis', 'renderers', 'vector'")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    steps = a.env_steps or (150 if a.quick else 20_000)
    scans = a.scans or (600 if a.quick else 10_000)
    cycles = a.cycles or (12 if a.quick else 200)
    from polar_sim.envs import ENV_IDS

    jobs = [(e, f"soak_env({e!r}, {steps}, warmup={steps // 3}, reset_every={50 if a.quick else 500})") for e in ENV_IDS]
    jobs += [("gpis", f"soak_gpis({scans}, loop=200)"), ("renderers", f"soak_renderers({cycles})")]
    if a.only:
        jobs = [j for j in jobs if j[0] in a.only]
    rows = {}
    for name, expr in jobs:
        r = run(expr)
        rows[name] = r
        extra = f"  [{r['wall_s']:.0f} s wall, {r.get('cpu_s', 0):.0f} s CPU]" if "cpu_s" in r else ""
        print(r["report"] + extra, flush=True)
    if not a.only or "vector" in a.only:
        from polar_sim.testing.soak import vector_workers_closed

        left = [vector_workers_closed("polar_sim/LidarNav-v0", n_envs=2, steps=5) for _ in range(1 if a.quick else 3)]
        ok = all(not x for x in left)
        rows["vector"] = {"ok": ok, "left": [sorted(x) for x in left]}
        print(f"AsyncVectorEnv (2 spawn workers) x {len(left)}: workers left after close: "
              f"{[sorted(x) for x in left]} -> {'ok' if ok else 'LEAK'}", flush=True)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0 if all(r["ok"] for r in rows.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
