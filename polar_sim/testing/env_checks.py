"""The env checks of :func:`~polar_sim.testing.check_polar_env` (after gymnasium's ``check_env``):
each takes an env id and the number of steps to roll out, and raises ``AssertionError`` on a failure."""

from __future__ import annotations

import contextlib
import subprocess
import sys

import numpy as np

from polar_sim.testing.digest import flatten, output_digest, same_output
from polar_sim.testing.entries import _env_state, _make_env

__all__ = ["ENV_CHECKS"]


@contextlib.contextmanager
def _env(env_id, seed=None, **kwargs):
    """A made env, reset with ``seed`` if given, closed on the way out."""
    env = _make_env(env_id, **kwargs)
    try:
        if seed is not None:
            env.reset(seed=seed)
        yield env
    finally:
        env.close()


def _truth_of(info):
    return {k: v for k, v in info.items() if isinstance(v, (np.ndarray, float, int, bool, np.generic, dict, list, tuple))}


def rollout(env_id, seed, n_steps, kwargs=None):
    """Observations, rewards and truth of ``n_steps`` sampled actions after ``reset(seed)``."""
    with _env(env_id, **(kwargs or {})) as env:
        obs, info = env.reset(seed=seed)
        out = [obs, _truth_of(info)]
        env.action_space.seed(seed)
        for _ in range(n_steps):
            obs, r, term, trunc, info = env.step(env.action_space.sample())
            out += [obs, float(r), bool(term), bool(trunc), _truth_of(info)]
            if term or trunc:
                obs, info = env.reset()
                out += [obs, _truth_of(info)]
        return flatten(out)


def check_gym_env(env_id, n_steps):
    from gymnasium.utils.env_checker import check_env

    with _env(env_id) as env:
        check_env(env.unwrapped, skip_render_check=True)


def check_seeded_reset(env_id, n_steps):
    assert same_output(rollout(env_id, 7, n_steps), rollout(env_id, 7, n_steps)), "same seed, different rollouts"


def check_across_processes(env_id, n_steps):
    code = (f"from polar_sim.testing.env_checks import rollout; from polar_sim.testing.digest import output_digest; "
            f"print(output_digest(rollout({env_id!r}, 7, {n_steps})))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip().splitlines()[-1] == output_digest(rollout(env_id, 7, n_steps)), \
        "a subprocess gave a different rollout"


def check_obs_in_space(env_id, n_steps):
    with _env(env_id) as env:
        obs, info = env.reset(seed=3)
        assert env.observation_space.contains(obs), "reset() observation outside observation_space"
        for _ in range(n_steps):
            obs, r, term, trunc, info = env.step(env.action_space.sample())
            assert env.observation_space.contains(obs), "step() observation outside observation_space"
            assert np.isfinite(r), f"reward {r} is not finite"
            if term or trunc:
                env.reset()


def check_truth_in_info(env_id, n_steps):
    with _env(env_id) as env:
        _, info = env.reset(seed=3)
        assert isinstance(info, dict) and info, "reset() info holds no truth"
        _, _, _, _, info = env.step(env.action_space.sample())
        assert isinstance(info, dict) and info, "step() info holds no truth"


def check_double_close(env_id, n_steps):
    env = _make_env(env_id)
    env.reset(seed=0)
    env.close()
    env.close()


def check_rejected_step_keeps_state(env_id, n_steps):
    with _env(env_id, seed=0) as env:
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


#: The env contract, in order: (check name, check(env_id, n_steps)).
ENV_CHECKS = [("check_env", check_gym_env), ("seeded_reset_determinism", check_seeded_reset),
              ("same_rollout_across_processes", check_across_processes), ("observations_in_space", check_obs_in_space),
              ("truth_in_info", check_truth_in_info), ("double_close", check_double_close),
              ("rejected_step_keeps_state", check_rejected_step_keeps_state)]
