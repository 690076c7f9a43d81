"""Per-kernel numba compile times in a cold cache (issue 14 item 5: cold start).

    python benchmarks/profile_numba_compile.py gpis            # first GPISMap2D.update + query
    python benchmarks/profile_numba_compile.py demo --out DIR  # a whole `polar-sim demo`

Run it with an empty cache (``NUMBA_CACHE_DIR=$(mktemp -d)``); kernels loaded from a cache are not
compiled and do not appear. For every compiled (kernel, signature): inclusive seconds (with the
kernels it compiled inside, e.g. callees typed on first use), exclusive seconds, and the number of
signatures each kernel ended with. Prints a markdown table sorted by exclusive time.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numba.core.event as ev

ROOT = Path(__file__).resolve().parents[1]


class _Rec(ev.Listener):
    def __init__(self):
        self.stack, self.rows = [], []

    def on_start(self, event):
        d = event.data["dispatcher"]
        self.stack.append([time.perf_counter(), 0.0, d.py_func.__module__, d.py_func.__name__])

    def on_end(self, event):
        t0, inner, _, _ = self.stack.pop()
        owner = next((f"{m.rsplit('.', 1)[-1]}.{f}" for _, _, m, f in reversed(self.stack)
                      if m.startswith("polar_sim")), "")
        dt = time.perf_counter() - t0
        if self.stack:
            self.stack[-1][1] += dt
        d = event.data["dispatcher"]
        name = f"{d.py_func.__module__.rsplit('.', 1)[-1]}.{d.py_func.__name__}"
        self.rows.append((name, tuple(str(a) for a in event.data["args"]), dt, dt - inner,
                          len(self.stack), d, owner))


def _gpis():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_gpis_coldstart import first_update_query

    t0, t1, t2 = first_update_query()
    print(f"first update {t1 - t0:.2f} s, first query {t2 - t1:.2f} s", file=sys.stderr)


def main():
    rec = _Rec()
    ev.register("numba:compile", rec)
    t0, c0 = time.perf_counter(), time.process_time()
    if sys.argv[1] == "gpis":
        _gpis()
    else:
        from polar_sim.cli import main as cli
        try:
            cli(sys.argv[1:])
        except SystemExit:
            pass
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    llvm = 0.0
    for d in {id(r[5]): r[5] for r in rec.rows}.values():
        for cr in d.overloads.values():
            llvm += cr.metadata.get("timers", {}).get("llvm_lock", 0.0) if cr.metadata else 0.0
    print(f"llvm_lock time summed over top-level compile results: {llvm:.1f} s")
    by = {}
    for name, args, inc, exc, depth, d, owner in rec.rows:
        if not d.py_func.__module__.startswith("polar_sim"):
            name = f"(numba library, inside {owner})"
        by.setdefault(name, [0.0, 0.0, 0, d, []])
        by[name][0] += exc
        by[name][1] += inc if depth == 0 else 0.0
        by[name][2] += 1
        by[name][4].append(args)
    tot = sum(v[0] for v in by.values())
    print(f"\n{len(rec.rows)} compilations of {len(by)} kernels; compile {tot:.1f} s exclusive total; "
          f"scenario {wall:.1f} s wall, {cpu:.1f} s CPU\n")
    print("| kernel | signatures compiled | exclusive compile s | top-level inclusive s |")
    print("|---|---|---|---|")
    for name, (exc, inc, n, d, sigs) in sorted(by.items(), key=lambda kv: -kv[1][0]):
        print(f"| {name} | {n} | {exc:.2f} | {inc:.2f} |")
    print("\nmulti-signature kernels:")
    for name, (exc, inc, n, d, sigs) in by.items():
        if n > 1:
            print(name)
            for s in sigs:
                print("   ", s)


if __name__ == "__main__":
    main()
