"""Where a ``GPISMap2D.update`` on gazebo1 spends its time, without a profiler's per-call overhead.

    python benchmarks/bench_gpis_stages.py [--scans 600]

cProfile charges a few microseconds to every Python call, which inflates the glue between the
kernels several times over (the stage-A profile put it at about 40 %). Here only the compiled
kernels (called through ``_native.K``) and the update's main steps are wrapped with a timer
(``time.perf_counter``: per-call CPU clocks are too coarse for 10-microsecond calls), 40 calls
a scan. Prints each one's milliseconds per update over scans 50 onwards and its share, and the
kernels' total against the rest (the Python glue). Wall-clock shares: read them on a quiet
machine, or as shares only.
"""

from __future__ import annotations

import argparse
import collections
import os
import time

import numpy as np

KERNELS = ("candidates", "apply_reeval", "reeval_changes", "_new_samples_1d", "apply_new", "dirty_slots",
           "gather_training", "_count_obs", "_train_many", "_mark", "_slot_samples", "_fit",
           "_line_search_1d", "_occupancy_1d", "_fuse_rows")


def _timed(f, label, acc):
    def call(*a, **k):
        c = time.perf_counter()
        try:
            return f(*a, **k)
        finally:
            acc[label] += time.perf_counter() - c
    return call


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=600)
    args = ap.parse_args(argv)
    from polar_sim.datasets import load_gazebo1
    from polar_sim.geometry import compose2d
    from polar_sim.gpis import GPISMap2D, _base, _distance, map2d
    from polar_sim.gpis._native import K

    acc = collections.Counter()
    for name in KERNELS:
        setattr(K, name, _timed(getattr(K, name), "K." + name, acc))
    for cls, name in ((map2d.GPISMap2D, "update"), (_base.GPISMapBase, "_run_update"),
                      (_base.GPISMapBase, "_precheck"), (_base.GPISMapBase, "_retrain_dirty"),
                      (map2d.GPISMap2D, "_prepare"), (map2d.GPISMap2D, "_reeval"),
                      (map2d.GPISMap2D, "_new_samples"), (_distance.FreeSpace, "mark")):
        setattr(cls, name, _timed(getattr(cls, name), f"{cls.__name__}.{name}", acc))
    g = load_gazebo1()
    n = args.scans
    poses = compose2d(g["poses"][:n], np.r_[g["sensor_offset"], 0.0])
    m = GPISMap2D()
    for k in range(n):
        if k == 50:
            acc.clear()
        m.update(g["thetas"], g["ranges"][k], poses[k])
    total = acc["GPISMap2D.update"]
    for label, v in sorted(acc.items(), key=lambda kv: -kv[1]):
        print(f"{label:32s} {1e3 * v / (n - 50):7.3f} ms  {100 * v / total:5.1f} %")
    kern = sum(v for label, v in acc.items() if label.startswith("K."))
    print(f"kernels {1e3 * kern / (n - 50):.3f} ms, the rest (Python) {1e3 * (total - kern) / (n - 50):.3f} ms "
          f"per update; load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
