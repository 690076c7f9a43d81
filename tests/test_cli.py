"""Smoke tests of the command line: help, list, errors as one-line messages, render, run."""

import subprocess
import sys

import numpy as np
import pytest

from polar_sim.cli import main


def _run(*args):
    return subprocess.run([sys.executable, "-m", "polar_sim.cli", *args], capture_output=True, text=True, timeout=600)


# --help and list work and name the scenes and experiments.
def test_help_and_list():
    r = _run("--help")
    assert r.returncode == 0 and "demo" in r.stdout and "reproduce" in r.stdout
    r = _run("list")
    assert r.returncode == 0, r.stderr
    for name in ("rover_terrain", "office2d", "tabletop", "sensors"):
        assert name in r.stdout


# Errors become exit code 1 with a one-line message naming the valid choices.
def test_errors_one_line(capsys):
    assert main(["run", "nope"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("polar-sim: error:") and "sensors" in err and err.count("\n") == 1
    assert main(["render", "moon_base", "--out", "/tmp/x"]) == 1


# render writes the camera pictures and an overview of a scene.
def test_render(tmp_path):
    assert main(["render", "office2d", "--out", str(tmp_path), "--width", "160", "--height", "120"]) == 0
    names = {p.name for p in tmp_path.glob("*.png")}
    assert {"office2d_front.png", "office2d_overview.png"} == names


# run --quick executes an experiment and reports its checks.
def test_run_quick(tmp_path):
    assert main(["run", "sensors", "--quick", "--out", str(tmp_path), "--set", "scene=office2d"]) == 0
    assert (tmp_path / "summary.md").is_file() and (tmp_path / "results.csv").is_file()


# list names the environment ids too.
def test_list_names_envs(capsys):
    from polar_sim.envs import ENV_IDS

    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "environments" in out and "## Description" not in out
    lines = {ln.split()[0]: ln for ln in out.splitlines() if ln.strip().startswith("polar_sim/")}
    assert set(lines) == set(ENV_IDS)
    assert all(len(ln.split()) > 3 for ln in lines.values())   # each id with a summary


# --set parses bare-word lists, JSON and plain strings, and rejects half-written JSON at once.
def test_set_parsing():
    from polar_sim.cli import _parse_overrides

    got = _parse_overrides(["scene=[office2d, rover_flat]", "spacing_m=[0.5,1.0]", "seed=3", "method=pkg.mod:Loc",
                            "flag=true", "name=plain"])
    assert got == {"scene": ["office2d", "rover_flat"], "spacing_m": [0.5, 1.0], "seed": 3,
                   "method": "pkg.mod:Loc", "flag": True, "name": "plain"}
    with pytest.raises(ValueError, match="--set"):
        _parse_overrides(["x={bad"])
    with pytest.raises(ValueError, match="KEY=VALUE"):
        _parse_overrides(["novalue"])


# The slips a new user makes end in one-line errors, never tracebacks.
@pytest.mark.parametrize("argv, match", [
    (["eval", "polar_sim/Nope-v0", "--policy", "random"], "unknown environment"),
    (["eval", "polar_sim/GPISNav-v1", "--policy", "random", "--episodes", "0"], "--episodes"),
    (["eval", "polar_sim/GPISNav-v1", "--policy", "random", "--env-kwargs", "[1]"], "--env-kwargs"),
    (["eval", "polar_sim/GPISNav-v1", "--policy", "random", "--env-kwargs", "{bad"], "--env-kwargs"),
    (["render", "office2d", "--width", "0"], "--width"),
    (["demo", "--out", "/dev/null/x"], "--out"),
    (["render", "office2d", "--out", "/tmp/" + "x" * 5000], "--out"),
    (["run", "sensors", "--quick", "--split", "train"], "valid: dev"),
    (["run", "sensors", "--quick", "--set", "bogus=1"], "valid:"),
    (["run", "sensors", "--quick", "--workers", "0"], "--workers"),
    (["compare", "/nonexistent/a", "/nonexistent/b"], "run_a"),
    # a value of the wrong type for a declared param is refused before any trial, naming it
    (["run", "localisation", "--quick", "--set", "map_every_steps=2.5"],
     "param 'map_every_steps': expected an integer (declared: 2, 3), got 2.5"),
    (["run", "localisation", "--quick", "--set", "loc_s=[30,60]"], "param 'loc_s': expected a number"),
    (["run", "surface_vs_rate", "--quick", "--set", "spacing_m=[fine]"], "axis 'spacing_m': expected a number"),
    # eval checks the env id before anything else, then asks for --policy
    (["eval", "NoSuchEnv-v0"], "env_id: unknown environment 'NoSuchEnv-v0'"),
    (["eval", "polar_sim/GPISNav-v1"], "--policy: required"),
    # every path option: an OS error is one line naming the option
    (["render", "office2d", "--out", "/proc/self"], "--out: cannot create files in '/proc/self'"),
    (["run", "sensors", "--quick", "--out", "/proc/self"], "--out: cannot create files in '/proc/self'"),
    (["run", "sensors", "--quick", "--out", "/proc/self/new"], "--out: cannot create '/proc/self/new'"),
    (["reproduce", "--quick", "--out", "/dev/null"], "--out: '/dev/null' exists and is not a folder"),
    (["reproduce", "--report-only", "--out", "/dev/null"], "--out: '/dev/null' exists and is not a folder"),
    (["reproduce", "--report-only", "--out", "/nonexistent/reproduce"], "--out: '/nonexistent/reproduce' does not exist"),
    (["eval", "polar_sim/GPISNav-v1", "--policy", "random", "--out", "/dev/null/x"], "--out: cannot create"),
    (["compare", "/proc/self", "/proc/self"], "run_a"),
    (["compare", "/nonexistent/a", "/nonexistent/b", "--out", "/dev/null"], "--out: '/dev/null' exists and is not a folder"),
    (["run", "sensors", "--quick", "--backend", "ray", "--address", "127.0.0.1:1"], "--address: cannot reach"),
])
def test_cli_slips(argv, match, capsys):
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.startswith("polar-sim: error:") and match in err and err.count("\n") == 1, err


# A file where a folder is expected, anywhere up the path, is named with the option.
def test_out_under_a_file(tmp_path, capsys):
    (tmp_path / "f").write_text("x")
    for argv in (["render", "office2d"], ["run", "sensors", "--quick"], ["demo"], ["reproduce", "--quick"]):
        assert main(argv + ["--out", str(tmp_path / "f" / "sub")]) == 1
        err = capsys.readouterr().err
        assert f"--out: cannot create '{tmp_path / 'f' / 'sub'}': '{tmp_path / 'f'}' is a file" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]


# An OS error raised deep in a command (not caught by the checks up front) still names the
# option whose path it concerns, in one line.
def test_os_error_names_the_option(tmp_path, capsys, monkeypatch):
    import polar_sim.runner.compare as compare

    def boom(run_a, run_b, **kw):
        raise PermissionError(13, "Permission denied", str(tmp_path / "b" / "compare" / "compare.md"))

    monkeypatch.setattr(compare, "compare_runs", boom)
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "b" / "compare")]) == 1
    err = capsys.readouterr().err
    assert err == f"polar-sim: error: --out: cannot use '{tmp_path / 'b' / 'compare' / 'compare.md'}': Permission denied\n"
    monkeypatch.setattr(compare, "compare_runs", lambda *a, **k: (_ for _ in ()).throw(
        FileNotFoundError(2, "No such file or directory", str(tmp_path / "a" / "results.csv"))))
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "b")]) == 1
    assert capsys.readouterr().err.startswith("polar-sim: error: run_a: cannot use ")


# eval prints every mean with its unit (success and other true/false metrics as % of episodes).
def test_eval_units():
    from polar_sim.cli import _EVAL_UNITS, _eval_lines

    rows = [{"return": 1.0, "length": 10, "truncated": False, "is_success": True, "pose_error": 0.1, "novel_s": 2.0},
            {"return": 3.0, "length": 30, "truncated": True, "is_success": False, "pose_error": 0.3, "novel_s": 4.0}]
    summary = {"env_id": "x", "episodes": 2, "seed": 0, "mean_return": 2.0, "mean_length": 20.0,
               "mean_truncated": 0.5, "mean_pose_error": 0.2, "mean_novel_s": 3.0, "success_rate": 0.5}
    assert dict(_eval_lines(rows, summary)) == {
        "return": "2 (reward)", "length": "20 steps", "truncated": "50.0 % of episodes", "pose_error": "0.2 m",
        "novel_s": "3 s", "success": "50.0 % of episodes"}
    assert _EVAL_UNITS["heading_error"] == "rad" and _EVAL_UNITS["tracking_error_deg"] == "deg"


# A callable that is not a policy is named once it is called (after the progress bar has started).
def test_eval_names_a_callable_that_is_not_a_policy(capsys):
    assert main(["eval", "polar_sim/GPISNav-v1", "--policy", "os:getcwd", "--episodes", "1"]) == 1
    last = capsys.readouterr().err.replace("\r", "\n").strip().splitlines()[-1]
    assert last.startswith("polar-sim: error: policy: ") and "policy(obs)" in last, last


# compare: two runs of the same toy sweep give per-metric differences with bootstrap intervals.
def test_compare(tmp_path):
    from polar_sim.runner.compare import bootstrap_difference, compare_runs
    from polar_sim.runner.results import ResultsFile, trial_key

    for run, shift in (("a", 0.0), ("b", 1.0)):
        rf = ResultsFile(tmp_path / run / "results.csv")
        for seed in range(8):
            rf.append({"m": "x", "seed": seed, "status": "ok", "trial_key": trial_key({"m": "x"}, seed),
                       "err": seed * 0.1 + shift})
    md = compare_runs(tmp_path / "a", tmp_path / "b", out=tmp_path / "cmp")
    import csv

    with open(tmp_path / "cmp" / "compare.csv") as fh:
        (r,) = [r for r in csv.DictReader(fh) if r["metric"] == "err"]
    r = {k: (float(v) if k.startswith(("diff", "ci95")) else v) for k, v in r.items()}
    assert r["diff_b_minus_a"] == pytest.approx(1.0) and r["paired"] == "True"
    assert r["ci95_low"] == pytest.approx(1.0) and r["ci95_high"] == pytest.approx(1.0)   # constant shift
    assert (tmp_path / "cmp" / "compare.png").is_file() and "err" in md.read_text()
    # an unpaired difference of means with noise covers the true shift
    rng = np.random.default_rng(0)
    d, lo, hi = bootstrap_difference(rng.normal(0, 1, 400), rng.normal(0.5, 1, 300), paired=False)
    assert lo < 0.5 < hi and lo > 0


# reproduce writes report.md and report.html with provenance, the experiments table and each summary.
def test_reproduce_report(tmp_path):
    assert main(["reproduce", "--quick", "--only", "sensors", "--out", str(tmp_path)]) == 0
    md = (tmp_path / "report.md").read_text()
    assert "## Provenance" in md and "## Findings" in md and "| sensors | dev" in md
    html = (tmp_path / "report.html").read_text()
    assert html.count("<table>") >= 2 and "<h2>Provenance</h2>" in html


# The HTML report inlines PNG figures and keeps escaped pipes inside cells.
def test_markdown_to_html_inlines_images(tmp_path):
    import cv2

    from polar_sim.runner.reproduce import markdown_to_html

    cv2.imwrite(str(tmp_path / "fig.png"), np.zeros((4, 4, 3), np.uint8))
    html = markdown_to_html("# T\n\n![fig](fig.png)\n\n| a | b |\n|---|---|\n| x \\| y | 2 |\n", base=tmp_path)
    assert "data:image/png;base64," in html and "<td>x | y</td>" in html


def _toy_experiment():
    from polar_sim.runner import Experiment

    seqs = [f"sequence_{i:02d}_with_a_long_name" for i in range(12)]
    return Experiment(name="toy", description="a toy", grid={"sequence": seqs[:6], "method": ["ww", "h"], "n": [1, 2]},
                      methods={"method": "tracker"}, trial=lambda p, s, c: {},
                      splits={"dev": {"seeds": range(3)}, "test": {"seeds": range(10_000, 10_005), "grid": {"sequence": seqs},
                                                             "params": {"stride": 3}}},
                      sizes={"quick": {"n_seeds": 1, "grid": {"sequence": seqs[:1]}, "params": {"drive_m": 20.0}},
                             "full": {}},
                      params={"drive_m": 60.0, "stride": 2, "label": "a b", "scale": [0.5, 1.0]})


# list shows, under each experiment, its grid axes and protocol params in the syntax --set takes,
# what the quick size and the other split change, and cuts long lists unless asked for one experiment.
def test_describe_experiment_lists_set_keys():
    from polar_sim.cli import _parse_overrides
    from polar_sim.runner.describe import describe_experiment

    exp = _toy_experiment()
    lines = describe_experiment(exp)
    text = "\n".join(lines)
    assert lines[0].startswith("grid:") and "method=[ww, h] (tracker methods)" in text and "n=[1, 2]" in text
    assert "seed 10000..10004 (test split)" in text
    assert "sequence=[sequence_00_with_a_long_name, " in text and "... 12 values]" in text   # cut
    (params,) = [ln for ln in lines if ln.startswith("params:")]
    assert params.split(None, 1)[1] == 'drive_m=60.0; stride=3; label="a b"; scale=[0.5, 1.0]'
    (quick,) = [ln for ln in lines if ln.startswith("quick:")]
    assert quick.split(None, 1)[1] == "drive_m=20.0; sequence=[sequence_00_with_a_long_name]; seed 10000"
    (dev,) = [ln for ln in lines if ln.startswith("dev:")]
    assert "stride=2" in dev and "sequence=[sequence_00" in dev and dev.endswith("seed 0..2")
    # in full, nothing is cut, and every KEY=VALUE shown is --set syntax that gives back the value
    sections = {}
    for ln in describe_experiment(exp, full=True):   # "label:  a; b;" then continuation lines
        if ln[:1] != " ":
            label, ln = ln.split(None, 1)
        sections[label] = sections.get(label, "") + " " + ln.strip()
    assert set(sections) == {"grid:", "params:", "quick:", "dev:"}
    shown = sections["grid:"] + ";" + sections["params:"]
    assert "... 12 values" not in shown and "sequence_11_with_a_long_name" in shown
    items = [it.strip().split(" (")[0] for it in shown.split(";") if "=" in it]
    got = _parse_overrides(items)
    assert got == {"sequence": [f"sequence_{i:02d}_with_a_long_name" for i in range(12)], "method": ["ww", "h"],
                   "n": [1, 2], "drive_m": 60.0, "stride": 3, "label": "a b", "scale": [0.5, 1.0]}
    assert exp.resolve_params("full", "test", got) == {k: got[k] for k in exp.params}


# `polar-sim list` puts a grid line under every experiment; `polar-sim list NAME` shows one in full.
def test_list_shows_grid_under_each_experiment(capsys):
    from polar_sim.runner import list_experiments

    assert main(["list"]) == 0
    out = capsys.readouterr().out.splitlines()
    for name in list_experiments():
        (i,) = [i for i, ln in enumerate(out) if ln.startswith(f"  {name} ")]
        assert out[i + 1].strip().startswith("grid:"), (name, out[i + 1])
    assert any("spacing_m=[0.1, 0.25, 0.5, 1.0]" in ln for ln in out)
    assert main(["list", "surface_vs_rate"]) == 0
    one = capsys.readouterr().out
    assert one.startswith("surface_vs_rate: ") and "grid:" in one and "quick:" in one and "scenes:" not in one
    assert main(["list", "nope"]) == 1 and "valid:" in capsys.readouterr().err
