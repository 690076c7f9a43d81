"""A/B of ``surface()``'s small-object refinement on dev worlds (issue 14): the surface scores
with and without ``polar_sim.gpis._surface._refined``, on the same map, per seed.

    python benchmarks/ab_gpis_surface_refine.py warehouse2d 0 1 2 3 4
    python benchmarks/ab_gpis_surface_refine.py office2d 0 1 2 3 4

Dev seeds only (< 10,000): the refinement was chosen on these; the held-out figure comes from
``polar-sim run gpis_accuracy --split test``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))

import _gpis_common as C  # noqa: E402

from polar_sim.gpis import _surface  # noqa: E402
from polar_sim.metrics.maps import ObservedArea, polyline_points, surface_scores_2d  # noqa: E402
from polar_sim.sim.recorders.drives2d import recorded_drives  # noqa: E402

KEYS = ("hausdorff_wellseen_m", "hausdorff_m", "surface_rmse_m", "p99_true_to_est_m")


def scores(scene, seed):
    d, = recorded_drives(scene, seed, [dict(route_seed=seed, every_steps=1, **C.ROUTE)])
    m = C.make("mapper2d", "gpis", seed=seed)
    C.fuse(m, d.angles, d.poses, d.ranges)
    w = C.truth_world(scene, seed)
    obs = ObservedArea(d.angles, d.poses, d.clean)
    out, refined = {}, _surface._refined
    try:
        for name, fn in (("without", lambda m, lines, res: []), ("with", refined)):
            _surface._refined = fn
            t0 = time.process_time()
            lines = m.surface()
            sc, _ = surface_scores_2d(polyline_points(lines, 0.01), w.sdf, obs, well_k=10)
            out[name] = {**{k: sc[k] for k in KEYS}, "surface_cpu_s": time.process_time() - t0}
    finally:
        _surface._refined = refined
        w.close()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", choices=C.SCENES_2D)
    ap.add_argument("seeds", nargs="+", type=int)
    a = ap.parse_args(argv)
    if any(s >= 10_000 or s < 0 for s in a.seeds):
        ap.error("seeds: dev seeds only (0 <= seed < 10000); the test split is scored by gpis_accuracy")
    rows = {s: scores(a.scene, s) for s in a.seeds}
    for s, r in rows.items():
        print(json.dumps({"seed": s, **r}))
    for name in ("without", "with"):
        print(name, {k: round(float(np.mean([r[name][k] for r in rows.values()])), 4) for k in KEYS})


if __name__ == "__main__":
    main()
