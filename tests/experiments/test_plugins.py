"""A user's plug-in (examples/my_localizer.py) runs through the quick localisation experiment as the
README says, and the experiment scores what the plug-in returned against the true poses.

``DeadReckoning`` ignores the scans, so its estimate is known exactly from the experiment's seeded
start offset and its recorded odometry: the test rebuilds it from the saved truth and odometry and
asserts that the experiment's per-step errors are that estimate's errors against truth. ``GridICP``
matches the scans against the mapping drive; it must do better than odometry alone.
"""

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from polar_sim.runner import RunContext, register_method, run_experiment
from polar_sim.runner.methods import _REGISTRY

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
DR, ICP = "my_localizer:DeadReckoning", "my_localizer:GridICP"


def _dead_reckoning_errors(truth, odom, seed):
    """Per-step (position m, heading deg) errors of odometry-only localisation started where the
    localisation experiment starts every method (0.1 m and 2 deg off, from its seeded stream)."""
    from polar_sim.geometry import between2d, compose2d
    from polar_sim.runner.localise import noisy_odometry

    rng = np.random.default_rng(np.random.SeedSequence([seed, 777]))
    np.testing.assert_array_equal(noisy_odometry(truth, rng), odom)   # the saved odometry is the seeded one
    a = rng.uniform(-np.pi, np.pi)
    pose = truth[0] + np.array([0.1 * np.cos(a), 0.1 * np.sin(a), np.radians(2.0) * rng.choice([-1.0, 1.0])])
    err = []
    for i in range(len(truth)):
        if i:
            pose = compose2d(pose, between2d(odom[i - 1], odom[i]))
        dth = (pose[2] - truth[i, 2] + np.pi) % (2 * np.pi) - np.pi
        err.append((math.hypot(*(pose[:2] - truth[i, :2])), abs(np.degrees(dth))))
    return np.asarray(err)


def _check_dead_reckoning(out, row):
    z = RunContext(out, "quick", "dev").arrays(row)
    truth, odom, err = z["truth"], z["odom"], z["err"]
    assert err.shape == (len(truth), 2) and row["n_steps"] == len(truth) > 50
    np.testing.assert_allclose(err[0], [0.1, 2.0], rtol=0, atol=1e-9)     # the start offset, exactly
    np.testing.assert_allclose(err, _dead_reckoning_errors(truth, odom, row["seed"]), rtol=0, atol=1e-9)
    assert row["pos_median_m"] == pytest.approx(float(np.median(err[:, 0])), abs=1e-12)
    return err


# the README's command: `polar-sim run localisation --quick --set method=[..., my_localizer:...]`
# with the example folder on the path; one row per plug-in, each scored against truth
@pytest.mark.slow
def test_example_plugins_through_the_cli(tmp_path, monkeypatch):
    from polar_sim.cli import main

    monkeypatch.syspath_prepend(str(EXAMPLES))
    out = tmp_path / "run"
    rc = main(["run", "localisation", "--quick", "--split", "dev", "--out", str(out), "--set", f"method=[{DR},{ICP}]"])
    assert rc == 0
    with open(out / "results.csv", newline="") as fh:
        raw = list(csv.DictReader(fh))
    assert sorted(r["method"] for r in raw) == [DR, ICP] and all(r["status"] == "ok" for r in raw)
    res = run_experiment("localisation", quick=True, split="dev", out=out, progress=False,
                         overrides={"method": [DR, ICP]})          # resumes: nothing runs again
    rows = {r["method"]: r for r in res.table}
    assert len(res.table) == 2 and not res.failures
    err_dr = _check_dead_reckoning(out, rows[DR])
    ctx = RunContext(out, "quick", "dev")
    z = ctx.arrays(rows[ICP])
    err_icp = z["err"]
    assert err_icp.shape == err_dr.shape
    np.testing.assert_array_equal(z["truth"], ctx.arrays(rows[DR])["truth"])   # the same drive for both
    # scan matching against the map beats odometry alone on this drive
    assert np.median(err_icp[:, 0]) < np.median(err_dr[:, 0]) and err_icp[:, 0].max() < err_dr[:, 0].max()
    summary = (out / "summary.md").read_text()
    assert f"| {DR} |" in summary and f"| {ICP} |" in summary
    with open(out / "localisation.csv", newline="") as fh:
        assert sorted(r["method"] for r in csv.DictReader(fh)) == [DR, ICP]


# the other route: register_method in the user's own process, then method=<name>
@pytest.mark.slow
def test_registered_plugin(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLES))
    import my_localizer

    monkeypatch.setitem(_REGISTRY["localizer2d"], "mine_dr", None)      # restored (removed) after the test
    register_method("localizer2d", "mine_dr", my_localizer.DeadReckoning, description="odometry only", replace=True)
    res = run_experiment("localisation", quick=True, split="dev", out=tmp_path, progress=False,
                         overrides={"method": ["mine_dr"]})
    assert [r["method"] for r in res.table] == ["mine_dr"] and not res.failures
    _check_dead_reckoning(tmp_path, res.table[0])
