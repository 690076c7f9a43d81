"""The battery itself: it finds what it must (a crash, a hang, a state change, a silent accept, a
wrong exception type) and passes a well-behaved module; bad-input generation is seeded."""

import functools
import os
from pathlib import Path

import numpy as np
import pytest

from polar_sim.testing import bad_inputs, generate, run_battery, state_digest

HERE = Path(__file__).resolve().parent


@pytest.fixture
def dummies(monkeypatch):
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")]))
    monkeypatch.syspath_prepend(str(HERE))


# A module that validates through _validation gets only clear or graceful outcomes.
def test_good_module_is_clean(dummies):
    res = run_battery("battery_dummies:good", n=40, isolate=False)
    assert res.ok and res.counts["clear"] > 20, res.report()


# Each kind of failure is found and attributed to the input that caused it, in a worker process.
@pytest.mark.parametrize("mode, outcome", [("crash", "crash"), ("hang", "hang"), ("state", "state"),
                                           ("silent", "accepted"), ("keyerror", "unclear")])
def test_failures_are_found(dummies, mode, outcome):
    res = run_battery(f"battery_dummies:{mode}", n=30, isolate=True, timeout=5.0, setup_timeout=120)
    assert res.n == 30 and res.counts[outcome] >= 1, res.report()
    labels = {f[2] for f in res.failures if f[3] == outcome}
    expected = {"crash": {"empty"}, "hang": {"str", "numeric-str"}, "keyerror": {"None"}}.get(mode)
    if expected:
        assert labels == expected, res.report()


# The same seed generates the same hostile inputs (a worker regenerates them); another seed differs.
def test_generation_is_seeded(dummies, tmp_path):
    import battery_dummies

    ep = battery_dummies.good()
    a = generate(ep, None, str(tmp_path), 60, seed=1)
    b = generate(ep, None, str(tmp_path), 60, seed=1)
    c = generate(ep, None, str(tmp_path), 60, seed=2)
    digest = lambda cases: state_digest([(x.label, x.value) for x in cases])  # noqa: E731
    assert digest(a) == digest(b) != digest(c)
    assert len({x.label for x in a}) >= 25


# The generated families cover the issue's list for an array argument.
def test_families_cover_the_issue():
    labels = {b.label for b in bad_inputs("points", np.ones((4, 3)), "p", np.random.default_rng(0))}
    for want in ("dtype:int", "dtype:bool", "dtype:complex", "dtype:object-None", "dtype:str", "nan", "inf", "empty",
                 "1e300", "None", "shape:transposed", "shape:shorter"):
        assert want in labels
    poses = {b.label for b in bad_inputs("pose", np.eye(4), "T", np.random.default_rng(0))}
    assert {"pose:scaled", "pose:sheared", "pose:reflected", "nan"} <= poses


# The state digest sees every change of an array, a generator or a nested attribute.
def test_state_digest():
    class A:
        pass

    a = A()
    a.x, a.rng, a.d = np.zeros(3), np.random.default_rng(0), {"k": [1, 2]}
    d0 = state_digest(a)
    a.x[1] = 1e-300
    d1 = state_digest(a)
    a.rng.random()
    d2 = state_digest(a)
    a.d["k"].append(3)
    assert len({d0, d1, d2, state_digest(a)}) == 4


# --- the module contract's checks can fail: a tiny module (battery_dummies.Sum), sound or with one flaw ---
def _sum_checks(cls_name, flaw):
    import battery_dummies

    from polar_sim.testing.contract import Subject, module_checks

    s = Subject(getattr(battery_dummies, cls_name)(scale=2.0, flaw=flaw))
    return {name: functools.partial(fn, s) for name, fn in module_checks(s.tags)}


def test_a_sound_module_passes_every_check(dummies):
    checks = _sum_checks("Sum", None)
    assert len(checks) == 10
    for fn in checks.values():
        fn()


@pytest.mark.parametrize("cls, flaw, check", [
    ("Sum", "params", "builds_and_stores_params"), ("EagerSum", None, "no_learned_state_before_update"),
    ("Sum", "query_before", "query_before_update_raises"), ("Sum", "impure", "query_is_pure"),
    ("Sum", "alias", "outputs_do_not_alias_inputs"), ("Sum", "seed", "same_seed_same_output"),
    ("Sum", "process", "same_output_across_processes"), ("Sum", "reset", "reset_then_replay"),
    ("Sum", "copy", "deep_copies"), ("Sum", "pickle", "saves_without_pickle")])
def test_each_module_check_finds_its_flaw(dummies, cls, flaw, check):
    with pytest.raises(AssertionError):
        _sum_checks(cls, flaw)[check]()


# check_module takes an instance, never a name or a class.
@pytest.mark.parametrize("bad", ["GPISMap2D", int, object()])
def test_check_module_takes_an_instance(bad):
    from polar_sim.testing import check_module

    with pytest.raises(TypeError, match="obj"):
        next(check_module(bad))


# --- entry points derived from a class's signature and TAGS -------------------------------------------
# Kinds come from the naming convention, else from the valid value; the derived list covers the
# constructor, the per-frame method, the query and save/load, and nothing is hand-written.
def test_entry_points_are_derived():
    from polar_sim.testing import ENTRY_POINTS, entry_points_of

    assert entry_points_of("GPISMap2D") == ["GPISMap2D", "GPISMap2D.update", "GPISMap2D.query", "GPISMap2D.save",
                                            "GPISMap2D.load"]
    assert entry_points_of("OccupancyGrid2D") == ["OccupancyGrid2D", "OccupancyGrid2D.update",
                                                  "OccupancyGrid2D.probability"]
    assert ENTRY_POINTS["GPISMap3D.update"]().kinds == {"depth": "depth", "K": "K", "T_world_cam": "pose"}
    assert ENTRY_POINTS["ICPLocalizer.localize"]().kinds == {"scan": "scan2d", "initial_pose": "pose2d"}
    kinds = ENTRY_POINTS["GroundVO"]().kinds
    assert kinds["camera_height"] == "float+" and kinds["seed"] == "seed" and kinds["model"] == "choice"
    assert kinds["tracking"] == "object"


# A class outside MODULE_CLASSES is reached by its path, also in a worker process; the derived
# constructor battery finds the parameters the class never checks (scale meets x in update; seed is unused).
def test_derived_battery_of_an_unregistered_class(dummies):
    from polar_sim.testing import entry_points_of

    assert entry_points_of("battery_dummies:Sum") == [   # update(x): nothing to attack
        "battery_dummies:Sum", "battery_dummies:Sum.save", "battery_dummies:Sum.load"]   # value(): no arguments
    res = run_battery("battery_dummies:Sum", n=20, isolate=True, setup_timeout=120)
    assert res.n == 20 and not res.ok
    assert {f[1] for f in res.failures} == {"scale", "seed"}, res.report()   # seed: never read
