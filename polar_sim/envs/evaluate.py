"""Closed-loop evaluation: run a policy for N episodes, score each against the truth in
``info``, and write per-episode metrics and a summary.

Episodes use seeds ``seed, seed + 1, ...``; the default 10_000 keeps evaluation seeds apart from
the low seeds training scripts usually take.
"""

from __future__ import annotations

import csv
import importlib
import inspect
import json
import numbers
import os
from pathlib import Path

import gymnasium as gym
import numpy as np
from tqdm.auto import tqdm

__all__ = ["evaluate", "load_policy", "policy_env_kwargs", "RandomPolicy"]


class RandomPolicy:
    """Uniform random actions from the environment's action space (seeded)."""

    def __init__(self, action_space, seed=0):
        self.space = action_space
        self.space.seed(seed)

    def reset(self):
        pass

    def __call__(self, obs):
        return self.space.sample()


def load_policy(spec, env=None):
    """The one way to get a policy: a callable ``policy(obs) -> action`` with ``reset()``.

    ``spec`` is one of

    - ``"random"``: uniform random actions of ``env``'s action space (seeded 0);
    - ``"pretrained"``: the policy shipped for ``env``'s id (:func:`polar_sim.envs.pretrained`);
    - a path to a policy file (``.npz``, :mod:`polar_sim.envs.policy_file`): a numpy MLP policy,
      or an SB3 policy (needs torch and stable-baselines3);
    - ``"module:callable"``: a class (instantiated without arguments) or a callable.

    With ``env``, a policy file is checked against its observation space (``ValueError`` naming
    the key that does not match).
    """
    if spec == "random":
        if env is None:
            raise ValueError("policy: 'random' needs the environment")
        return RandomPolicy(env.action_space)
    if spec == "pretrained":
        from polar_sim.envs.shipped import pretrained

        if env is None or env.spec is None:
            raise ValueError("policy: 'pretrained' needs an environment made by gym.make (its id picks the policy)")
        policy = pretrained(env.spec.id)
        policy.check_env(env)
        return policy
    if isinstance(spec, os.PathLike) or (isinstance(spec, str) and spec.endswith(".npz")):
        return _load_file(spec, env)
    if not isinstance(spec, str) or ":" not in spec:
        raise ValueError(f"policy: expected 'random', 'pretrained', a .npz policy file or 'module:callable', "
                         f"got {spec!r}")
    mod_name, attr = spec.split(":", 1)
    try:
        obj = getattr(importlib.import_module(mod_name), attr)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"policy: cannot load {spec!r}: {exc}") from exc
    if inspect.isclass(obj):
        obj = obj()
    if not callable(obj):
        raise ValueError(f"policy: {spec!r} is not callable")
    return obj


def _load_file(path, env):
    from polar_sim.envs.policy_file import read_policy_file

    meta, _ = read_policy_file(path, "policy")
    if meta["kind"] in ("mlp", "mapcnn"):
        from polar_sim.envs.shipped import load_numpy_policy

        return load_numpy_policy(path, env, name="policy")
    if env is None:
        raise ValueError("policy: an SB3 policy file needs the environment to rebuild its network")
    from polar_sim.envs.learning import SB3Policy, load_model

    model, norm, meta = load_model(path, env, name="policy")
    return SB3Policy(model, norm, meta["recipe"], meta.get("env_id"), meta.get("env_kwargs"))


def policy_env_kwargs(spec, env_id):
    """The ``gym.make`` arguments a policy ``spec`` was made for (``"pretrained"`` or a policy
    file; ``{}`` otherwise), so that it is scored on the observation it reads."""
    if spec == "pretrained":
        from polar_sim.envs.shipped import pretrained

        return dict(pretrained(env_id).env_kwargs)
    if isinstance(spec, os.PathLike) or (isinstance(spec, str) and spec.endswith(".npz")):
        from polar_sim.envs.policy_file import read_policy_file

        return dict(read_policy_file(spec, "policy")[0].get("env_kwargs") or {})
    return dict(getattr(spec, "env_kwargs", None) or {})


def _act(policy, obs):
    """``policy(obs)``; a callable that cannot be called so (``os:getcwd``, say) is named."""
    try:
        return policy(obs)
    except TypeError as exc:
        raise TypeError(f"policy: {policy!r} cannot be called as policy(obs) -> action ({exc})") from exc


def _scalar_info(info):
    out = {}
    for k, v in info.items():
        if isinstance(v, (bool, np.bool_)):
            out[k] = bool(v)
        elif isinstance(v, numbers.Real):
            out[k] = float(v)
    return out


def evaluate(env_id, policy, *, episodes=10, seed=10_000, env_kwargs=None, out_dir=None, progress=True):
    """Run ``policy`` for ``episodes`` episodes of ``env_id``.

    Returns ``(rows, summary)``: one dict per episode (seed, return, length, truncated, and the
    scalar entries of the final ``info``, e.g. ``is_success``) and a dict of means. With
    ``out_dir``, writes ``episodes.csv``, ``summary.json`` and ``summary.md`` there.
    """
    env_kwargs = {**policy_env_kwargs(policy, env_id), **(env_kwargs or {})}
    env = gym.make(env_id, **env_kwargs)
    if isinstance(policy, (str, os.PathLike)):
        policy = load_policy(policy, env)
    rows = []
    try:
        for i in tqdm(range(int(episodes)), desc=env_id, unit="episode", disable=not progress):
            obs, info = env.reset(seed=int(seed) + i)
            if hasattr(policy, "reset"):
                policy.reset()
            ret, n, terminated, truncated = 0.0, 0, False, False
            while not (terminated or truncated):
                obs, r, terminated, truncated, info = env.step(_act(policy, obs))
                ret += r
                n += 1
            row = {"episode": i, "seed": int(seed) + i, "return": ret, "length": n, "truncated": bool(truncated)}
            row.update(_scalar_info(info))
            rows.append(row)
    finally:
        env.close()
    keys = [k for k in rows[0] if k != "episode" and not k.endswith("seed")]
    summary = {"env_id": env_id, "episodes": len(rows), "seed": int(seed),
               **{f"mean_{k}": float(np.mean([float(r.get(k, np.nan)) for r in rows])) for k in keys}}
    if "is_success" in rows[0]:
        summary["success_rate"] = summary.pop("mean_is_success")
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        fields = list(dict.fromkeys(k for r in rows for k in r))
        with open(out / "episodes.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=fields)
            w.writeheader()
            w.writerows(rows)
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
        lines = [f"# {env_id}: {len(rows)} episodes", "", "| metric | value |", "|---|---|"]
        lines += [f"| {k} | {v:.4g} |" if isinstance(v, float) else f"| {k} | {v} |" for k, v in summary.items()]
        (out / "summary.md").write_text("\n".join(lines) + "\n")
    return rows, summary
