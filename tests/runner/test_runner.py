"""The experiment runner: sweeps, results as they finish, resume, failures, overrides, checks."""

import json

import numpy as np
import pytest

from polar_sim.runner import Check, Experiment, get_experiment, list_experiments, run_experiment
from polar_sim.runner.results import ResultsFile

CALLS = []


def _trial(params, seed, ctx):
    CALLS.append((params["a"], seed))
    if params["a"] == 99:
        raise RuntimeError("boom")
    (ctx.out_dir / "artefact.txt").write_text("x")
    return {"value": params["a"] * 10 + seed, "quick": ctx.quick}


def _summary(table, out_dir, quick):
    return f"rows: {len(table)}"


def _checks(table, quick):
    return [Check("values positive", all(r["value"] >= 0 for r in table), "")]


TOY = Experiment("toy", "a toy sweep", grid={"a": [1, 2]}, seeds=[0, 1], trial=_trial,
                 summarize=_summary, checks=_checks, quick_grid={"a": [1]}, quick_seeds=[0])


# Every grid point x seed runs once; rows land in results.csv; summary and checks are written.
def test_run_writes_results(tmp_path):
    CALLS.clear()
    res = run_experiment(TOY, out=tmp_path, progress=False)
    assert sorted(CALLS) == [(1, 0), (1, 1), (2, 0), (2, 1)]
    rows = ResultsFile(tmp_path / "results.csv").read()
    assert sorted(r["value"] for r in rows) == [10, 11, 20, 21]
    assert res.passed and (tmp_path / "summary.md").read_text().count("rows: 4") == 1
    assert json.loads((tmp_path / "checks.json").read_text())[0]["passed"] is True
    assert (tmp_path / "trials").is_dir()


# Running again into the same folder resumes: finished trials are not run twice.
def test_resume(tmp_path):
    CALLS.clear()
    run_experiment(TOY, out=tmp_path, quick=True, progress=False)
    assert CALLS == [(1, 0)]
    CALLS.clear()
    res = run_experiment(TOY, out=tmp_path, progress=False)
    assert sorted(CALLS) == [(1, 1), (2, 0), (2, 1)]
    assert len(res.table) == 4


# A failing trial is recorded with its error and fails the run, without stopping the others.
def test_failure_recorded(tmp_path):
    res = run_experiment(TOY, out=tmp_path, overrides={"a": [1, 99]}, progress=False)
    errs = [r for r in res.table if r["status"] == "error"]
    assert len(errs) == 2 and "boom" in errs[0]["error"]
    assert not res.passed and any(c.name == "every trial ran" and not c.passed for c in res.checks)


# Unknown parameters and experiment names raise errors listing the valid ones.
def test_bad_names(tmp_path):
    with pytest.raises(ValueError, match="valid: a, seed"):
        run_experiment(TOY, out=tmp_path, overrides={"b": 1}, progress=False)
    with pytest.raises(ValueError, match="valid: .*sensors"):
        get_experiment("nope")
    with pytest.raises(ValueError, match="backend"):
        run_experiment(TOY, out=tmp_path, backend="slurm", progress=False)


# A process pool (spawn) gives the same rows as running in-process.
def test_process_pool_matches_serial(tmp_path):
    a = run_experiment("sensors", quick=True, out=tmp_path / "a", progress=False,
                       overrides={"scene": ["office2d"], "seed": [0, 1]})
    b = run_experiment("sensors", quick=True, out=tmp_path / "b", workers=2, progress=False,
                       overrides={"scene": ["office2d"], "seed": [0, 1]})
    key = lambda r: r["trial_key"]  # noqa: E731
    for ra, rb in zip(sorted(a.table, key=key), sorted(b.table, key=key)):
        for k, v in ra.items():
            if k != "elapsed_s":
                assert v == rb[k] or (isinstance(v, float) and np.isnan(v) and np.isnan(rb[k]))


# The shipped sensors experiment's quick size passes its exactness checks.
def test_sensors_quick(tmp_path):
    assert "sensors" in list_experiments()
    res = run_experiment("sensors", quick=True, out=tmp_path, progress=False)
    assert res.passed, [(c.name, c.detail) for c in res.checks]
