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


def _summary(table, ctx):
    return f"rows: {len(table)}"


def _checks(table, ctx):
    return [Check("values positive", all(r["value"] >= 0 for r in table), "")]


TOY = Experiment("toy", "a toy sweep", grid={"a": [1, 2]}, trial=_trial,
                 splits={"dev": {"seeds": [0, 1]}},
                 sizes={"quick": {"n_seeds": 1, "grid": {"a": [1]}}, "full": {}},
                 summarize=_summary, checks=_checks)


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
    run_experiment(TOY, out=tmp_path, overrides={"seed": [0]}, progress=False)
    assert sorted(CALLS) == [(1, 0), (2, 0)]
    CALLS.clear()
    res = run_experiment(TOY, out=tmp_path, progress=False)
    assert sorted(CALLS) == [(1, 1), (2, 1)]
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
    a = run_experiment("sensors", quick=True, split="dev", out=tmp_path / "a", progress=False,
                       overrides={"scene": ["office2d"], "seed": [0, 1]})
    b = run_experiment("sensors", quick=True, split="dev", out=tmp_path / "b", workers=2, progress=False,
                       overrides={"scene": ["office2d"], "seed": [0, 1]})
    key = lambda r: r["trial_key"]  # noqa: E731
    for ra, rb in zip(sorted(a.table, key=key), sorted(b.table, key=key)):
        for k, v in ra.items():
            if k != "elapsed_s":
                assert v == rb[k] or (isinstance(v, float) and np.isnan(v) and np.isnan(rb[k]))


# The shipped sensors experiment's quick size passes its exactness checks.
def test_sensors_quick(tmp_path):
    assert "sensors" in list_experiments()
    res = run_experiment("sensors", quick=True, split="dev", out=tmp_path, progress=False)
    assert res.passed, [(c.name, c.detail) for c in res.checks]


def _slow_trial(params, seed, ctx):
    import os
    import time

    if params["a"] == "sleep":
        time.sleep(60)
    if params["a"] == "die":
        os._exit(3)
    ctx.save_arrays(x=np.arange(3) + seed)
    return {"value": float(seed)}


def _arrays_summary(table, ctx):
    return "sums: " + ", ".join(str(int(ctx.arrays(r)["x"].sum())) for r in sorted(table, key=lambda r: r["seed"]))


FAULTY = Experiment("faulty", "trials that hang or kill their worker", grid={"a": ["ok", "sleep", "die"]},
                    trial=_slow_trial, splits={"dev": {"seeds": [0, 1]}}, summarize=_arrays_summary)


# Splits and sizes resolve as declared: split grid, then size grid, then overrides; n_seeds cuts the split.
def test_splits_and_sizes_resolve():
    exp = Experiment("e", "", grid={"m": ["a", "b"], "fam": ["dev1"]}, trial=_trial,
                     splits={"dev": {"seeds": range(5)}, "test": {"seeds": range(10_000, 10_003), "grid": {"fam": ["held"]}}},
                     sizes={"quick": {"n_seeds": 1, "grid": {"m": ["a"]}}, "full": {}})
    assert exp.pick_split() == "test"
    assert exp.resolve("full", "dev") == ({"m": ["a", "b"], "fam": ["dev1"]}, [0, 1, 2, 3, 4])
    assert exp.resolve("quick", "test") == ({"m": ["a"], "fam": ["held"]}, [10_000])
    assert exp.resolve("quick", "test", {"m": "b", "seed": [7, 8]}) == ({"m": ["b"], "fam": ["held"]}, [7, 8])
    with pytest.raises(ValueError, match="valid: dev, test"):
        exp.resolve("full", "train")
    with pytest.raises(ValueError, match="valid: quick, full"):
        exp.resolve("huge", "dev")
    with pytest.raises(ValueError, match="unknown axes"):
        Experiment("e", "", grid={"m": [1]}, trial=_trial, sizes={"quick": {"grid": {"x": [1]}}})


# A trial that hangs past the timeout, or kills its worker, is an error row; the others finish,
# and the summary reads the survivors' arrays through the public API.
def test_timeout_and_dead_worker(tmp_path):
    res = run_experiment(FAULTY, out=tmp_path, workers=2, trial_timeout=5, progress=False)
    by = {(r["a"], r["seed"]): r for r in res.table}
    assert len(by) == 6
    assert by[("ok", 0)]["status"] == by[("ok", 1)]["status"] == "ok"
    assert "timed out after 5 s" in by[("sleep", 0)]["error"]
    assert "exit code 3" in by[("die", 1)]["error"]
    assert "sums: 3, 6" in (tmp_path / "summary.md").read_text()
    assert not res.passed


# The trial's clock starts when a worker has the trial in hand: a worker that takes longer than
# trial_timeout to start (spawn, imports; here a module that sleeps 3 s at import) does not time
# out the quick trial it was sent.
def test_a_slow_worker_start_is_not_the_trials_time(tmp_path, monkeypatch):
    (tmp_path / "slow_import_trial.py").write_text(
        "import time\ntime.sleep(3.0)\n\ndef trial(params, seed, ctx):\n    return {'value': float(seed)}\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import slow_import_trial

    exp = Experiment("slow_start", "", grid={"a": [1]}, trial=slow_import_trial.trial, splits={"dev": {"seeds": [0, 1]}})
    res = run_experiment(exp, out=tmp_path / "run", workers=2, trial_timeout=2, progress=False)
    assert [r["status"] for r in res.table] == ["ok", "ok"], [r["error"] for r in res.table]


# One folder holds one size and split: a full run into a quick run's folder is refused, and a
# corrupt results.csv is reported and left as it was.
def test_folder_guards(tmp_path):
    run_experiment(TOY, out=tmp_path, quick=True, progress=False)
    with pytest.raises(ValueError, match="size 'quick', not 'full'"):
        run_experiment(TOY, out=tmp_path, progress=False)
    bad = tmp_path / "corrupt"
    bad.mkdir()
    (bad / "results.csv").write_text("a,seed,trial_key\n1,2\n")
    before = (bad / "results.csv").read_bytes()
    with pytest.raises(ValueError, match="corrupt"):
        run_experiment(TOY, out=bad, progress=False)
    assert (bad / "results.csv").read_bytes() == before


# Sizes are data: protocol params resolve from the experiment, then the size, then --set; the
# trial and the summary read them (also in a worker process), config.json records them, and a
# folder refuses to resume with other values. A results.csv whose config.json was lost refuses
# rows of another size (a trial's key holds neither, so they would mix).
def _params_trial(params, seed, ctx):
    return {"frames": ctx.params["frames"], "res": ctx.params["res"]}


PARAMS_EXP = Experiment("params_toy", "", grid={"a": [1, 2]}, trial=_params_trial, splits={"dev": {"seeds": [0]}},
                        params={"frames": 300, "res": 0.05}, sizes={"quick": {"params": {"frames": 30}}, "full": {}})


def test_sizes_as_params(tmp_path):
    assert PARAMS_EXP.resolve_params("full") == {"frames": 300, "res": 0.05}
    assert PARAMS_EXP.resolve_params("quick", overrides={"res": [1]}) == {"frames": 30, "res": 1.0}
    with pytest.raises(TypeError, match=r"param 'frames': expected an integer \(declared: 300, 30\), got \"many\""):
        PARAMS_EXP.resolve_params("full", overrides={"frames": "many"})
    with pytest.raises(ValueError, match="unknown parameter 'nope'; valid: a, seed, frames, res"):
        PARAMS_EXP.resolve("full", overrides={"nope": 1})
    with pytest.raises(ValueError, match="overrides unknown params"):
        Experiment("bad", "", grid={"a": [1]}, trial=_params_trial, sizes={"quick": {"params": {"x": 1}}})
    with pytest.raises(ValueError, match="also grid axes"):
        Experiment("bad", "", grid={"a": [1]}, trial=_params_trial, params={"a": 1})
    res = run_experiment(PARAMS_EXP, out=tmp_path / "q", quick=True, workers=2, progress=False)
    assert [r["frames"] for r in res.table] == [30, 30]
    assert json.loads((tmp_path / "q" / "config.json").read_text())["params"] == {"frames": 30, "res": 0.05}
    assert "`frames=30`" in (tmp_path / "q" / "summary.md").read_text()
    with pytest.raises(ValueError, match="with params"):
        run_experiment(PARAMS_EXP, out=tmp_path / "q", quick=True, overrides={"frames": 60}, progress=False)
    (tmp_path / "q" / "config.json").unlink()
    before = (tmp_path / "q" / "results.csv").read_bytes()
    with pytest.raises(ValueError, match="holds rows of size/split quick/dev, not full/dev"):
        run_experiment(PARAMS_EXP, out=tmp_path / "q", progress=False)
    assert (tmp_path / "q" / "results.csv").read_bytes() == before


# A --set value of the wrong type for a declared param or axis is refused before any trial runs,
# naming the param, the type its declared values have and the value (an integer param given 2.5
# used to run int(2.5) while config.json recorded 2.5); an integer where numbers are declared is
# recorded as the number that ran.
@pytest.mark.parametrize("key, value, expected", [
    ("frames", 2.5, "an integer"), ("frames", True, "an integer"), ("frames", [30, 60], "an integer"),
    ("frames", None, "an integer"), ("res", "fine", "a number"), ("res", False, "a number"),
    ("a", [1.5], "an integer"), ("a", ["x"], "an integer"), ("mode", 3, "a string"),
    ("limit", 2.5, "null or an integer"), ("scale", [0.5, "x"], "a number"), ("scale", 0.5, "a list of a number"),
])
def test_set_refuses_wrong_types(tmp_path, key, value, expected):
    exp = Experiment("typed", "", grid={"a": [1, 2], "mode": ["x"]}, trial=_params_trial, splits={"dev": {"seeds": [0]}},
                     params={"frames": 300, "res": 0.05, "limit": None, "scale": [0.5, 1.0]},
                     sizes={"quick": {"params": {"frames": 30, "limit": 5}}, "full": {}})
    with pytest.raises(TypeError, match=f"typed: (param|axis) '{key}'.*: expected {expected}.*got "):
        run_experiment(exp, out=tmp_path / "t", overrides={key: value}, progress=False)
    assert not (tmp_path / "t").exists()
    assert exp.resolve_params("full", overrides={"res": 1, "limit": 7, "scale": [1, 2.5], "frames": [60]}) == \
        {"frames": 60, "res": 1.0, "limit": 7, "scale": [1.0, 2.5]}
    assert exp.resolve("full", overrides={"a": [3], "mode": "y"})[0] == {"a": [3], "mode": ["y"]}


# An axis with declared choices refuses another value before any trial runs (a typo in
# --set scene=[...] used to start a sweep whose every trial failed).
def test_axis_choices(tmp_path):
    exp = Experiment("choice_toy", "", grid={"scene": ["a"]}, trial=_params_trial, splits={"dev": {"seeds": [0]}},
                     choices={"scene": lambda: ["a", "b"]})
    with pytest.raises(ValueError, match="scene: choice_toy has no scene 'moon'; valid: a, b"):
        run_experiment(exp, out=tmp_path / "c", overrides={"scene": ["moon"]}, progress=False)
    assert not (tmp_path / "c").exists()
    with pytest.raises(ValueError, match="choices names axes not in the grid"):
        Experiment("bad", "", grid={"a": [1]}, trial=_params_trial, choices={"scene": ["a"]})


# A run resumed at another commit says so: config.json keeps every invocation, and the report
# names the commits whose invocations ran trials (not one that only re-read finished rows).
def test_resume_keeps_history(tmp_path, monkeypatch):
    import polar_sim.runner.provenance as prov
    from polar_sim.runner.reproduce import write_report
    from polar_sim.runner.run import run_commits

    for commit, seeds in (("a" * 40, [0]), ("b" * 40 + "+dirty", None), ("c" * 40, None)):
        monkeypatch.setattr(prov, "git_commit", lambda c=commit: c)
        res = run_experiment(TOY, out=tmp_path, overrides={"seed": seeds} if seeds else None, progress=False)
    hist = json.loads((tmp_path / "config.json").read_text())["history"]
    assert [h["trials_todo"] for h in hist] == [2, 2, 0]
    assert all(h["wall_s"] is not None for h in hist)
    assert run_commits(res.config) == ["a" * 40, "b" * 40 + "+dirty"]
    report = write_report({"toy": res}, tmp_path).read_text()
    assert "| aaaaaaaaaaaa, bbbbbbbbbbbb+dirty |" in report


# Floats survive the CSV bit for bit, and each row says its split and size.
def test_rows_round_trip_exactly(tmp_path):
    def trial(params, seed, ctx):
        return {"x": 0.1 + 0.2, "tiny": 1e-300 * 3.3}

    exp = Experiment("exact", "", grid={"a": [1]}, trial=trial, splits={"dev": {"seeds": [0]}})
    row = run_experiment(exp, out=tmp_path, progress=False).table[0]
    assert row["x"] == 0.1 + 0.2 and row["tiny"] == 1e-300 * 3.3
    assert row["split"] == "dev" and row["size"] == "full"
    cfg = json.loads((tmp_path / "config.json").read_text())
    assert cfg["provenance"]["python"] and cfg["seeds"] == [0]


# Checks that are recorded misses are "missed", not failures, unless strict.
def test_known_miss_status(tmp_path):
    def checks(table, ctx):
        return [Check("met", True), Check("recorded miss", False, "2.4 cm vs 2 cm", known_miss=True)]

    exp = Experiment("miss", "", grid={"a": [1]}, trial=lambda p, s, c: {"v": 1}, checks=checks,
                     splits={"dev": {"seeds": [0]}})
    res = run_experiment(exp, out=tmp_path, progress=False)
    assert res.passed and not res.strict_passed and [c.status for c in res.checks] == ["pass", "missed"]
    assert "| recorded miss | missed |" in (tmp_path / "summary.md").read_text()


# A finished folder reads back as the run returned it, without its trials/ (so it can be shared
# or committed without them); an unfinished, interrupted or corrupt one is refused and left as is.
def test_load_run(tmp_path):
    import shutil

    from polar_sim.runner.run import load_run

    res = run_experiment(TOY, out=tmp_path, progress=False)
    shutil.rmtree(tmp_path / "trials")
    back = load_run(tmp_path, TOY)
    assert back.table == res.table and back.checks == res.checks and back.findings == res.findings
    assert back.config == json.loads((tmp_path / "config.json").read_text()) and back.passed
    with pytest.raises(ValueError, match="holds a run of 'toy'"):
        load_run(tmp_path, "sensors")

    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    lines = (tmp_path / "results.csv").read_text().splitlines(keepends=True)
    (tmp_path / "results.csv").write_text("".join(lines[:-1]))          # one trial not run
    with pytest.raises(ValueError, match="1 of 4 trials"):
        load_run(tmp_path, TOY)
    (tmp_path / "results.csv").write_bytes(before["results.csv"])
    cfg = json.loads(before["config.json"])
    del cfg["wall_s"]                                                     # an interrupted invocation
    (tmp_path / "config.json").write_text(json.dumps(cfg))
    with pytest.raises(ValueError, match="interrupted"):
        load_run(tmp_path, TOY)
    del cfg["size"]                                                       # an older folder's config
    (tmp_path / "config.json").write_text(json.dumps({**cfg, "wall_s": 1.0}))
    with pytest.raises(ValueError, match="no size or split"):
        load_run(tmp_path, TOY)
    (tmp_path / "config.json").write_bytes(before["config.json"])
    (tmp_path / "checks.json").write_text("[{")
    with pytest.raises(ValueError, match="corrupt"):
        load_run(tmp_path, TOY)
    (tmp_path / "checks.json").write_bytes(before["checks.json"])
    (tmp_path / "findings.json").unlink()
    with pytest.raises(ValueError, match="no findings.json"):
        load_run(tmp_path, TOY)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(set(before) - {"findings.json"})


# A check's status: met, a recorded miss, a slow timing, or a failure. Only a failure (or a failed
# trial) fails a run by default; --strict fails it on a miss or a slow timing too.
def test_check_status_and_exit_code(tmp_path):
    from polar_sim.cli import _exit_code
    from polar_sim.runner.run import RunResult

    assert Check("a", True, timing=True, known_miss=True).status == "pass"
    assert Check("b", False, known_miss=True, timing=True).status == "missed"
    assert Check("c", False, timing=True).status == "slow"
    assert Check("d", False).status == "FAIL"
    run = lambda *checks: RunResult(tmp_path, [{}], list(checks), [])  # noqa: E731
    assert _exit_code([run(Check("c", False, timing=True), Check("b", False, known_miss=True))], strict=False) == 0
    assert _exit_code([run(Check("c", False, timing=True))], strict=True) == 2
    assert _exit_code([run(Check("c", True, timing=True), Check("d", False))], strict=False) == 2
    assert _exit_code([RunResult(tmp_path, [{}], [Check("a", True)], [{"error": "x"}])], strict=False) == 2
