"""benchmarks/bench_vs_published.py: a --gpismap-src that is not a buildable GPisMap2 checkout stops
with one line on stderr that names the problem and the build log, exit code 2, and no traceback.

The script is run as a user runs it (a subprocess), with --build-dir in the test's folder so that
nothing is written to the shared cache. No GPisMap2 code is used: the "checkouts" here are made up.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "bench_vs_published.py"


def _run(src, build):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    p = subprocess.run([sys.executable, str(SCRIPT), "--gpismap-src", str(src), "--build-dir", str(build)],
                       capture_output=True, text=True, timeout=120, env=env, cwd=ROOT)
    return p.returncode, p.stdout, p.stderr


def _fake_checkout(d, cmake_text):
    (d / "gpismap").mkdir(parents=True)
    (d / "CMakeLists.txt").write_text(cmake_text)
    (d / "gpismap" / "runtime_api.h").write_text("/* empty */\n")
    (d / "gpismap" / "runtime_api.cc").write_text("/* empty */\n")
    return d


def _assert_one_line(rc, out, err, build, *needles):
    assert rc == 2, (rc, out, err)
    assert "Traceback" not in err and "Traceback" not in out, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    line = lines[0]
    log = build / "build.log"
    assert line.startswith("bench_vs_published: ") and f"build log: {log}" in line, line
    assert log.is_file()
    for n in needles:
        assert n in line, (n, line)
    return line, log.read_text()


# a missing folder, a folder of something else, and a CMake project that is not GPisMap's: each is
# named as such, with what is missing; the build log says the same and that nothing was built
@pytest.mark.parametrize("case", ["missing", "other_files", "other_project"])
def test_not_a_checkout(tmp_path, case):
    src, build = tmp_path / "src", tmp_path / "build"
    if case == "other_files":
        src.mkdir()
        (src / "README.md").write_text("not GPisMap\n")
    elif case == "other_project":
        _fake_checkout(src, "cmake_minimum_required(VERSION 3.10)\nproject(SomethingElse)\n")
    rc, out, err = _run(src, build)
    if case == "missing":
        needles = [f"{src.resolve()} is not a directory"]
    elif case == "other_files":
        needles = [f"{src.resolve()} is not a GPisMap2 checkout",
                   "missing CMakeLists.txt, gpismap/runtime_api.h, gpismap/runtime_api.cc"]
    else:
        needles = [f"{src.resolve()} is not a GPisMap2 checkout", "missing its CMake project"]
    line, log = _assert_one_line(rc, out, err, build, "--gpismap-src: ", *needles)
    assert needles[0] in log and "Nothing was built." in log, log


# a folder that looks like a checkout but does not build: the failed step is named and the build
# log holds CMake's own output (or, without cmake on the PATH, says so in the one line)
def test_failed_build(tmp_path):
    src, build = tmp_path / "src", tmp_path / "build"
    _fake_checkout(src, "cmake_minimum_required(VERSION 3.10)\nproject(GPisMap2 CXX)\nthis_is_not_cmake(\n")
    rc, out, err = _run(src, build)
    line, log = _assert_one_line(rc, out, err, build, "build failed")
    if "cmake not found" not in line:
        assert "build failed (cmake configure exited " in line or "build failed (cmake build exited " in line, line
        assert log.startswith("$ cmake -S " + str(src.resolve())), log[:200]
        assert "CMakeLists.txt" in log and len(log.splitlines()) > 2, log
