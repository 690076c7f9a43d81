"""The ground experiments' summaries, checks and findings on synthetic tables: fake rows and
trajectories written through the runner's public contexts, no simulation. These cover the paths a
quick run never reaches (the full-size KITTI findings of ground_odometry, the recorded-miss rule of
ground_appearance) and the report rules: no all-empty (nan) columns, and a line saying why one is
absent; sizes as declared params; the route axis refusing unknown routes before any trial."""

import json
import re

import numpy as np
import pytest

from polar_sim.experiments import _ground_candidates as C
from polar_sim.experiments import _ground_common as G
from polar_sim.experiments import ground_appearance as GA
from polar_sim.experiments import ground_odometry as GO
from polar_sim.runner import RunContext, TrialContext, run_experiment
from polar_sim.runner.results import trial_dir, trial_key

GROUND = ("ground_odometry", "ground_appearance", "ground_success", "ground_scale")


def _path(n, scale=1.0, yaw_rate=0.0):
    """(n, 4, 4) camera poses 1 m apart along z (KITTI camera frame), each step ``scale`` m long on
    the estimate and turned about y by ``yaw_rate`` rad per metre: a VO with a scale error of
    (scale - 1) and a rotation drift of yaw_rate."""
    poses, T = [], np.eye(4)
    for _ in range(n):
        poses.append(T.copy())
        c, s = np.cos(yaw_rate * scale), np.sin(yaw_rate * scale)
        step = np.eye(4)
        step[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
        step[2, 3] = scale
        T = T @ step
    return np.array(poses)


def _odometry_run(tmp_path, errors, *, frames=151, routes=("r0", "r1"), yaw=None, split="test", size="full"):
    """A RunContext and rows of ground_odometry as its trials would leave them: per (route, method),
    a straight route of ``frames`` frames (1 m apart) estimated with a KITTI translation error of
    ``errors[method]`` % and ``yaw[method]`` rad/m rotation drift. (A 100 m segment of 1 m steps spans
    101 m, divided by its nominal 100 m: a scale error of e / 1.01 scores e.)"""
    from polar_sim.metrics.ground import kitti_scores

    yaw = yaw or {}
    ctx = RunContext(tmp_path, size=size, split=split, params={"max_frames": None})
    gt, table = _path(frames), []
    for route in routes:
        for m, pct in errors.items():
            est = _path(frames, 1.0 + pct / 101.0, yaw.get(m, 1e-5))
            params = {"route": route, "method": m}
            key = trial_key(params, 10_000)
            TrialContext(trial_dir(tmp_path, key)).save_arrays("trajectories", gt=gt, est=est)
            table.append(dict(params, seed=10_000, split=split, size=size, status="ok", trial_key=key, route_used=route,
                              length_m=float(frames - 1), frames=frames, cpu_ms_median=12.0, **kitti_scores(gt, est)))
    return table, ctx


# The full-size ordering as the dev split measured it (w6 1.09 < u6 1.17 < u2 3.78 < w2 4.46 %, held-scale
# monocular baseline 14.24 %): "partly held", and the ours text says both things the reproduce table
# must: our ordering reverses the 2-parameter pair, and our monocular baseline is not VISO2-M.
def test_odometry_findings_reversed_two_parameter_pair(tmp_path):
    table, ctx = _odometry_run(tmp_path, {"u2": 3.78, "w2": 4.46, "u6": 1.17, "w6": 1.09, "mono": 14.24})
    order, rot = GO.findings(table, ctx)
    assert order.verdict == "partly held"
    assert order.claim == "w6 6.21 < u6 7.01 < w2 7.15 < u2 7.19 %; VISO2-M 12.58 % worse"
    got = [(m, float(x)) for m, x in re.findall(r"(\w+) (\d+\.\d+)", order.ours.split(";")[0])]
    assert [m for m, _ in got] == ["w6", "u6", "u2", "w2"]
    np.testing.assert_allclose([x for _, x in got], [1.09, 1.17, 3.78, 4.46], atol=0.006)
    assert "our ordering reverses the 2-parameter pair (w2 > u2)" in order.ours
    assert "6-parameter" not in order.ours
    assert "our monocular baseline differs from VISO2-M" in order.ours and "14.24 %, worse than all four" in order.ours
    assert "100–800 m" in order.note and "VISO2-M is not run here" in order.note
    # the same rotation drift on all four: equal rotation errors
    assert rot.verdict == "held" and rot.claim == "rotation error equal across u2, w2, u6, w6"
    degm = [float(x) for x in re.findall(r"(\d+\.\d+) deg/m", rot.ours)]
    np.testing.assert_allclose(degm, np.degrees(1e-5), atol=1e-4)
    # the full-size checks: targets on 100-800 m segments, not the short-route comparison
    checks = {c.name: c for c in GO.checks(table, ctx)}
    assert set(checks) == {"w6 pooled translation error ≤ 2.0 % (test)", "w6 pooled rotation error ≤ 0.01 deg/m (test)",
                           "w6 rotation error ≤ 0.01 deg/m on every route (test)",
                           "w6 has the lowest pooled translation error", "per-frame CPU ≤ 15.0 ms (621x188, median)"}
    assert all(c.passed for c in checks.values())


# The held-out figures before the dense ground alignment (w6 7.58 %, u6 6.58 % below it): with the
# dense stage w6 meets the target on test (RESULTS, issue 35: 1.76 %), so such a table now fails on
# both splits; u6 below w6 stays a recorded miss on test only.
@pytest.mark.parametrize("split, status, lowest", [("test", "FAIL", "missed"), ("dev", "FAIL", "FAIL")])
def test_odometry_recorded_misses(tmp_path, split, status, lowest):
    errors = {"u2": 13.69, "w2": 13.09, "u6": 6.58, "w6": 7.58, "mono": 30.09}
    table, ctx = _odometry_run(tmp_path, errors, split=split)
    checks = {c.name.split(" (")[0]: c for c in GO.checks(table, ctx)}
    assert checks["w6 pooled translation error ≤ 2.0 %"].status == status
    assert checks["w6 has the lowest pooled translation error"].status == lowest
    assert checks["w6 rotation error ≤ 0.01 deg/m on every route"].status == "pass"
    assert checks["w6 pooled rotation error ≤ 0.01 deg/m"].status == "pass"   # this table drifts 1e-5 rad/m
    assert checks["per-frame CPU ≤ 15.0 ms"].status == "pass"


# The published ordering and a worse monocular baseline: "held", with no reversal named.
def test_odometry_findings_published_order_holds(tmp_path):
    table, ctx = _odometry_run(tmp_path, {"u2": 7.19, "w2": 7.15, "u6": 7.01, "w6": 6.21, "mono": 12.58})
    order, rot = GO.findings(table, ctx)
    assert order.verdict == "held" and "reversed" not in order.ours and "reverses" not in order.ours
    assert order.ours.startswith("w6 6.2") and " < u6 7.0" in order.ours and " < w2 7.1" in order.ours
    assert rot.verdict == "held"


# The held-out split's pattern (u6 < w6, mono worse): the 6-parameter pair is named as reversed; a
# monocular baseline better than one of the four is said; unequal rotation drift fails the equality.
def test_odometry_findings_other_reversals(tmp_path):
    errors = {"u2": 13.7, "w2": 13.1, "u6": 6.58, "w6": 7.58, "mono": 10.0}
    table, ctx = _odometry_run(tmp_path, errors, yaw={"w6": 1e-4}, routes=("r0",))
    order, rot = GO.findings(table, ctx)
    assert "our ordering reverses the 6-parameter pair (w6 > u6)" in order.ours and "2-parameter" not in order.ours
    assert "not worse than all four" in order.ours and order.verdict == "partly held"
    assert rot.verdict == "not held"
    checks = {c.name: c.passed for c in GO.checks(table, ctx)}
    assert checks["w6 has the lowest pooled translation error"] is False
    assert checks["w6 pooled translation error ≤ 2.0 % (test)"] is False


# Without all four of u2/w2/u6/w6 the published ordering is not tested, and the finding says so.
def test_odometry_findings_without_the_four(tmp_path):
    table, ctx = _odometry_run(tmp_path, {"w6": 1.0, "mono": 5.0})
    (f,) = GO.findings(table, ctx)
    assert f.verdict == "not tested the same way" and "this run has only" in f.note


# Routes under 100 m (the quick size's, or any short route at full size) have no 100 m KITTI segment:
# the report drops those columns and says why in one line, and the checks and findings use the scaled
# segments because of the routes' length, whatever the size is called.
@pytest.mark.parametrize("size", ["quick", "full"])
def test_odometry_short_routes_use_scaled_segments(tmp_path, size):
    table, ctx = _odometry_run(tmp_path, {"w6": 2.0, "mono": 6.0}, frames=60, routes=("quick",), split="dev",
                               size=size)
    assert all(not np.isfinite(r["t_pct"]) for r in table)
    text = GO.summarize(table, ctx)
    assert "nan" not in text and "| t_pct_scaled |" in text
    assert "| t_pct |" not in text and "| r_degm |" not in text
    assert "Not shown: `t_pct`, `r_degm` (no 100 m KITTI segment on routes under 100 m)." in text
    (check,) = GO.checks(table, ctx)
    assert check.name == "w6 beats the held-scale monocular baseline (scaled segments: routes under 100 m)"
    assert check.passed and not check.known_miss
    (f,) = GO.findings(table, ctx)
    assert "scaled segments" in f.note and "longest 59 m" in f.note


# A long route's report keeps the KITTI columns and needs no such line.
def test_odometry_long_route_summary_keeps_kitti_columns(tmp_path):
    table, ctx = _odometry_run(tmp_path, {"w6": 1.0, "mono": 5.0}, routes=("r0",))
    text = GO.summarize(table, ctx)
    assert "| t_pct | r_degm |" in text and "nan" not in text
    assert "no 100 m KITTI segment" not in text


def test_table_drops_empty_columns_and_says_why():
    rows = [{"a": 1.0, "b": float("nan"), "c": None, "d": 2.0}, {"a": 2.0, "b": None, "c": "", "d": float("nan")}]
    text = G.table(rows, ["a", "b", "c", "d"], {"b": "too short"})
    header = text.splitlines()[0]
    assert header == "| a | d |"
    assert text.splitlines()[-1] == "Not shown: `b` (too short); `c` (empty in every row)."
    assert G.table(rows, ["a", "d"]).count("Not shown") == 0


def _series(families, iou):
    """ground_appearance's per-trial series: one settled frame per family zone with IoU ``iou[k]``
    and a perfectly calibrated 4x4 probability map."""
    from polar_sim.metrics.calibration import reliability_counts
    from polar_sim.metrics.ground import class_prob_sums

    prob, mask = np.full((4, 4), 0.5), np.arange(16).reshape(4, 4) % 2 == 0
    n = len(families)
    return dict(t=np.arange(n, dtype=float), iou=np.asarray(iou, float), settled=np.ones(n, bool), zone=np.arange(n),
                progress=np.zeros(n), boundaries=np.zeros(n), families=np.array(families),
                bins=np.array([reliability_counts(prob, mask)] * n), psums=np.array([class_prob_sums(prob, mask)] * n))


# No family is recorded as missing the IoU target any more (checker meets it with the sky labels;
# uniform and stripes with the dense stage's support labels): any family below it is a failure, at
# any size.
@pytest.mark.parametrize("below, status", [(("checker",), "FAIL"), (("stripes",), "FAIL"), (("uniform",), "FAIL"),
                                           (("gravel",), "FAIL"), (("checker", "gravel"), "FAIL"), ((), "pass")])
def test_appearance_recorded_misses(tmp_path, below, status):
    fams = ["gravel", "grass", "stripes", "checker", "uniform"]
    params = {"route": "r0", "method": "w6"}
    key = trial_key(params, 0)
    TrialContext(trial_dir(tmp_path, key)).save_arrays("series", **_series(fams, [0.5 if f in below else 0.95 for f in fams]))
    table = [dict(params, seed=0, trial_key=key)]
    iou, ece = GA.checks(table, RunContext(tmp_path, size="full", split="test"))
    assert iou.status == status and iou.name == "w6 settled IoU ≥ 0.85 on every family (test)"
    assert "5 families with settled frames" in iou.detail
    assert ece.passed and ece.status == "pass"


# Sizes are data: the quick size differs from the full one only in declared params and grid values.
@pytest.mark.parametrize("name", ["ground_odometry", "ground_appearance"])
def test_route_experiments_declare_max_frames(name):
    from polar_sim.runner.registry import get_experiment

    exp = get_experiment(name)
    assert exp.resolve_params("full") == {"max_frames": None}
    assert exp.resolve_params("quick") == {"max_frames": G.QUICK_FRAMES}
    assert exp.resolve_params("quick", overrides={"max_frames": 40}) == {"max_frames": 40}
    for bad in (0, -3, 2.5, "ten", True):
        with pytest.raises(ValueError, match="max_frames: expected a positive number of frames or null"):
            G.max_frames(TrialContext(".", params={"max_frames": bad}))


# The route axis accepts the split's quick route and every registered route, and refuses a typo
# before any trial runs (nothing is written).
def test_route_choices(tmp_path):
    from polar_sim.sim.recorders.rover_sequences import SPLITS

    routes = G.route_choices()
    assert routes[0] == "quick" and set(routes[1:]) == set(SPLITS["dev"]) | set(SPLITS["test"])
    assert set(G.DEV10) | set(G.DEV_FAMILY_ROUTES) | set(G.TEST_ROUTES) | set(G.QUICK_ROUTE.values()) <= set(routes)
    for name in ("ground_odometry", "ground_appearance"):
        with pytest.raises(ValueError, match=f"route: {name} has no route 'terain_00'; valid: quick, terrain_00"):
            run_experiment(name, out=tmp_path / name, quick=True, overrides={"route": ["terain_00"]}, progress=False)
        assert not (tmp_path / name).exists()
    with pytest.raises(ValueError, match="data: ground_success has no data 'dev11'"):
        run_experiment("ground_success", out=tmp_path / "s", quick=True, overrides={"data": ["dev11"]}, progress=False)


# User-facing text names no internal issue or spec section (the specs are not shipped).
@pytest.mark.parametrize("name", GROUND)
def test_no_internal_references(name):
    import importlib

    from polar_sim.runner.registry import get_experiment

    mod = importlib.import_module(f"polar_sim.experiments.{name}")
    for text in (get_experiment(name).description, mod.__doc__, G.__doc__, C.__doc__, C.candidate_set.__doc__):
        assert not re.search(r"issue \d|§|spec ", text), text


def test_findings_and_checks_text_has_no_internal_references(tmp_path):
    table, ctx = _odometry_run(tmp_path, {"u2": 3.78, "w2": 4.46, "u6": 1.17, "w6": 1.09, "mono": 14.24})
    text = json.dumps([f.__dict__ for f in GO.findings(table, ctx)] + [c.__dict__ for c in GO.checks(table, ctx)])
    assert not re.search(r"issue \d|§|spec ", text)
