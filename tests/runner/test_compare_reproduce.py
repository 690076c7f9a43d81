"""benchmarks/compare_reproduce.py: two reproduce folders compare equal exactly when every non-timing
cell and every non-timing check status agree; any other difference is printed and exits 1.

The folders are made up here (two experiments, a timing column, a timing check), and the script is
run as a user runs it (a subprocess).
"""

import csv
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "compare_reproduce.py"
COLS = ["method", "seed", "rmse_m", "update_cpu_ms_median", "load", "elapsed_s", "trial_key"]


def _run(a, b):
    p = subprocess.run([sys.executable, str(SCRIPT), str(a), str(b)], capture_output=True, text=True, timeout=60)
    return p.returncode, p.stdout


def _write(root, rows, checks, name="gpis_accuracy"):
    d = root / name
    d.mkdir(parents=True)
    with open(d / "results.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, COLS)
        w.writeheader()
        w.writerows(rows)
    (d / "checks.json").write_text(json.dumps(checks))
    return d


def _rows(rmse="0.0123", cpu="4.5", load="3.2"):
    return [{"method": m, "seed": 0, "rmse_m": rmse if m == "gpis" else "0.02", "update_cpu_ms_median": cpu,
             "load": load, "elapsed_s": "12.0", "trial_key": json.dumps({"params": {"method": m}, "seed": 0})}
            for m in ("gpis", "legacy")]


CHECKS = [{"name": "rmse <= 2 cm", "status": "pass", "timing": False},
          {"name": "update <= 5 ms", "status": "pass", "timing": True}]


# Only timing differs (a timing column, a timing check's status): identical, exit 0.
def test_timing_only_is_identical(tmp_path):
    _write(tmp_path / "a", _rows(), CHECKS)
    _write(tmp_path / "b", _rows(cpu="9.1", load="7.0"), [CHECKS[0], {**CHECKS[1], "status": "missed"}])
    rc, out = _run(tmp_path / "a", tmp_path / "b")
    assert rc == 0, out
    assert "gpis_accuracy: 2 trials, 8/8 cells identical" in out   # 2 trials x 4 non-timing columns


# A figure in the last digit, a check's status, a missing trial or a missing experiment: exit 1, each printed.
def test_differences_are_reported(tmp_path):
    _write(tmp_path / "a", _rows(), CHECKS)
    _write(tmp_path / "a", _rows(), CHECKS, name="sensors")
    _write(tmp_path / "b", _rows(rmse="0.0124")[:1] + _rows()[1:], [{**CHECKS[0], "status": "missed"}, CHECKS[1]])
    rc, out = _run(tmp_path / "a", tmp_path / "b")
    assert rc == 1
    assert "rmse_m: '0.0123' -> '0.0124'" in out and "'rmse <= 2 cm': pass -> missed" in out
    assert "sensors: only in BEFORE" in out
    _write(tmp_path / "c", _rows()[:1], CHECKS)
    rc, out = _run(tmp_path / "a", tmp_path / "c")
    assert rc == 1 and "trial only in BEFORE" in out and '"legacy"' in out
