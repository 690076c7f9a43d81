"""How sensitive is the Intel Lab scan-to-map odometry (``intel_lab``'s ``s2m`` relations) to round-off?

``intel_lab`` registers each scan by ICP-G to the map of the scans before it, with no loop closure,
so its error over loops is the end of a 909-step chain. This script runs that chain on the shipped
log as it is, and with every range scaled by (1 + eps) for tiny eps (a change at the level of the
last digits, as another CPU's SIMD paths or another BLAS can make), and prints the benchmark-relation
errors of each. If the loop errors of eps = 1e-12 differ from eps = 0 as much as they do between
machines, the loop figure is a property of the chain's chaos, not of the method.

Usage: python benchmarks/diag_intel_s2m_roundoff.py [--eps 0 1e-12 1e-9]   (default: 0, 1e-12, -1e-12, 1e-9)
"""

from __future__ import annotations

import argparse
import time


from polar_sim.datasets import load_intel_lab
from polar_sim.runner.gpis_methods import call_factory, scan_to_map_odometry
from polar_sim.metrics import relation_scores
from polar_sim.runner.methods import get_method


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--eps", type=float, nargs="+", default=[0.0, 1e-12, -1e-12, 1e-9])
    args = ap.parse_args(argv)
    d = load_intel_lab()
    factory = get_method("mapper2d", "gpis")
    print("| eps | local trans mean (m) | loop trans mean (m) | loop trans max (m) | loop rot mean (deg) | CPU (s) |")
    print("|---|---|---|---|---|---|")
    for eps in args.eps:
        t0 = time.process_time()
        est = scan_to_map_odometry(lambda: call_factory(factory, seed=10_000), d["angles"], d["ranges"] * (1.0 + eps), d["odom"],
                                   d["poses"][0])
        s = relation_scores({"s2m": est}, d["t_abs"], d["benchmark_relations"])
        print(f"| {eps:g} | {s['s2m_local_trans_mean_m']:.4f} | {s['s2m_loop_trans_mean_m']:.3f} | "
              f"{s['s2m_loop_trans_max_m']:.3f} | {s['s2m_loop_rot_mean_deg']:.3f} | {time.process_time() - t0:.1f} |",
              flush=True)


if __name__ == "__main__":
    main()
