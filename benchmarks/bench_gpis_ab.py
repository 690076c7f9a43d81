"""A/B of warm GPIS speed between two checkouts (issue 14 item 5: the cold-start changes must not
slow the warm path). Run once per checkout, alternating, with a shared warm NUMBA_CACHE_DIR:

    for i in 1 2 3; do for r in /work/main /work/wt/coldstart; do
        python benchmarks/bench_gpis_ab.py $r; done; done

Prints JSON: median thread-CPU ms of the 55 updates after 5 (60 room scans, 270 beams) and of 30
queries of 1,000 points within 5 cm of the samples, and sums of the answers (equal sums at full
precision: the same floats).
"""
import json
import sys
import time

import numpy as np

root = sys.argv[1]
sys.path[:0] = [root + "/tests/gpis", root]  # the checkout under test, and its test scenes

import polar_sim  # noqa: E402  (after the path: the checkout's own package)
from polar_sim.gpis import GPISMap2D  # noqa: E402
from scenes import room_path, scan_2d  # noqa: E402

assert polar_sim.__file__.startswith(root), polar_sim.__file__
ang = np.deg2rad(np.arange(-135.0, 135.0, 1.0))
up = []
m = GPISMap2D()
for pose in room_path(60):
    r = scan_2d(pose, ang)
    c = time.thread_time()
    m.update(ang, r, pose)
    up.append(time.thread_time() - c)
rng = np.random.default_rng(0)
s = m.samples()["points"]
P = s[rng.integers(0, len(s), 1000)] + rng.uniform(-0.05, 0.05, (1000, 2))
for _ in range(3):
    m.query(P)
q = []
for _ in range(30):
    c = time.thread_time()
    d = m.query(P)
    q.append(time.thread_time() - c)
print(json.dumps({"root": root, "update_ms": 1e3 * float(np.median(up[5:])), "query_ms": 1e3 * float(np.median(q)),
                  "sdf_sum": float(np.sum(d[0])), "var_sum": float(np.sum(d[2]))}))
