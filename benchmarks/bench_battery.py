"""The hostile battery at full size (issue 17): >= 200 generated bad inputs per public entry point,
each call in a worker subprocess with a time limit; prints the outcome counts per entry point.

    python benchmarks/bench_battery.py                 # every entry point, 200 inputs each
    python benchmarks/bench_battery.py --quick         # 20 inputs each
    python benchmarks/bench_battery.py --only World GPISMap2D --n 300 --json out.json

Outcomes (polar_sim.testing): clear = ValueError/TypeError (FileNotFoundError for paths) naming
the argument, state unchanged; graceful = an input documented as acceptable was accepted; unclear
= another exception type or a message that does not name the argument; accepted = a bad input
accepted silently; state = refused but the object changed; crash = the interpreter died; hang =
over the time limit. The CLI's inputs are a fixed list of hostile command lines.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

os.environ.setdefault("MUJOCO_GL", "egl")

from tqdm import tqdm  # noqa: E402

from polar_sim.testing import OUTCOMES, entry_point_names, run_battery  # noqa: E402


def all_entries():
    from polar_sim.envs import ENV_IDS

    names = entry_point_names()     # the hand-written ones and every module class's, derived
    for env_id in ENV_IDS:
        names += [f"{env_id}.reset", f"{env_id}.step"]
    return names


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="bad inputs per entry point (default 200)")
    ap.add_argument("--quick", action="store_true", help="20 inputs per entry point")
    ap.add_argument("--only", nargs="*", help="entry points, or prefixes of them (World, metrics, polar_sim/GPISNav-v0)")
    ap.add_argument("--timeout", type=float, default=None, help="seconds per call before it counts as a hang")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None, help="write the counts and failures here")
    args = ap.parse_args(argv)
    n = 20 if args.quick else args.n
    names = all_entries()
    if args.only:
        names = [e for e in names if any(e == o or e.startswith(o + ".") or e.startswith(o) for o in args.only)]
    rows, t0, cpu0 = {}, time.perf_counter(), time.process_time()
    for name in tqdm(names, desc="entry points", file=sys.stderr):
        try:
            res = run_battery(name, n=n, seed=args.seed, timeout=args.timeout)
        except Exception as exc:  # noqa: BLE001 - an entry point that cannot even be set up is reported
            print(f"{name}: setup failed: {type(exc).__name__}: {exc}", flush=True)
            rows[name] = {"n": 0, "setup_error": f"{type(exc).__name__}: {exc}"}
            continue
        rows[name] = {"n": res.n, **res.counts, "seconds": round(res.seconds, 1),
                      "failures": [list(f) for f in res.failures]}
        print(res.report(limit=8), flush=True)
    head = f"{'entry point':<34}" + "".join(f"{k:>9}" for k in ("n",) + OUTCOMES)
    print("\n" + head)
    tot = dict.fromkeys(("n",) + OUTCOMES, 0)
    for name, r in rows.items():
        if "setup_error" in r:
            print(f"{name:<34}  setup failed")
            continue
        print(f"{name:<34}" + "".join(f"{r[k]:>9}" for k in ("n",) + OUTCOMES))
        for k in tot:
            tot[k] += r[k]
    print(f"{'total':<34}" + "".join(f"{tot[k]:>9}" for k in ("n",) + OUTCOMES))
    if tot["n"]:
        ok = tot["clear"] + tot["graceful"]
        print(f"clear {100 * tot['clear'] / tot['n']:.1f} %, clear or graceful {100 * ok / tot['n']:.1f} % of "
              f"{tot['n']} inputs over {len(rows)} entry points; wall {time.perf_counter() - t0:.0f} s "
              f"(this process {time.process_time() - cpu0:.0f} s CPU; the calls run in workers)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"n_per_entry": n, "seed": args.seed, "rows": rows, "total": tot}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
