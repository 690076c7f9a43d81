"""The Ray backend runs the same trials as the local one and gives the same rows."""

import numpy as np
import ray

from polar_sim.runner import run_experiment


# A local Ray instance (what `--backend ray` starts without RAY_ADDRESS) matches a serial run.
def test_ray_backend_matches_local(tmp_path):
    over = {"scene": ["office2d"], "seed": [0, 1]}
    try:
        a = run_experiment("sensors", quick=True, out=tmp_path / "a", progress=False, overrides=over)
        b = run_experiment("sensors", quick=True, out=tmp_path / "b", backend="ray", workers=2,
                           progress=False, overrides=over)
    finally:
        ray.shutdown()
    assert b.passed and len(b.table) == 2
    key = lambda r: r["trial_key"]  # noqa: E731
    for ra, rb in zip(sorted(a.table, key=key), sorted(b.table, key=key)):
        for k, v in ra.items():
            if k != "elapsed_s":
                assert v == rb[k] or (isinstance(v, float) and np.isnan(v) and np.isnan(rb[k]))
