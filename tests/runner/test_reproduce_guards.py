"""`polar-sim reproduce` never replaces a good report with a worse one: --report-only takes the
size from the folders (or refuses, writing nothing), and a run into folders of another size, or
on a Ray cluster that does not answer, is refused before anything runs."""

import json

import pytest

from polar_sim.cli import main
from polar_sim.runner.reproduce import reproduce


@pytest.fixture(scope="module")
def quick_folder(tmp_path_factory):
    """A finished quick reproduction of the sensors experiment and its report."""
    out = tmp_path_factory.mktemp("rq")
    assert main(["reproduce", "--quick", "--only", "sensors", "--out", str(out), "--quiet"]) == 0
    return out


def _snapshot(folder):
    return {p.relative_to(folder): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


# --report-only without --quick on a quick folder: the size is the folder's, the report the same
# (it used to be rewritten as "every experiment failed", exit 2).
def test_report_only_takes_the_folders_size(quick_folder, capsys):
    before = json.loads((quick_folder / "report.json").read_text())
    assert main(["reproduce", "--report-only", "--only", "sensors", "--out", str(quick_folder)]) == 0
    capsys.readouterr()
    md = (quick_folder / "report.md").read_text()
    assert "**Size: quick**" in md and "assembled" in md
    after = json.loads((quick_folder / "report.json").read_text())
    assert after["experiments"] == before["experiments"] and not after["errors"]


# Folders the report cannot be assembled from are refused in one line naming --out, and the
# folder (its good report included) is left byte for byte as it was.
@pytest.mark.parametrize("argv, says", [
    (["--report-only"], "--out: 15 of 16 experiments have no finished run in"),     # the others are missing
    (["--report-only", "--only", "sensors", "gazebo1"], "--out: 1 of 2 experiments have no finished run"),
    (["--only", "sensors"], "--out: "),                                               # a full run into quick folders
    (["--quick", "--only", "sensors", "--backend", "ray", "--address", "127.0.0.1:1"], "--address: cannot reach"),
])
def test_refused_leaves_the_folder_untouched(quick_folder, capsys, argv, says):
    before = _snapshot(quick_folder)
    rc = main(["reproduce", "--out", str(quick_folder), *argv])
    err = capsys.readouterr().err
    assert rc == 1 and err.startswith("polar-sim: error: " + says) and err.count("\n") == 1, err
    assert _snapshot(quick_folder) == before


# The library says why: the size the folders hold, and what to change.
def test_report_only_size_mismatch_names_the_fix(quick_folder):
    before = _snapshot(quick_folder)
    with pytest.raises(ValueError, match=r"out: .* holds quick-size runs, not full-size ones \(add --quick\); "
                                         "no report was written"):
        reproduce(quick_folder, quick=False, only=["sensors"], report_only=True)
    with pytest.raises(ValueError, match=r"out: .*sensors.* holds a run of 'sensors' with size 'quick', not 'full'"):
        reproduce(quick_folder, only=["sensors"], progress=False)
    assert _snapshot(quick_folder) == before
