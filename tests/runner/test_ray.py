"""The Ray backend runs the same trials as the local pool and writes the same results.csv."""

import csv

import pytest
import ray

from polar_sim.runner import run_experiment

TIMING = {"elapsed_s"}


def _rows(path):
    with open(path, newline="") as fh:
        return {r["trial_key"]: r for r in csv.DictReader(fh)}


# A local Ray instance with 2 CPUs and the local 2-worker pool give results.csv files that are
# equal trial for trial: every metric bit-identical (the CSV holds repr floats), timing excluded.
def test_ray_results_equal_local_pool(tmp_path):
    over = {"scene": ["office2d", "rover_flat"], "seed": [0, 1]}
    try:
        a = run_experiment("sensors", quick=True, split="dev", out=tmp_path / "a", workers=2, progress=False,
                           overrides=over)
        b = run_experiment("sensors", quick=True, split="dev", out=tmp_path / "b", backend="ray", workers=2,
                           progress=False, overrides=over)
    finally:
        ray.shutdown()
    assert a.passed and b.passed and len(b.table) == 4
    ra, rb = _rows(tmp_path / "a" / "results.csv"), _rows(tmp_path / "b" / "results.csv")
    assert ra.keys() == rb.keys()
    for key in ra:
        assert {k: v for k, v in ra[key].items() if k not in TIMING} == \
               {k: v for k, v in rb[key].items() if k not in TIMING}


# An address where no cluster listens is a clear error within seconds, not a hang.
def test_unreachable_address():
    with pytest.raises(ValueError, match="cannot reach the Ray cluster"):
        run_experiment("sensors", quick=True, split="dev", backend="ray", address="127.0.0.1:1", progress=False)
    with pytest.raises(ValueError, match="HOST:PORT"):
        run_experiment("sensors", quick=True, split="dev", backend="ray", address="nonsense", progress=False)
