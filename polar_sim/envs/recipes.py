"""Training recipes by name, one command each: ``train("dagger", "polar_sim/GPISNav-Room-v1")``.

A recipe is a name and a dict of parameters with documented defaults (:data:`RECIPES`);
:func:`check_recipe` refuses an unknown name, an unknown parameter or a bad value with a
``ValueError`` before anything is built. :func:`train` runs it on dev-split worlds only (training
episodes draw seeds 0-999, the learning curve scores dev worlds 1000, 1001, ...; the held-out
worlds, seeds >= 10,000, are left to :func:`polar_sim.envs.evaluate.evaluate`), shows a tqdm bar
over the environment steps (stderr; off with ``progress=False`` or when stderr is not a terminal),
and writes ``policy.npz``, ``curve.csv`` and ``summary.json`` to ``out``.

| recipe | what | policy file |
|---|---|---|
| ``dagger`` | behaviour cloning + DAgger rounds from a scripted expert (:mod:`polar_sim.envs.imitation`) | numpy MLP |
| ``dagger_map`` | DAgger of ``SDFNavigator`` for a learner with a map memory (:mod:`polar_sim.envs.imitation_map`) | numpy map CNN |
| ``dagger_ppo`` | ``dagger`` (or ``init_policy``: a policy file, ``"pretrained"``), then PPO fine-tuning from its weights (critic warm-up first) | numpy MLP |
| ``ppo`` | PPO from scratch, masked-stencil MLP (or ``obs_mode="grid"``: the grid CNN) | SB3 (``far_unknown: false``: numpy MLP) |
| ``recurrent_ppo`` | sb3-contrib RecurrentPPO, an LSTM policy on the masked stencil | SB3 |
| ``sac``, ``tqc`` | off-policy SAC (SB3) / TQC (sb3-contrib) on the masked stencil | SB3 |

The RL recipes train with ``train_pose_source`` and ``train_sdf_source`` (default: the true pose and
the exact SDF, the cheapest steps) and are scored in the default slam mode; the masked stencil with
``far_unknown`` (:mod:`polar_sim.envs.far_mask`) reads far free space alike in both, and the two
differ only near surfaces the online map has not seen yet.


Torch, stable-baselines3 and sb3-contrib are needed to train (the ``[test]`` extra), not to act.
"""

from __future__ import annotations

import copy
import csv
import json
import time
from pathlib import Path

import numpy as np

from polar_sim._validation import as_bool, as_float, as_int, check_choice

__all__ = ["RECIPES", "check_recipe", "train", "LEARNING_ENV_IDS", "DEV_SEED"]

#: The env ids a recipe trains on: the GPISNav tiers, v2 (the kinematic rover, faster) and v1.
LEARNING_ENV_IDS = ("polar_sim/GPISNav-Room-v2", "polar_sim/GPISNav-Rooms2-v2", "polar_sim/GPISNav-v2",
                    "polar_sim/GPISNav-Room-v1", "polar_sim/GPISNav-Rooms2-v1", "polar_sim/GPISNav-v1")
DEV_SEED = 1000
STENCIL_KEYS = ["goal", "sdf", "sdf_grad", "twist"]
MASKED_KEYS = ["goal", "sdf", "sdf_grad", "sdf_var", "twist"]

_COMMON = {"train_pose_source": "truth", "env_kwargs": {}, "eval_every": 0, "eval_episodes": 20}
_DAGGER = {"train_pose_source": "slam", "expert": "reactive", "rounds": 4, "steps_per_round": 5000, "beta_decay": 0.5, "hidden": [256, 256],
           "activation": "tanh", "epochs": 100, "batch_size": 256, "lr": 1e-3, "obs_keys": MASKED_KEYS,
           "known_var": 0.5}
# RL from scratch: the masked stencil (the imitation recipe's observation) with far points read as
# unknown (polar_sim.envs.far_mask), trained where a step is cheapest (true pose, exact SDF: about 10x
# the slam mode's steps per CPU-second) and scored in slam, with a clutter curriculum over the first
# half of training (polar_sim.envs.curriculum; curriculum_steps 0 = off). Chosen on dev worlds
# 1000-1019 (benchmarks/RESULTS.md, "PPO from scratch on GPISNav-Room-v2"). eval_mode "train" scores
# the dev checkpoints in the training mode (cheap; for recipe search), train_reward reweights the
# training envs' reward only (e.g. {"collision": 2.5}; scoring keeps the env's own).
_RL = {"train_sdf_source": "truth", "obs_keys": MASKED_KEYS, "known_var": 0.5, "far_unknown": True,
       "curriculum_steps": 150_000, "curriculum_start": 0, "eval_mode": "slam", "train_reward": {}}
# PPO: an entropy bonus and a wider initial action noise (std 0.61), because without them the
# policy's noise collapsed (log std -1 -> -1.7 in 150k steps, -2.4 with 4x the updates) while it
# still drove into clutter (issue 32, branch ppo2, dev worlds).
_PPO = {**_RL, "steps": 300_000, "n_envs": 4, "obs_mode": "stencil", "learning_rate": 3e-4,
        "n_steps": 512, "batch_size": 256, "n_epochs": 10, "gamma": 0.99, "gae_lambda": 0.95, "clip_range": 0.2,
        "ent_coef": 0.01, "log_std_init": -0.5, "hidden": [128, 128]}
#: Recipe name -> its parameters' defaults (every parameter a recipe takes is here).
RECIPES = {
    "dagger": {**_COMMON, **_DAGGER, "head": "regress", "near_weight": 1.0},
    # The shipped Rooms2-v2 and 3x3 policies' recipe (Room-v2: rounds 3, steps_per_round 7000), chosen on dev
    # worlds 1000-1049 (benchmarks/RESULTS.md, "A discrete action head: fourth push").
    "dagger_map": {**_COMMON, "train_pose_source": "slam", "rounds": 6, "steps_per_round": 5000, "beta_decay": 0.5,
                   "hidden": [256, 256], "activation": "tanh", "epochs": 30, "batch_size": 256, "lr": 1e-3,
                   "head": "bins", "near_weight": 1.0},
    "dagger_ppo": {**_COMMON, **_DAGGER, "finetune_steps": 50_000, "n_envs": 4, "learning_rate": 5e-5,
                   "n_steps": 512, "batch_size": 256, "n_epochs": 5, "gamma": 0.99, "gae_lambda": 0.95,
                   "clip_range": 0.1, "ent_coef": 0.0, "log_std_init": -2.0, "critic_warmup_steps": 10_000,
                   "init_policy": ""},
    "ppo": {**_COMMON, **_PPO},
    "recurrent_ppo": {**_COMMON, **{k: v for k, v in _PPO.items() if k != "hidden"}, "n_steps": 128,
                      "batch_size": 128, "ent_coef": 0.0, "log_std_init": -1.0},  # as run in branch ppo
    "sac": {**_COMMON, **_RL, "steps": 100_000, "n_envs": 1, "obs_mode": "stencil", "learning_rate": 3e-4,
            "buffer_size": 100_000, "learning_starts": 1000, "batch_size": 256, "gamma": 0.99},
}
RECIPES["tqc"] = dict(RECIPES["sac"])

_CHOICES = {"train_pose_source": ("truth", "odometry", "slam"), "train_sdf_source": ("truth", "gpis"),
            "expert": ("reactive", "navigator"),
            "activation": ("tanh", "relu"), "obs_mode": ("stencil", "grid"), "head": ("regress", "bins"),
            "eval_mode": ("slam", "train")}
_UNIT = ("beta_decay", "gamma", "gae_lambda", "clip_range")  # floats in [0, 1]


def _check_init_policy(value):
    """``init_policy``: "" (run ``dagger`` first), "pretrained" (the tier's shipped policy) or an
    existing ``.npz`` policy file."""
    if not isinstance(value, str):
        raise ValueError(f"init_policy: expected '', 'pretrained' or a .npz path, got {value!r}")
    if value not in ("", "pretrained") and not (value.endswith(".npz") and Path(value).is_file()):
        raise ValueError(f"init_policy: expected '', 'pretrained' or an existing .npz policy file, got {value!r}")
    return value


def _check_value(key, value, default):
    if key == "init_policy":
        return _check_init_policy(value)
    if key == "known_var":
        return None if value is None else as_float(value, key, minimum=0.0, maximum=1e6, exclusive_minimum=True)
    if key in _CHOICES:
        return check_choice(value, _CHOICES[key], key)
    if isinstance(default, bool):
        return as_bool(value, key)
    if isinstance(default, int):
        lo = 0 if key in ("eval_every", "critic_warmup_steps", "learning_starts", "curriculum_steps",
                          "curriculum_start") else 1
        return as_int(value, key, minimum=lo, maximum=100_000_000)
    if isinstance(default, float):
        if key in _UNIT:
            return as_float(value, key, minimum=0.0, maximum=1.0)
        if key == "log_std_init":
            return as_float(value, key, minimum=-10.0, maximum=2.0)
        return as_float(value, key, minimum=0.0, maximum=10.0, exclusive_minimum=key in ("lr", "learning_rate"))
    if key == "hidden":
        if not isinstance(value, (list, tuple)) or not value:
            raise ValueError(f"hidden: expected a non-empty list of layer widths, got {value!r}")
        return [as_int(h, "hidden", minimum=1, maximum=4096) for h in value]
    if key == "obs_keys":
        if not isinstance(value, (list, tuple)) or not value or not all(isinstance(k, str) for k in value):
            raise ValueError(f"obs_keys: expected a non-empty list of observation keys, got {value!r}")
        return list(value)
    if key == "train_reward":  # reward weights of the training envs only (scoring: the env's own)
        from polar_sim.envs.lidar_nav import as_reward_weights

        if not isinstance(value, dict):
            raise ValueError(f"train_reward: expected a dict of reward weights, got {value!r}")
        try:
            full = as_reward_weights(value)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"train_reward: {exc}") from None
        return {k: full[k] for k in value}
    if key == "env_kwargs":
        if not isinstance(value, dict):
            raise ValueError(f"env_kwargs: expected a dict of gym.make arguments, got {value!r}")
        for k in ("pose_source", "sdf_source"):
            if k in value:
                raise ValueError(f"env_kwargs: set the training {k} with train_{k}; scoring is always slam")
        return dict(value)
    raise ValueError(f"{key}: cannot check a value of type {type(default).__name__}")  # pragma: no cover


def check_recipe(name, params=None, env_id=None):
    """The recipe ``name``'s parameters: its defaults updated by ``params``, each checked.

    Raises ``ValueError`` for an unknown recipe (listing the known ones), an unknown parameter
    (listing the recipe's), a value of the wrong kind or range, or an ``env_id`` that is not a
    learning tier, all before anything is trained."""
    if name not in RECIPES:
        raise ValueError(f"recipe: unknown recipe {name!r}; expected one of {', '.join(RECIPES)}")
    if env_id is not None and env_id.split(":")[-1] not in LEARNING_ENV_IDS:
        raise ValueError(f"env_id: recipes train on {', '.join(LEARNING_ENV_IDS)}; got {env_id!r}")
    params = {} if params is None else params
    if not isinstance(params, dict):
        raise ValueError(f"params: expected a dict, got {type(params).__name__}")
    unknown = sorted(set(params) - set(RECIPES[name]))
    if unknown:
        raise ValueError(f"params: {unknown} are not parameters of recipe {name!r}; it takes "
                         f"{', '.join(sorted(RECIPES[name]))}")
    out = copy.deepcopy(RECIPES[name])
    for k, v in params.items():
        out[k] = _check_value(k, v, RECIPES[name][k])
    if out.get("obs_mode") == "grid" and name in ("sac", "tqc"):
        raise ValueError(f"obs_mode: recipe {name!r} trains on the stencil only")
    if out.get("known_var") is not None and out.get("obs_mode") != "grid" and "sdf_var" not in out["obs_keys"]:
        raise ValueError(f"known_var: masking unknown space needs 'sdf_var' among the obs_keys, got {out['obs_keys']}")
    if out.get("far_unknown") and out.get("known_var") is None:
        raise ValueError("far_unknown: reading far points as unknown needs the masked stencil (known_var)")
    if name == "dagger_ppo" and out["finetune_steps"] < out["n_envs"] * out["n_steps"]:
        raise ValueError(f"finetune_steps: expected at least n_envs * n_steps = {out['n_envs'] * out['n_steps']}")
    return out


def train(recipe, env_id, *, params=None, seed=0, out=None, progress=None):
    """Run ``recipe`` (a name of :data:`RECIPES`) on ``env_id`` with ``params``.

    Returns ``(policy, summary)``: a callable ``policy(obs) -> action`` for the default slam
    mode, and a dict with the parameters, the steps, the wall and CPU time, and the learning
    curve (dev-world success against environment steps and wall seconds, every ``eval_every``
    steps when > 0). With ``out``, writes ``policy.npz``, ``curve.csv`` and ``summary.json`` there.
    ``progress``: None shows the tqdm bar only on a terminal, False never.
    """
    p = check_recipe(recipe, params, env_id)
    seed = as_int(seed, "seed", minimum=0)
    env_id = env_id.split(":")[-1]
    from polar_sim.envs import _train  # torch, SB3: imported only once the arguments are good

    t_wall, t_cpu = time.perf_counter(), time.process_time()
    curve = []
    with _train.one_torch_thread():
        policy, steps = _train.RUNNERS[recipe](env_id, p, seed, curve, progress)
    summary = {"recipe": recipe, "env_id": env_id, "params": p, "seed": seed, "steps": int(steps),
               "wall_s": time.perf_counter() - t_wall, "cpu_s": time.process_time() - t_cpu,
               "dev_seeds": [DEV_SEED, DEV_SEED + p["eval_episodes"] - 1], "curve": curve}
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        policy.save(out / "policy.npz")
        if curve:
            with open(out / "curve.csv", "w", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=list(curve[0]))
                w.writeheader()
                w.writerows(curve)
        (out / "summary.json").write_text(json.dumps(summary, indent=2, default=_jsonable))
    return policy, summary


def _jsonable(x):
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"not JSON: {type(x).__name__}")
