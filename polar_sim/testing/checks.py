"""Named checks: :func:`check_module` (after scikit-learn's ``check_estimator``) and
:func:`check_polar_env` (after gymnasium's ``check_env``)."""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from collections.abc import Callable

import numpy as np

from polar_sim.testing.battery import run_battery
from polar_sim.testing.digest import state_digest
from polar_sim.testing.entries import (_cached, _depth_plane, _env_ids, _env_state, _make_env, _scan_circle,
                                       _track_sequence, _vo_sequence, entry_points_of)

__all__ = ["ModuleCase", "MODULES", "Check", "check_module", "check_polar_env", "env_ids"]



@dataclasses.dataclass
class ModuleCase:
    """How to exercise one module class with valid data.

    ``build(**params)`` makes an instance (``params`` are the documented constructor arguments
    that must come back from ``get_params()``); ``frames()`` gives the per-frame calls as a list
    of positional-argument tuples for ``method``; ``query`` is ``(method name, args tuple)`` or
    None; ``seed_param`` names the random-state parameter, if any; ``outputs(result)`` turns a
    per-frame result into arrays to compare bit for bit.
    """

    name: str
    build: Callable
    params: dict
    frames: Callable
    method: str
    query: tuple | None = None
    seed_param: str | None = None
    outputs: Callable = dataclasses.field(default=lambda r: r)
    savable: bool = False


#: Result fields that measure wall time, not output: left out of "same output" comparisons.
TIMING_FIELDS = frozenset({"time_s", "stage_times", "timings", "timing", "elapsed", "elapsed_s", "seconds",
                           "cpu_s", "wall_s", "times_s", "runtime_s"})


def _flatten(x, out=None):
    """Arrays and scalars of a result, in a fixed order, for bit-identical comparisons (timing
    fields, :data:`TIMING_FIELDS`, left out)."""
    out = [] if out is None else out
    if isinstance(x, np.ndarray):
        out.append(x)
    elif isinstance(x, (int, float, bool, str, np.generic)) or x is None:
        out.append(np.asarray(x if x is not None else np.nan))
    elif isinstance(x, dict):
        for k in sorted(x, key=repr):
            if k not in TIMING_FIELDS:
                _flatten(x[k], out)
    elif isinstance(x, (list, tuple)):
        for e in x:
            _flatten(e, out)
    elif dataclasses.is_dataclass(x):
        for f in dataclasses.fields(x):
            if f.name not in TIMING_FIELDS:
                _flatten(getattr(x, f.name), out)
    elif hasattr(x, "__dict__"):
        for k in sorted(vars(x)):
            if k not in TIMING_FIELDS:
                _flatten(getattr(x, k), out)
    return out


def _digest(x):
    """SHA-256 of a result's flattened arrays (dtype, shape, bytes; timing fields left out): what
    a subprocess prints so that its result is compared bit for bit without pickling it."""
    h = hashlib.sha256()
    for a in _flatten(x):
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes() if a.dtype.kind not in "OUS" else repr(a.tolist()).encode())
    return h.hexdigest()


def _same(a, b):
    fa, fb = _flatten(a), _flatten(b)
    if len(fa) != len(fb):
        return False
    for x, y in zip(fa, fb):
        x, y = np.asarray(x), np.asarray(y)
        if x.shape != y.shape or x.dtype != y.dtype:
            return False
        if x.dtype.kind in "fc":
            if not np.array_equal(x, y, equal_nan=True):
                return False
        elif not np.array_equal(x, y):
            return False
    return True


def _mod_gpis2d():
    from polar_sim.gpis import GPISMap2D

    def frames():
        out = []
        for k in range(3):
            pose = np.array([0.1 * k, 0.05 * k, 0.1 * k])
            a, r = _scan_circle(pose=pose)
            out.append((a, r, pose))
        return out

    return ModuleCase("GPISMap2D", build=lambda **p: GPISMap2D().set_params(**p),
                      params={"local_gp__map_scale": 1.1, "observation__obs_var_thre": 0.1},
                      frames=frames, method="update", query=("query", (np.array([[0.5, 0.5], [2.0, -1.0]]),)),
                      savable=True)


def _mod_gpis3d():
    from polar_sim.gpis import GPISMap3D

    def frames():
        out = []
        for k in range(2):
            depth, K = _depth_plane(z=1.0 + 0.05 * k)
            T = np.eye(4)
            T[:3, 3] = [0.01 * k, 0.0, 0.0]
            out.append((depth, K, T))
        return out

    return ModuleCase("GPISMap3D", build=lambda **p: GPISMap3D().set_params(**p), params={"local_gp__map_scale": 0.05},
                      frames=frames,
                      method="update", query=("query", (np.array([[0.0, 0.0, 0.9], [0.05, 0.0, 1.0]]),)), savable=True)


def _mod_groundvo():
    from polar_sim.ground import GroundVO

    s = _cached("vo", _vo_sequence)
    return ModuleCase("GroundVO", build=lambda **p: GroundVO(s["K"], s["camera_height"], **p),
                      params={"model": "6param", "sampling": "weighted", "seed": 3},
                      frames=lambda: [(s["rgb"][i], float(s["times"][i])) for i in range(len(s["rgb"]))],
                      method="process", seed_param="seed")


def _mod_tracker():
    from polar_sim.tracking import ObjectTracker

    seq, pts, nrm, frames = _cached("trk", _track_sequence)
    return ModuleCase("ObjectTracker", build=lambda **p: ObjectTracker(pts, seq.K, seq.poses[0], model_normals=nrm, **p),
                      params={"appearance": "ww", "random_state": 3},
                      frames=lambda: [(f["rgb"], f["depth"], i / 30) for i, f in enumerate(frames)],
                      method="process", seed_param="random_state")


#: module name -> builder of its :class:`ModuleCase`.
MODULES: dict[str, Callable[[], ModuleCase]] = {
    "GPISMap2D": _mod_gpis2d, "GPISMap3D": _mod_gpis3d, "GroundVO": _mod_groundvo, "ObjectTracker": _mod_tracker,
}


class Check:
    """A named check: calling it runs the check and raises ``AssertionError`` on a failure."""

    def __init__(self, name, fn):
        self.name = name
        self._fn = fn

    def __call__(self):
        return self._fn()

    def __repr__(self):
        return f"Check({self.name!r})"


def _hostile_check(entry, n, isolate):
    def run():
        res = run_battery(entry, n=n, isolate=isolate)
        assert res.ok, res.report()
    return run


class _Subject:
    """One module under check: its case (built once, cached), fresh instances and fed frames."""

    def __init__(self, name, case_builder):
        self.name, self._builder = name, case_builder

    def case(self) -> ModuleCase:
        return _cached(("case", self.name), self._builder)

    def fresh(self, **extra):
        c = self.case()
        return c.build(**{**c.params, **extra})

    def feed(self, m, frames=None):
        c = self.case()
        return [getattr(m, c.method)(*f) for f in (frames if frames is not None else c.frames())]

    def query(self, m, args=None):
        q = self.case().query
        return getattr(m, q[0])(*(q[1] if args is None else args))


def _learned(m):
    """The instance's learned attributes (scikit-learn's trailing underscore)."""
    return [k for k in vars(m) if k.endswith("_") and not k.startswith("__")]


def _check_params_stored(s):
    c, m = s.case(), s.fresh()
    assert hasattr(m, "get_params"), f"{s.name} has no get_params()"
    got = m.get_params()
    for k, v in c.params.items():
        assert k in got and got[k] == v, f"get_params()[{k!r}] = {got.get(k)!r}, expected {v!r}"
    if hasattr(m, "set_params"):
        m.set_params(**c.params)


def _check_no_state_before_update(s):
    learned = _learned(s.fresh())
    assert not learned, f"learned attributes before the first {s.case().method}(): {learned}"


def _check_query_before_update(s):
    c = s.case()
    if c.query is None:
        return
    from polar_sim.errors import NotUpdatedError

    try:
        s.query(s.fresh())
    except NotUpdatedError:
        return
    raise AssertionError(f"{c.query[0]}() before any {c.method}() did not raise NotUpdatedError")


def _check_query_pure(s):
    c = s.case()
    if c.query is None:
        return
    m = s.fresh()
    s.feed(m)
    ignore = ("_kd_tree", "_kd_idx", "_kd_version")  # a lazily built search index is a cache, not state
    before = state_digest(m, ignore=ignore)
    args = tuple(np.array(a, copy=True) for a in c.query[1])
    out = s.query(m, args)
    assert state_digest(m, ignore=ignore) == before, f"{c.query[0]}() changed the state"
    for o in _flatten(out):
        for a in args:
            assert not np.shares_memory(o, a), f"{c.query[0]}() output shares memory with its input"


def _check_outputs_do_not_alias_inputs(s):
    m, method = s.fresh(), s.case().method
    for f in s.case().frames():
        for o in _flatten(getattr(m, method)(*f)):
            for a in f:
                if isinstance(a, np.ndarray) and isinstance(o, np.ndarray) and o.size > 1:
                    assert not np.shares_memory(o, a), f"{method}() output shares memory with an input"


def _check_same_seed_same_output(s):
    a, b = s.fresh(), s.fresh()
    assert _same(s.feed(a), s.feed(b)), "two instances with the same parameters and data gave different outputs"
    if s.case().query is not None:
        assert _same(s.query(a), s.query(b)), "queries differ"


def _check_across_processes(s):
    code = (f"from polar_sim.testing.checks import _digest, _module_outputs; "
            f"print(_digest(_module_outputs({s.name!r})))")
    outs = []
    for _ in range(2):
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                           env=dict(os.environ, PYTHONHASHSEED="random"), check=False)
        assert r.returncode == 0, r.stderr[-2000:]
        outs.append(r.stdout.strip().splitlines()[-1])
    assert outs[0] == outs[1], "two processes gave different outputs for the same seed and data"
    assert outs[0] == _digest(_module_outputs(s.name)), "a subprocess and this process gave different outputs"


def _check_reset_replay(s):
    m = s.fresh()
    s.feed(m)
    assert hasattr(m, "reset"), f"{s.name} has no reset()"
    m.reset()
    learned = _learned(m)
    assert not learned, f"reset() kept learned attributes {learned}"
    assert _same(s.feed(m), s.feed(s.fresh())), "reset() then replay differs from a fresh instance"


def _check_copies(s):
    """A deep copy taken mid-sequence is independent and equal: both continue the sequence alike
    (this holds for modules without a query too), and feeding the copy leaves the original as it was."""
    frames = s.case().frames()
    half = max(1, len(frames) // 2)
    m = s.fresh()
    s.feed(m, frames[:half])
    m2 = copy.deepcopy(m)
    before = state_digest(m)
    rest2 = s.feed(m2, frames[half:])
    assert state_digest(m) == before, "feeding the deep copy changed the original"
    assert _same(s.feed(m, frames[half:]), rest2), "the original and its deep copy continue differently"
    if s.case().query is not None:
        assert _same(s.query(m), s.query(m2)), "the original and its deep copy answer differently"


def _check_saves_without_pickle(s):
    c = s.case()
    if not c.savable:
        return
    m = s.fresh()
    s.feed(m)
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "m.npz"
        m.save(p)
        with np.load(p, allow_pickle=False) as z:
            for k in z.files:
                z[k]
        m2 = type(m).load(p)
        assert _same(s.query(m), s.query(m2)), "round trip differs"
        assert [q.name for q in Path(d).iterdir()] == ["m.npz"], "save() left stray files"


#: The contract every module class is held to, in order: (check name, check(subject)).
_MODULE_CHECKS = [("builds_and_stores_params", _check_params_stored),
                  ("no_learned_state_before_update", _check_no_state_before_update),
                  ("query_before_update_raises", _check_query_before_update), ("query_is_pure", _check_query_pure),
                  ("outputs_do_not_alias_inputs", _check_outputs_do_not_alias_inputs),
                  ("same_seed_same_output", _check_same_seed_same_output),
                  ("same_output_across_processes", _check_across_processes),
                  ("reset_then_replay", _check_reset_replay), ("deep_copies", _check_copies),
                  ("saves_without_pickle", _check_saves_without_pickle)]


def _module_contract_checks(name, case_builder):
    subject = _Subject(name, case_builder)
    return [(cname, functools.partial(fn, subject)) for cname, fn in _MODULE_CHECKS]


def _module_outputs(name):
    c = MODULES[name]()
    m = c.build(**c.params)
    out = [getattr(m, c.method)(*f) for f in c.frames()]
    if c.query is not None:
        out.append(getattr(m, c.query[0])(*c.query[1]))
    return _flatten(out)


def check_module(obj_or_factory, *, n_bad=None, isolate=True):
    """Named checks of a module (a name from :data:`MODULES`, a :class:`ModuleCase`, or an entry
    point family such as ``"metrics.kitti_errors"``, ``"World"``, ``"Recording"``, ``"cli"``).

    Yields :class:`Check` objects (``check.name``; call it to run it). ``n_bad`` hostile inputs per
    entry point (default 200, the full size); ``isolate`` runs them in a worker subprocess.
    """
    n = 200 if n_bad is None else n_bad
    if isinstance(obj_or_factory, ModuleCase):
        name, builder = obj_or_factory.name, (lambda c=obj_or_factory: c)
    else:
        name = obj_or_factory if isinstance(obj_or_factory, str) else getattr(obj_or_factory, "__name__", str(obj_or_factory))
        builder = MODULES.get(name)
    if builder is not None:
        for cname, fn in _module_contract_checks(name, builder):
            yield Check(f"{name}:{cname}", fn)
    for entry in entry_points_of(name):
        yield Check(f"{name}:hostile[{entry}]", _hostile_check(entry, n, isolate))



def _rollout(env_id, seed, n_steps, kwargs=None):
    """Observations, rewards and truth of ``n_steps`` mid-range actions after ``reset(seed)``."""
    env = _make_env(env_id, **(kwargs or {}))
    try:
        obs, info = env.reset(seed=seed)
        out = [obs, _truth_of(info)]
        sp = env.action_space
        env.action_space.seed(seed)
        for _ in range(n_steps):
            a = sp.sample()
            obs, r, term, trunc, info = env.step(a)
            out += [obs, float(r), bool(term), bool(trunc), _truth_of(info)]
            if term or trunc:
                obs, info = env.reset()
                out += [obs, _truth_of(info)]
        return _flatten(out)
    finally:
        env.close()


def _truth_of(info):
    return {k: v for k, v in info.items() if isinstance(v, (np.ndarray, float, int, bool, np.generic, dict, list, tuple))}


def check_polar_env(env_id, *, n_steps=5, n_bad=None, isolate=True):
    """Named checks of a registered env id; yields :class:`Check` objects."""
    n = 200 if n_bad is None else n_bad

    def gym_check_env():
        from gymnasium.utils.env_checker import check_env

        env = _make_env(env_id)
        try:
            check_env(env.unwrapped, skip_render_check=True)
        finally:
            env.close()

    def seeded_reset():
        assert _same(_rollout(env_id, 7, n_steps), _rollout(env_id, 7, n_steps)), "same seed, different rollouts"

    def across_processes():
        code = (f"from polar_sim.testing.checks import _digest, _rollout; "
                f"print(_digest(_rollout({env_id!r}, 7, {n_steps})))")
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, r.stderr[-2000:]
        assert r.stdout.strip().splitlines()[-1] == _digest(_rollout(env_id, 7, n_steps)), \
            "a subprocess gave a different rollout"

    def obs_in_space():
        env = _make_env(env_id)
        try:
            obs, info = env.reset(seed=3)
            assert env.observation_space.contains(obs), "reset() observation outside observation_space"
            for _ in range(n_steps):
                obs, r, term, trunc, info = env.step(env.action_space.sample())
                assert env.observation_space.contains(obs), "step() observation outside observation_space"
                assert np.isfinite(r), f"reward {r} is not finite"
                if term or trunc:
                    env.reset()
        finally:
            env.close()

    def truth_in_info():
        env = _make_env(env_id)
        try:
            _, info = env.reset(seed=3)
            assert isinstance(info, dict) and info, "reset() info holds no truth"
            _, _, _, _, info = env.step(env.action_space.sample())
            assert isinstance(info, dict) and info, "step() info holds no truth"
        finally:
            env.close()

    def double_close():
        env = _make_env(env_id)
        env.reset(seed=0)
        env.close()
        env.close()

    def rejected_step_keeps_state():
        env = _make_env(env_id)
        try:
            env.reset(seed=0)
            sp = env.action_space
            if not hasattr(sp, "high"):
                return
            before = _env_state(env)
            # a value just above the bound, as in issue 17 (finding 5)
            bad = (sp.high.astype(np.float64) * (1 + 1e-7) + 1e-7).astype(sp.dtype)
            for a in (bad, np.full(sp.shape, np.nan, sp.dtype), (sp.high * 2).astype(sp.dtype)):
                try:
                    env.step(a)
                except (ValueError, TypeError):
                    assert _env_state(env) == before, f"step({a!r}) was refused but changed the env"
                else:
                    return   # accepted (clipped); the hostile battery judges that
        finally:
            env.close()

    checks = [("check_env", gym_check_env), ("seeded_reset_determinism", seeded_reset),
              ("same_rollout_across_processes", across_processes), ("observations_in_space", obs_in_space),
              ("truth_in_info", truth_in_info), ("double_close", double_close),
              ("rejected_step_keeps_state", rejected_step_keeps_state)]
    for cname, fn in checks:
        yield Check(f"{env_id}:{cname}", fn)
    for entry in entry_points_of(env_id):
        yield Check(f"{env_id}:hostile[{entry}]", _hostile_check(entry, n, isolate))


def env_ids():
    """The registered polar_sim env ids."""
    return _env_ids()

