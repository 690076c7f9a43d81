"""The GPIS-chapter experiments (issue 4, and issue 3's accuracy experiment) at their quick size.

Each test runs one experiment exactly as ``polar-sim run NAME --quick`` does and asserts its
headline checks (the issue's inequalities, evaluated against exact ground truth). A few of the
issue's bounds are missed by the current maps; they are listed in ``KNOWN_MISSES`` with the
measured figure, and the test asserts that they are still missed, like a strict xfail: the day one
is met, the test fails so that benchmarks/RESULTS.md and the README get updated. Checks whose
bound is on CPU time (``TIMED``) are not asserted here: a timing in a unit test on a shared 2-core
machine measures the machine. The test asserts that they ran and gave a figure; their bounds are
measured at full size and recorded in benchmarks/RESULTS.md.
"""

import json

import numpy as np

import pytest

from polar_sim.runner import run_experiment

pytestmark = pytest.mark.slow

EXPERIMENTS = ["gpis_accuracy", "surface_vs_rate", "mapping_cost", "localisation", "objects3d", "gazebo1"]

#: (experiment, start of the check's name): why it is missed (measured at the quick size).
KNOWN_MISSES = {
    ("gpis_accuracy", "SDF RMSE within 0.3 m"): "2.5 cm vs 2 cm: corners and surfaces glimpsed by a few scans",
    ("gpis_accuracy", "Hausdorff surface()"): "0.24 m vs 10 cm: glimpsed walls without trusted normals, wall ends",
}

#: (experiment, start of the check's name) of checks on CPU time: run, not asserted (see above).
TIMED = {("mapping_cost", "update cost independent of map size")}

# Figures and tables each experiment's summary must produce.
ARTEFACTS = {
    "gpis_accuracy": ["gpis_accuracy_office2d.csv", "gpis_accuracy_object_orbit.csv", "gpis_accuracy_office2d.png"],
    "surface_vs_rate": ["surface_vs_rate.csv", "structure_surface_vs_rate.png", "structure_surfaces_sparsest.png"],
    "mapping_cost": ["mapping_cost.csv", "structure_mapping_cost.png"],
    "localisation": ["localisation.csv", "structure_localisation.png"],
    "objects3d": ["objects3d.csv", "gpis_objects3d.png"],
    "gazebo1": ["gazebo1.csv", "gpis_gazebo1_modes.png"],
}


# quick size: every trial runs, the summary has its tables and figures, and the headline checks hold
@pytest.mark.parametrize("name", EXPERIMENTS)
def test_quick_experiment(name, tmp_path):
    res = run_experiment(name, quick=True, out=tmp_path, progress=False)
    assert not res.failures, res.failures[0]["error"] if res.failures else ""
    assert res.checks, "the experiment declares no checks"
    for f in ARTEFACTS[name]:
        assert (tmp_path / f).is_file(), f"{name}: {f} missing"
    timed = [c for c in res.checks if any(e == name and c.name.startswith(t) for e, t in TIMED)]
    assert len(timed) == sum(e == name for e, _ in TIMED), f"{name}: a timed check is missing"
    assert all(" ms " in c.detail for c in timed), [c.detail for c in timed]
    assert "**FAIL**" in (tmp_path / "summary.md").read_text() or all(c.passed for c in res.checks)
    saved = json.loads((tmp_path / "checks.json").read_text())
    assert [c["name"] for c in saved] == [c.name for c in res.checks]
    for c in res.checks:
        if c in timed:
            continue
        miss = next((why for (e, start), why in KNOWN_MISSES.items() if e == name and c.name.startswith(start)), None)
        if miss is None:
            assert c.passed, f"{name}: check failed: {c.name}: {c.detail}"
        else:
            assert not c.passed, f"{name}: known miss now met, update the records: {c.name}: {c.detail}"
    for (e, start) in KNOWN_MISSES:
        if e == name:
            assert any(c.name.startswith(start) for c in res.checks), f"{name}: no check named {start!r}"


# office2d tiles=2: four floors joined by doors; the mapping_cost snake keeps clear of every wall
def test_tiled_office_is_drivable():
    from polar_sim.experiments.mapping_cost import snake
    from polar_sim.sim import World

    w = World("office2d", seed=0, kinematic=True, tiles=2)
    one = World("office2d", seed=0, kinematic=True)
    try:
        assert w.meta["bounds"] == (-15.0, 45.0, -15.0, 45.0) and "tiles" not in one.meta
        path = snake(2)
        assert w.sdf(path).min() > 0.35                     # doors between tiles, furniture-free lanes
        assert one.sdf(path[path[:, 0] < 14.5][:10]).min() > 0.5
        # tile (0, 0) keeps the untiled furniture where the lane allows it; tile (1, 1) has its own
        assert w.model.ngeom > 3 * one.model.ngeom
        # the walls between tiles are there, with a door only where the snake passes
        assert w.sdf(np.array([[20.0, 15.0], [15.0, 8.0]])).max() < 0.0
        assert w.sdf(np.array([[39.85, 15.0], [15.0, 0.0]])).min() > 0.4
    finally:
        w.close()
        one.close()
