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
from pathlib import Path

import gymnasium as gym
import numpy as np
from tqdm.auto import tqdm

__all__ = ["evaluate", "load_policy", "RandomPolicy"]


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
    """A policy from ``"module:callable"`` (a class is instantiated without arguments), or
    ``"random"``. The result is called as ``policy(obs) -> action``."""
    if spec == "random":
        if env is None:
            raise ValueError("policy: 'random' needs the environment")
        return RandomPolicy(env.action_space)
    if not isinstance(spec, str) or ":" not in spec:
        raise ValueError(f"policy: expected 'module:callable' or 'random', got {spec!r}")
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
    env = gym.make(env_id, **(env_kwargs or {}))
    if isinstance(policy, str):
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
