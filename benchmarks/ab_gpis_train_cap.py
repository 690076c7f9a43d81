"""GPISMap2D's ``train_cap`` side by side: update time, memory and scan-to-map drift on the Intel Lab.

    python benchmarks/ab_gpis_train_cap.py none 24 32 48      # caps to compare, in one process

For each cap, on the 910 scans of the real Intel Research Lab log (``load_intel_lab``): the
median and p99 update (thread CPU, ms), the ratio of the last to the first 10 % of scans, the
map's arrays after the run (MB), and the scan-to-map odometry's relation errors (Kümmerle et al.
2009: local and loop mean translation). The log is held out (never used for tuning): the default
cap was chosen on office2d's dev seeds with the factories below, as plug-ins of ``gpis_accuracy``:

    PYTHONPATH=benchmarks polar-sim run gpis_accuracy --split dev --set "scene=[office2d]" \\
        "method=[ab_gpis_train_cap:cap_none,ab_gpis_train_cap:cap24,ab_gpis_train_cap:cap32,ab_gpis_train_cap:cap48]"
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from polar_sim.gpis import GPISMap2D
from polar_sim.gpis.config import LocalGPConfig2D


def _cap(k):
    def make():
        return GPISMap2D(local_gp=LocalGPConfig2D(train_cap=k))
    make.__doc__ = f"GPISMap2D(local_gp=LocalGPConfig2D(train_cap={k}))"
    return make


cap_none, cap16, cap24, cap32, cap48, cap64 = (_cap(k) for k in (None, 16, 24, 32, 48, 64))


def measure(cap, d):
    from polar_sim.runner.gpis_methods import scan_to_map_odometry
    from polar_sim.metrics import relation_scores

    A, P, R = d["angles"], d["poses"], d["ranges"]
    warm = GPISMap2D(local_gp=LocalGPConfig2D(train_cap=cap))             # compile outside the timing
    warm.update(A, R[0], P[0])
    warm.query(P[:1, :2])
    m, cpu = GPISMap2D(local_gp=LocalGPConfig2D(train_cap=cap)), []
    for p, r in zip(P, R):
        t0 = time.thread_time()
        m.update(A, r, p)
        cpu.append(time.thread_time() - t0)
    cpu = 1e3 * np.asarray(cpu)
    k = len(cpu) // 10
    est = scan_to_map_odometry(lambda: GPISMap2D(local_gp=LocalGPConfig2D(train_cap=cap)), A, R, d["odom"], P[0])
    rel = relation_scores({"s2m": est}, d["t_abs"], d["benchmark_relations"])
    return {"median": np.median(cpu), "p99": np.percentile(cpu, 99), "late_early": np.median(cpu[-k:]) / np.median(cpu[:k]),
            "mb": m.nbytes() / 1e6, "local": rel["s2m_local_trans_mean_m"], "loop": rel["s2m_loop_trans_mean_m"],
            "all": rel["s2m_trans_mean_m"]}


def main(argv=None):
    from polar_sim.datasets import load_intel_lab

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("caps", nargs="+", help="caps to compare: integers, or 'none' for no cap")
    args = ap.parse_args(argv)
    caps = [None if c == "none" else int(c) for c in args.caps]
    d = load_intel_lab()
    print(f"load average before: {os.getloadavg()[0]:.2f} (2 cores)\n")
    print("| train_cap | update median / p99 ms | last / first 10 % | map MB | s2m local / loop / all, mean trans m |")
    print("|---|---|---|---|---|")
    for cap in caps:
        r = measure(cap, d)
        print(f"| {cap} | {r['median']:.2f} / {r['p99']:.1f} | {r['late_early']:.2f} | {r['mb']:.1f} | "
              f"{r['local']:.4f} / {r['loop']:.3f} / {r['all']:.3f} |", flush=True)
    print(f"\nload average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
