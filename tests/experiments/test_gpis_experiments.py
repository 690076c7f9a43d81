"""The GPIS-chapter experiments at their quick size, and the plug-ins they run.

Each quick test runs one experiment as ``polar-sim run NAME --quick --split dev`` does and asserts
its headline checks (the issues' inequalities, evaluated against exact ground truth or, for the
real Intel Lab log, against its corrected poses). Bounds the current maps miss are listed in
``KNOWN_MISSES`` with the figure measured at this size; the test asserts that they are still
missed (a strict xfail: the day one is met the test fails, so that benchmarks/RESULTS.md and the
README get updated) and that the experiment reports them as known misses. Checks on CPU time
(``TIMED``) are not asserted: a timing on a shared 2-core machine measures the machine; the test
asserts only that they ran and gave a figure in ms. Their bounds are measured at full size and
recorded in benchmarks/RESULTS.md.
"""

import json

import numpy as np
import pytest

from polar_sim.runner import get_method, list_methods, run_experiment

EXPERIMENTS = ["gpis_accuracy", "surface_vs_rate", "mapping_cost", "localisation", "objects3d", "gazebo1", "intel_lab"]

#: (experiment, start of the check's name): the figure measured at the quick size (dev seed 0).
KNOWN_MISSES = {
    ("gpis_accuracy", "warehouse2d: near-surface SDF RMSE"): "2.49 cm vs 2 cm",
    ("gpis_accuracy", "warehouse2d: Hausdorff on surfaces hit by >= 10 scans"): "above 10 cm: corners (small clutter kept since the surface() fix)",
    ("intel_lab", "Intel Lab: held-out end points' median |SDF|"): "1.56 cm vs 1.5 cm",
}

#: (experiment, start of the check's name) of checks on CPU time: run, not asserted (see above).
TIMED = {("mapping_cost", "update cost independent of map size"),
         ("localisation", "ICP-G error lower than the PF's at the same compute budget"),
         ("localisation", "one ICP-G step <= 10 ms"),
         ("intel_lab", "Intel Lab: median update <= 8 ms")}

# Figures and tables each experiment's summary must produce.
ARTEFACTS = {
    "gpis_accuracy": ["gpis_accuracy_warehouse2d.csv", "gpis_accuracy_object_orbit.csv", "gpis_accuracy_warehouse2d.png"],
    "surface_vs_rate": ["surface_vs_rate.csv", "structure_surface_vs_rate.png", "structure_surfaces_sparsest_warehouse2d.png"],
    "mapping_cost": ["mapping_cost.csv", "structure_mapping_cost.png"],
    "localisation": ["localisation.csv", "structure_localisation.png"],
    "objects3d": ["objects3d.csv", "gpis_objects3d.png"],
    "gazebo1": ["gazebo1.csv", "gpis_gazebo1_modes.png"],
    "intel_lab": ["intel_lab.csv", "intel_lab.png"],
}


def _match(name, check, table):
    return next((v for (e, start), v in table.items() if e == name and check.name.startswith(start)), None) \
        if isinstance(table, dict) else any(e == name and check.name.startswith(s) for e, s in table)


# quick size: every trial runs, one row per grid point, the summary has its tables and figures, and
# the headline checks hold (known misses stay missed; timings are not asserted)
@pytest.mark.slow
@pytest.mark.parametrize("name", EXPERIMENTS)
def test_quick_experiment(name, tmp_path):
    res = run_experiment(name, quick=True, split="dev", out=tmp_path, progress=False)
    assert not res.failures, res.failures[0]["error"] if res.failures else ""
    assert res.checks, "the experiment declares no checks"
    for f in ARTEFACTS[name]:
        assert (tmp_path / f).is_file(), f"{name}: {f} missing"
    saved = json.loads((tmp_path / "checks.json").read_text())
    assert [c["name"] for c in saved] == [c.name for c in res.checks]
    for c in res.checks:
        # the checks on CPU time say so (a miss of one shows as "slow", not as a failure)
        assert c.timing == _match(name, c, TIMED), f"{name}: {c.name}: timing={c.timing}"
        if c.timing:
            assert " ms" in c.detail, c.detail
            continue
        miss = _match(name, c, KNOWN_MISSES)
        if miss is None:
            assert c.passed, f"{name}: check failed: {c.name}: {c.detail}"
        else:
            assert not c.passed, f"{name}: known miss now met, update the records: {c.name}: {c.detail}"
            assert c.known_miss, f"{name}: a recorded miss must be reported as missed, not FAIL: {c.name}"
    for (e, start) in list(KNOWN_MISSES) + list(TIMED):
        if e == name:
            assert any(c.name.startswith(start) for c in res.checks), f"{name}: no check named {start!r}"


# the methods are real axes: the localisation quick run has one row per method, each its own errors
@pytest.mark.slow
def test_localisation_rows_per_method(tmp_path):
    res = run_experiment("localisation", quick=True, split="dev", out=tmp_path, progress=False,
                         overrides={"method": ["icpg", "icpd_gt"]})
    assert sorted(r["method"] for r in res.table) == ["icpd_gt", "icpg"]
    for r in res.table:
        assert 0.0 < r["pos_median_m"] < 0.1 and r["n_steps"] > 50
    assert res.table[0]["pos_median_m"] != res.table[1]["pos_median_m"]


# every built-in GPIS plug-in follows its protocol on an analytic room: the localisers return the
# pose they were started at when the scan matches the map exactly there
def test_localizer_plugins_on_a_square_room():
    from polar_sim.runner.gpis_methods import call_factory

    def sdf(P):                       # inside a 6 x 4 m room centred at the origin
        return np.minimum(3.0 - np.abs(P[:, 0]), 2.0 - np.abs(P[:, 1]))

    angles = np.linspace(-np.pi * 0.75, np.pi * 0.75, 271)

    def scan(pose):
        d = np.c_[np.cos(angles + pose[2]), np.sin(angles + pose[2])]
        with np.errstate(divide="ignore"):
            tx = np.where(d[:, 0] > 0, (3 - pose[0]) / d[:, 0], (-3 - pose[0]) / d[:, 0])
            ty = np.where(d[:, 1] > 0, (2 - pose[1]) / d[:, 1], (-2 - pose[1]) / d[:, 1])
        return np.minimum(np.abs(tx), np.abs(ty))

    poses = np.array([[x, y, th] for x, y, th in [(-1, 0, 0), (0, 0.5, 1), (1, -0.5, 2), (0.5, 0, -1)]], float)
    ranges = np.array([scan(p) for p in poses])
    truth = np.array([0.2, -0.3, 0.4])
    for name in list_methods("localizer2d"):
        loc = call_factory(get_method("localizer2d", name), seed=0, init_std=(0.02, 0.02, 0.01), exact_sdf=sdf)
        loc.fit(angles, ranges, poses)
        loc.reset(truth + [0.03, -0.02, 0.01])
        for _ in range(3):
            est = loc.step(angles, scan(truth), np.zeros(3))
        assert est.shape == (3,) and np.hypot(*(est[:2] - truth[:2])) < 0.05, (name, est)
    for name in list_methods("mapper2d"):
        m = call_factory(get_method("mapper2d", name), seed=0)
        for p, r in zip(poses, ranges):
            m.update(angles, r, p)
        d, g, _ = m.query(np.array([[2.8, 0.0], [0.0, -1.8]]))      # 0.2 m from a wall (legacy: a distance only there)
        np.testing.assert_allclose(d, [0.2, 0.2], atol=0.1, err_msg=name)
        np.testing.assert_allclose(g / np.linalg.norm(g, axis=1)[:, None], [[-1, 0], [0, 1]], atol=0.2, err_msg=name)


# a user's plug-in given as "package.module:attribute" runs through the experiment's method axis
def test_import_path_plugin_is_validated():
    from polar_sim.runner.methods import get_method

    f = get_method("localizer2d", "polar_sim.runner.gpis_methods:ICPGLocalizer2D")
    assert f.__name__ == "ICPGLocalizer2D"
    with pytest.raises(ValueError, match="valid"):
        get_method("localizer2d", "icp_nope")


# office2d tiles=2: four floors joined by doors; the mapping_cost snake keeps clear of every wall
def test_tiled_office_is_drivable():
    from polar_sim.sim import World
    from polar_sim.sim.recorders.drives2d import snake_route

    w = World("office2d", seed=0, kinematic=True, tiles=2)
    one = World("office2d", seed=0, kinematic=True)
    try:
        assert w.meta.bounds == (-15.0, 45.0, -15.0, 45.0) and one.meta.tiles == 1
        path = snake_route(2)
        assert w.sdf(path).min() > 0.35                     # doors between tiles, furniture-free lanes
        assert one.sdf(path[path[:, 0] < 14.5][:10]).min() > 0.5
        assert w.model.ngeom > 3 * one.model.ngeom
        assert w.sdf(np.array([[20.0, 15.0], [15.0, 8.0]])).max() < 0.0
        assert w.sdf(np.array([[39.85, 15.0], [15.0, 0.0]])).min() > 0.4
    finally:
        w.close()
        one.close()


# ---- sizes as data, findings and user-facing text (unit tests: no trial runs) ----

#: The full-size protocol of each GPIS experiment (the committed full-size runs were made with it)
#: and the quick size's overrides.
PROTOCOL = {
    "gazebo1": ({"map_every_scans": 1, "held_out_every_scans": 10, "picture_res_m": 0.1},
                {"map_every_scans": 10, "held_out_every_scans": 20, "picture_res_m": 0.2}),
    "gpis_accuracy": ({"every_steps": 1, "n_eval_2d": 60_000, "orbit_n_frames": 40, "orbit_n_eval": 4000},
                      {"every_steps": 3, "n_eval_2d": 30_000, "orbit_n_frames": 20, "orbit_n_eval": 2000}),
    "intel_lab": ({"held_out_stride": 1, "picture_res_m": 0.05}, {"held_out_stride": 4, "picture_res_m": 0.2}),
    "localisation": ({"map_s": 150.0, "map_every_steps": 2, "loc_s": 60.0, "loc_every_steps": 2},
                     {"map_s": 60.0, "map_every_steps": 3, "loc_s": 30.0, "loc_every_steps": 2}),
    "mapping_cost": ({"every_m": 0.5}, {"every_m": 1.0}),
    "objects3d": ({"n_frames": 40, "n_eval": 4000}, {"n_frames": 20, "n_eval": 2000}),
    "surface_vs_rate": ({"n_eval": 40_000}, {"n_eval": 15_000}),
    "sensors": ({}, {}),
}


# every size-dependent protocol value is a declared param, not an `if quick` branch in the code
@pytest.mark.parametrize("name", sorted(PROTOCOL))
def test_sizes_are_params(name):
    import inspect

    from polar_sim.runner import get_experiment

    exp = get_experiment(name)
    full, quick = PROTOCOL[name]
    assert exp.resolve_params("full") == full
    assert exp.resolve_params("quick") == quick
    src = inspect.getsource(inspect.getmodule(exp.trial))
    assert "ctx.quick" not in src and "quick =" not in src, f"{name}: a size picked in code, not in params"


# scene-like axes refuse unknown values before any trial runs
@pytest.mark.parametrize("name, axis, bad", [("gpis_accuracy", "scene", "office3d"), ("surface_vs_rate", "scene", "moon"),
                                             ("localisation", "scene", "warehouse"), ("sensors", "scene", "tabletop_x"),
                                             ("objects3d", "object", "teapot")])
def test_scene_choices(name, axis, bad, tmp_path):
    with pytest.raises(ValueError, match=f"{axis}: {name} has no {axis} '{bad}'; valid: "):
        run_experiment(name, quick=True, split="dev", out=tmp_path / "r", overrides={axis: [bad]}, progress=False)
    assert not (tmp_path / "r" / "results.csv").exists()


# no internal issue numbers in what `polar-sim list` shows
@pytest.mark.parametrize("name", sorted(PROTOCOL))
def test_no_issue_numbers_in_descriptions(name):
    import re

    from polar_sim.runner import get_experiment

    assert not re.search(r"\bissues? \d", get_experiment(name).description)


class _Ctx:
    """A RunContext stand-in whose rows carry their arrays."""

    out_dir, size, split, params = None, "full", "dev", {}

    def arrays(self, row, name="arrays"):
        return row["_arrays"]


def _loc_row(method, median_m, cpu_ms, n=100):
    err = np.c_[np.full(n, median_m), np.full(n, 0.1)]
    return {"method": method, "seed": 0, "pos_median_m": median_m, "fail_steps": 0, "cpu_ms_median": cpu_ms,
            "wall_ms_median": cpu_ms, "head_median_deg": 0.1, "_arrays": {"err": err}}


# localisation: one finding per comparison, each with its figures; ICP-G losing to ICP-D on the
# ground-truth SDF is "not held" there while it still beats ICP-D on the grid EDT and the PF
def test_localisation_findings_compare_each_baseline():
    from polar_sim.experiments import localisation as L

    table = [_loc_row("icpg", 0.004, 6.0), _loc_row("icpd", 0.005, 3.0), _loc_row("icpd_gt", 0.002, 3.0),
             _loc_row("pf1000", 0.016, 1.8), _loc_row("pf5000", 0.0158, 6.3), _loc_row("pf10000", 0.015, 13.0)]
    f = {x.source.split(": ", 1)[1]: x for x in L.findings(table, _Ctx())}
    gt, edt, pf = (f["ICP-G vs ICP-D on a ground-truth discrete SDF"], f["ICP-G vs ICP-D on a map from the same scans"],
                   f["ICP-G vs the particle filter at the same compute budget"])
    assert (gt.verdict, edt.verdict, pf.verdict) == ("not held", "held", "held")
    assert "0.40 cm" in gt.ours and "0.20 cm" in gt.ours and "0.50 cm" in edt.ours
    assert "pf5000 1.58 cm" in pf.ours and "pf10000" in pf.ours      # the budget match, and the most accurate PF
    assert "ground-truth" in gt.claim and "dissertation's setting" in gt.note
    # no PF reaches ICP-G's CPU per step: the same-budget claim is not tested
    cheap = [r for r in table if r["method"] not in ("pf5000", "pf10000")]
    pf = next(x for x in L.findings(cheap, _Ctx()) if "particle filter" in x.source)
    assert pf.verdict == "not tested the same way" and "no PF run reached" in pf.note


def _svr_rows(values):
    """surface_vs_rate rows from {(spacing, method): (hausdorff m, surface rmse m)}."""
    return [{"scene": "office2d", "spacing_m": sp, "method": k, "seed": 0, "hausdorff_m": h, "surface_rmse_m": r,
             "worst_corner_share": 0.8 if k == "gpis" else 0.2, "worst_sparse_share": 0.1 if k == "gpis" else 0.5}
            for (sp, k), (h, r) in values.items()]


# surface_vs_rate: the finding gives Hausdorff and RMSE of GPIS, both grids and the EDT at the
# sparsest and densest spacing, and its verdict follows where GPIS is the lowest
def test_surface_vs_rate_finding_gives_figures():
    from polar_sim.experiments import surface_vs_rate as S

    base = {(sp, k): (0.5, 0.01) for sp in (0.1, 0.5, 1.0) for k in ("grid5", "grid10", "edt5")}
    cases = [({(0.1, "gpis"): (0.2, 0.005), (1.0, "gpis"): (0.3, 0.006)}, "held"),
             ({(0.1, "gpis"): (0.2, 0.02), (1.0, "gpis"): (0.9, 0.02)}, "partly held"),
             ({(0.1, "gpis"): (0.9, 0.02), (1.0, "gpis"): (0.9, 0.02)}, "not held")]
    for gp, verdict in cases:
        gp[(0.5, "gpis")] = (0.1, 0.001)          # an intermediate spacing: not in the finding
        acc, worst = S.findings(_svr_rows({**base, **gp}), _Ctx())
        assert acc.verdict == verdict, (gp, acc.ours)
        assert "every 1 m (sparsest)" in acc.ours and "every 0.1 m (densest)" in acc.ours and "every 0.5 m" not in acc.ours
        for label in ("GPIS", "grid 5 cm", "grid 10 cm", "EDT"):
            assert f"{label} " in acc.ours
        assert f"GPIS {gp[(1.0, 'gpis')][0]:.2f} m / {100 * gp[(1.0, 'gpis')][1]:.2f} cm" in acc.ours
        assert worst.source == "Ch. 7, where the worst errors lie" and worst.verdict == "held"
