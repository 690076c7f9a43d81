"""``polar-sim reproduce --quick`` covers the Intel Lab and warehouse2d GPIS experiments (issue 14):
they run at their quick size inside reproduce, their findings rows reach the report's findings
table, and their recorded misses show as *missed* (exit code 0), failing only under ``--strict``.
"""

import json
import re

import pytest

from polar_sim.cli import main
from polar_sim.runner.reproduce import reproduce

GPIS = ["intel_lab", "gpis_accuracy", "surface_vs_rate"]

#: findings each experiment must state in the report (the start of the "source" cell)
FINDINGS = {"intel_lab": ["Ch. 7, Fig. 7.12a (Intel Lab)", "Ch. 7, Fig. 7.19 (Intel Lab)"],
            "surface_vs_rate": ["Ch. 7, surface accuracy against data rate", "Ch. 7, where the worst errors lie"]}


def _table(md, header):
    """Rows (lists of cells) of the Markdown table whose header line starts with ``header``."""
    lines = md.splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith(header))
    rows = []
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))])
    return rows


@pytest.mark.slow
def test_reproduce_quick_gpis_worlds(tmp_path):
    results, report = reproduce(tmp_path, quick=True, only=GPIS, progress=False)
    assert list(results) == GPIS
    md = report.read_text()
    assert md.splitlines()[2].startswith("**Size: quick** (the CI size")
    for name, r in results.items():
        assert r.config["size"] == "quick" and r.table and not r.failures, (name, r.failures)
        assert r.passed, [(c.name, c.status, c.detail) for c in r.checks if c.status == "FAIL"]
        assert (tmp_path / name / "summary.md").is_file()
    # the experiments table: one row each, with its trials, and no failed checks or trial errors
    exp_rows = {row[0]: row for row in _table(md, "| experiment | split (seeds) | trials |")}
    for name, r in results.items():
        row = exp_rows[name]
        assert row[2] == str(len(r.table)) and row[6] == "0" and row[7] == "0", row
        assert row[3] == str(sum(c.status == "pass" for c in r.checks))
        assert row[4] == str(sum(c.status == "missed" for c in r.checks))
        assert row[5] == str(sum(c.status == "slow" for c in r.checks))
    # the findings table: every finding of these experiments, with its experiment named
    found = _table(md, "| source | published | ours | verdict |")
    for name, sources in FINDINGS.items():
        for src in sources:
            hits = [row for row in found if row[0].startswith(src) and row[-1] == name]
            assert len(hits) >= 1, (name, src)
            # a quick run is not evidence: no held or not held, but the sample the figures rest on
            assert all(re.fullmatch(r"\*\*insufficient evidence\*\* at this size \(n = \d+ [^)]+\)", h[3])
                       for h in hits), hits
    assert any(row[-1] == "surface_vs_rate" and row[2].startswith("warehouse2d:") for row in found)
    # the recorded misses (Intel Lab held-out |SDF|, the warehouse2d GPIS bounds) are listed as missed, not FAIL
    not_met = _table(md, "| experiment | check | status | figures |")
    assert not_met and all(row[2] in ("missed", "slow") for row in not_met), not_met
    assert {row[0] for row in not_met} >= {"gpis_accuracy", "intel_lab"}
    assert any(row[0] == "gpis_accuracy" and row[1].startswith("warehouse2d") for row in not_met)
    assert any(row[0] == "intel_lab" and row[1].startswith("Intel Lab: held-out") for row in not_met)
    saved = json.loads((tmp_path / "report.json").read_text())
    assert set(saved["experiments"]) == set(GPIS) and not saved["errors"]
    html = (tmp_path / "report.html").read_text()
    assert "data:image/png;base64," in html and html.count("<table>") >= 3
    # the CLI on the same folder resumes (no trial runs again) and exits 0 by default, 2 with --strict
    assert main(["reproduce", "--quick", "--only", *GPIS, "--out", str(tmp_path)]) == 0
    assert main(["reproduce", "--quick", "--strict", "--only", *GPIS, "--out", str(tmp_path)]) == 2
    # --report-only reads the finished folders back, their trials/ removed, and runs nothing: the
    # same experiments and findings tables; a size the folders do not hold is refused, writing nothing
    import shutil

    for name in GPIS:
        shutil.rmtree(tmp_path / name / "trials")
    again, report2 = reproduce(tmp_path, quick=True, only=GPIS, progress=False, report_only=True)
    md2 = report2.read_text()
    assert "assembled" in md2 and not (tmp_path / GPIS[0] / "trials").exists()
    assert [r[:7] for r in _table(md2, "| experiment | split (seeds) | trials |")] == \
        [r[:7] for r in _table(md, "| experiment | split (seeds) | trials |")]
    assert _table(md2, "| source | published | ours | verdict |") == found
    assert main(["reproduce", "--quick", "--report-only", "--only", *GPIS, "--out", str(tmp_path)]) == 0
    with pytest.raises(ValueError, match="holds quick-size runs, not full-size ones"):
        reproduce(tmp_path, quick=False, only=GPIS, progress=False, report_only=True)


# The committed full reproduction (docs/reproduce_full, linked from the README) is whole and
# consistent: every shipped experiment is a finished full-size run whose trial keys are today's
# grid (an experiment whose grid changed no longer loads), and --report-only rebuilds the
# committed report's findings and experiments tables from those folders, cell for cell.
def test_committed_full_reproduction(tmp_path):
    import shutil
    from pathlib import Path

    from polar_sim.runner.registry import list_experiments
    from polar_sim.runner.run import load_run

    root = Path(__file__).resolve().parents[2] / "docs" / "reproduce_full"
    for name in list_experiments():
        r = load_run(root / name, name)
        assert r.config["size"] == "full" and r.table and not r.failures, name
        shutil.copytree(root / name, tmp_path / name)
    results, report = reproduce(tmp_path, report_only=True, progress=False)
    assert set(results) == set(list_experiments())
    new, old = report.read_text(), (root / "report.md").read_text()
    for header in ("| source | published | ours | verdict |", "| experiment | split (seeds) | trials |"):
        assert _table(new, header) == _table(old, header), header
    assert "data:image/png;base64," in (root / "report.html").read_text()
