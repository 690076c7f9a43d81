"""Verdicts respect the sample: only a full-size run on the protocol's seeds, with cells that
can separate the methods, gives held or not held; reports show values with units and notes
below the table."""

import json

import pytest

from polar_sim.runner import Experiment, Finding, run_experiment
from polar_sim.runner.findings import INSUFFICIENT, findings_table, verdict_text, weigh
from polar_sim.runner.report import duration, length, number, percent


def _f(verdict="held", **kw):
    kw.setdefault("note", "simulated sequences")
    return Finding("Ch. 5, Fig. 5.6", "the four implementations perform similarly", "98.4 % to 99.9 %", verdict, **kw)


# At the quick size every verdict reads "insufficient evidence at this size (n = ...)" (a smaller
# run does not test the claim the same way either); at the full size "not tested the same way",
# a statement about the setting, stays.
@pytest.mark.parametrize("verdict", ["held", "partly held", "not held", "not tested the same way"])
def test_quick_size_is_not_evidence(verdict):
    w = weigh(_f(verdict, n=50, n_of="frames of 2 sequences"), size="quick", n_trials=10)
    assert w.verdict == INSUFFICIENT and w.indicated == verdict
    assert verdict_text(w) == "**insufficient evidence** at this size (n = 50 frames of 2 sequences)"
    assert weigh(w, size="quick", n_trials=10) == w                      # idempotent
    assert weigh(_f(verdict), size="quick", n_trials=1).evidence == "at this size (n = 1 trial)"
    kept = _f("not tested the same way", saturated="every variant at 100.0 %")
    assert weigh(kept, size="full", n_trials=3, seeds=1, full_seeds=20) is kept


# At the full size the verdict stands, unless the seeds were cut below the protocol's, n is below
# what the finding needs, or the cells are saturated (every one at 100 %: no difference can show).
def test_full_size_reasons():
    assert weigh(_f(), size="full", n_trials=20, seeds=20, full_seeds=20) == _f()
    assert weigh(_f(), size="full", n_trials=3).verdict == "held"
    cut = weigh(_f(), size="full", n_trials=6, seeds=1, full_seeds=20)
    assert cut.evidence == "with 1 of the protocol's 20 seeds (n = 6 trials)"
    few = weigh(_f(n=2, n_of="sequences", n_needed=3), size="full", n_trials=2)
    assert few.verdict == INSUFFICIENT and few.evidence == "(n = 2 sequences; 3 needed)"
    assert weigh(_f(n=3, n_of="sequences", n_needed=3), size="full", n_trials=3).verdict == "held"
    sat = weigh(_f(n=1760, n_of="frames", saturated="every variant at 100.0 %"), size="full", n_trials=10)
    assert sat.verdict == INSUFFICIENT and sat.evidence == "(n = 1760 frames; every variant at 100.0 %)"
    with pytest.raises(ValueError, match="verdict"):
        _f("probably")
    with pytest.raises(TypeError, match="n_needed"):
        _f(n_needed=2.5)


# A run weighs its findings: findings.json and summary.md say "insufficient evidence" at the
# quick size, the full size keeps the verdict, and a folder written before weighing is weighed
# when it is read back.
def _trial(params, seed, ctx):
    return {"v": 1.0}


def _findings(table, ctx):
    return [Finding("src", "claim", f"{len(table)} rows", "held", "a note " * 40)]


EXP = Experiment("weighed", "", grid={"a": [1]}, trial=_trial, splits={"dev": {"seeds": [0, 1]}},
                 sizes={"quick": {"n_seeds": 1}, "full": {}}, findings=_findings)


def test_runs_weigh_their_findings(tmp_path):
    from polar_sim.runner.run import load_run

    q = run_experiment(EXP, quick=True, out=tmp_path / "q", progress=False)
    assert [f.verdict for f in q.findings] == [INSUFFICIENT]
    saved = json.loads((tmp_path / "q" / "findings.json").read_text())
    assert saved[0]["verdict"] == INSUFFICIENT and saved[0]["indicated"] == "held"
    md = (tmp_path / "q" / "summary.md").read_text()
    assert "**insufficient evidence** at this size (n = 1 trial)" in md and "| [1] |" in md and "- [1] a note" in md
    full = run_experiment(EXP, out=tmp_path / "f", progress=False)
    assert [f.verdict for f in full.findings] == ["held"]
    cut = run_experiment(EXP, out=tmp_path / "c", overrides={"seed": [0]}, progress=False)
    assert cut.findings[0].evidence == "with 1 of the protocol's 2 seeds (n = 1 trial)"
    # an older folder stored the unweighed verdict: reading it back weighs it
    saved[0].update(verdict="held", evidence="", indicated="")
    for k in ("n", "n_of", "n_needed", "saturated", "evidence", "indicated"):
        saved[0].pop(k)
    (tmp_path / "q" / "findings.json").write_text(json.dumps(saved))
    assert load_run(tmp_path / "q", EXP).findings[0].verdict == INSUFFICIENT


# The findings table keeps rows short: notes are numbered below it.
def test_findings_table_moves_notes_below():
    lines = findings_table([("exp_a", _f(note="x" * 600)), ("exp_b", _f(note=""))], experiment_column=True)
    assert lines[0] == "| source | published | ours | verdict | note | experiment |"
    assert lines[1] == "|---|---|---|---|---|---|"
    assert lines[2].endswith("| **held** | [1] | exp_a |") and lines[3].endswith("| **held** |  | exp_b |")
    assert max(len(ln) for ln in lines[:4]) < 200 and lines[-1] == "- [1] " + "x" * 600


# Values carry units: a length in the unit that reads best (or the one asked), percentages,
# durations, plain numbers without e-notation.
def test_units():
    assert length(0.03483) == "3.48 cm" and length(0.0044, "cm", decimals=2) == "0.44 cm"
    assert length(1.2e-5) == "12.0 µm" and length(2.08) == "2.08 m" and length(0.5, "mm") == "500 mm"
    assert percent(1.0) == "100.0 %" and percent(0.52, 0) == "52 %"
    assert duration(0.00281) == "2.81 ms" and duration(300) == "5.00 min" and duration(2e-6) == "2.00 µs"
    assert number(0.0001234) == "0.000123" and number(0) == "0" and number(float("nan")) == "nan"
    with pytest.raises(ValueError, match="unit"):
        length(1.0, "ft")
