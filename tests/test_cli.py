"""Smoke tests of the command line: help, list, errors as one-line messages, render, run."""

import subprocess
import sys

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
    assert {"office2d_front_rgb.png", "office2d_front_depth.png", "office2d_front_labels.png",
            "office2d_overview.png"} <= names


# run --quick executes an experiment and reports its checks.
def test_run_quick(tmp_path):
    assert main(["run", "sensors", "--quick", "--out", str(tmp_path), "--set", "scene=office2d"]) == 0
    assert (tmp_path / "summary.md").is_file() and (tmp_path / "results.csv").is_file()
