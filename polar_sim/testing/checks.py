"""Named checks: :func:`check_module` (after scikit-learn's ``check_estimator``) and
:func:`check_polar_env` (after gymnasium's ``check_env``)."""

from __future__ import annotations

import functools
import subprocess
import sys

import numpy as np

from polar_sim.testing.battery import run_battery
from polar_sim.testing.contract import Subject, module_checks
from polar_sim.testing.digest import flatten, output_digest, same_output
from polar_sim.testing.entries import _env_ids, _env_state, _make_env, _module_class, entry_points_of

__all__ = ["Check", "check_module", "check_entry_points", "check_polar_env", "env_ids"]


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


def check_module(obj, *, n_bad=None, isolate=True):
    """Named checks of a module instance (``check_module(GPISMap2D())``), as scikit-learn's
    ``check_estimator`` takes an estimator: the module contract that applies to the instance's
    tags (:mod:`polar_sim.testing.contract`, run on clones), then the hostile battery of each of
    its class's entry points.

    Yields :class:`Check` objects (``check.name``; call it to run it). ``n_bad`` hostile inputs per
    entry point (default 200, the full size); ``isolate`` runs them in a worker subprocess.
    """
    subject = Subject(obj)
    for cname, fn in module_checks(subject.tags):
        yield Check(f"{subject.name}:{cname}", functools.partial(fn, subject))
    cls = type(obj)
    path = f"{cls.__module__}:{cls.__qualname__}"
    n = 200 if n_bad is None else n_bad
    for entry in entry_points_of(subject.name if _module_class(subject.name) is cls else path):
        yield Check(f"{subject.name}:hostile[{entry}]", _hostile_check(entry, n, isolate))


def check_entry_points(name, *, n_bad=None, isolate=True):
    """The hostile battery of every entry point of ``name``: a module class's name, or a family
    of calls that is not a module (``"World"``, ``"Recording"``, ``"metrics.kitti_errors"``,
    ``"localize"``, ``"cli"``). Yields :class:`Check` objects."""
    n = 200 if n_bad is None else n_bad
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
        return flatten(out)
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
        assert same_output(_rollout(env_id, 7, n_steps), _rollout(env_id, 7, n_steps)), "same seed, different rollouts"

    def across_processes():
        code = (f"from polar_sim.testing.checks import _rollout; from polar_sim.testing.digest import output_digest; "
                f"print(output_digest(_rollout({env_id!r}, 7, {n_steps})))")
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, r.stderr[-2000:]
        assert r.stdout.strip().splitlines()[-1] == output_digest(_rollout(env_id, 7, n_steps)), \
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

