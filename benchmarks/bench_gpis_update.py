"""CPU per ``GPISMap2D.update`` on gazebo1, two or more checkouts side by side (issue 35, item 5).

    python benchmarks/bench_gpis_update.py ROOT [ROOT ...] [--rounds 3] [--scans 600]

Each round runs one child process per checkout (the order rotating each round), which imports
``polar_sim`` from that checkout, fuses the first ``--scans`` gazebo1 scans with the default
``GPISMap2D()`` (sensor poses: the base poses composed with the laser mounting, as
``bench_vs_published.py`` feeds them) and reports the CPU time (``time.process_time``) per update
of scans 50 onwards (the first 50 warm numba's caches and grow the buffers), and the answers:
the samples' and a 1,000-point query's sums at full precision, so that equal code paths show equal
floats and a round-off change shows its size. Prints one JSON line per child and a summary: the
median over rounds of each checkout's ms per update, and each one's ratio to the first ROOT.
Children of one round run one after the other under the same load, so only ratios are read.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

CHILD = r"""
import json, sys, time
import numpy as np
root, n = sys.argv[1], int(sys.argv[2])
sys.path.insert(0, root)
import polar_sim
assert polar_sim.__file__.startswith(root), polar_sim.__file__
from polar_sim.datasets import load_gazebo1
from polar_sim.geometry import compose2d
from polar_sim.gpis import GPISMap2D
g = load_gazebo1()
poses = compose2d(g["poses"][:n], np.r_[g["sensor_offset"], 0.0])
m = GPISMap2D()
cpu = []
for k in range(n):
    c = time.process_time()
    m.update(g["thetas"], g["ranges"][k], poses[k])
    cpu.append(time.process_time() - c)
s = m.samples()
P = s["points"][np.random.default_rng(0).integers(len(s["points"]), size=1000)] + 0.1
d, gr, v = m.query(P)
print(json.dumps({"root": root, "ms_per_update": 1e3 * float(np.sum(cpu[50:])) / (n - 50),
                  "n_samples": int(len(s["points"])), "points_sum": float(s["points"].sum()),
                  "sdf_sum": float(d.sum()), "var_sum": float(v.sum())}))
"""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("roots", nargs="+", help="checkouts (folders holding polar_sim/)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--scans", type=int, default=600)
    args = ap.parse_args(argv)
    roots = [os.path.abspath(r) for r in args.roots]
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    env.pop("PYTHONPATH", None)
    times = {r: [] for r in roots}
    for k in range(args.rounds):
        for j in range(len(roots)):
            r = roots[(j + k) % len(roots)]
            out = subprocess.run([sys.executable, "-c", CHILD, r, str(args.scans)], env=env, check=True,
                                 capture_output=True, text=True).stdout.strip().splitlines()[-1]
            print(out, flush=True)
            times[r].append(json.loads(out)["ms_per_update"])
    base = float(np.median(times[roots[0]]))
    print(f"load average {os.getloadavg()[0]:.1f}")
    for r in roots:
        med = float(np.median(times[r]))
        print(f"{r}: {med:.3f} ms CPU per update (median of {args.rounds}; {', '.join(f'{t:.3f}' for t in times[r])}), "
              f"{base / med:.2f}x of the first")
    return 0


if __name__ == "__main__":
    sys.exit(main())
