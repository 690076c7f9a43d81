"""The runners behind :func:`polar_sim.envs.recipes.train` (torch, stable-baselines3, sb3-contrib).

Each runner takes ``(env_id, params, seed, curve, progress)`` with checked ``params``, appends
learning-curve rows to ``curve`` and returns ``(policy, env_steps)``; the policy has ``save(path)``.
"""

from __future__ import annotations

import contextlib
import time

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecNormalize
from tqdm.auto import tqdm

from polar_sim.envs.action_head import BINS
from polar_sim.envs.action_maps import wrap_action
from polar_sim.envs.curriculum import ClutterCurriculum, Ramp
from polar_sim.envs.evaluate import evaluate
from polar_sim.envs.far_mask import FarAsUnknown
from polar_sim.envs.imitation import TRAIN_SEEDS, DAggerConfig, train_dagger
from polar_sim.envs.imitation_map import MapDAggerConfig, train_dagger_map
from polar_sim.envs.mlp_policy import MLPPolicy
from polar_sim.envs.learning import (FeatureObservation, ObsNormaliser, SB3Policy, export_mlp, load_mlp_into,
                                     make_model, ppo_recipe, sb3_recipe)

__all__ = ["RUNNERS", "bar_disable", "one_torch_thread"]

DEV_SEED = 1000


@contextlib.contextmanager
def one_torch_thread():
    """Run torch on one thread, then restore the caller's setting: the nets are small (one thread is
    as fast on 2 shared cores), and one thread makes a run bit-for-bit repeatable from its seed."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(n)


def bar_disable(progress):
    """tqdm's ``disable`` for ``progress``: None shows the bar only on a terminal."""
    return None if progress is None else not progress


def _train_env_kwargs(p):
    kw = {**p["env_kwargs"], "pose_source": p["train_pose_source"]}
    if "train_sdf_source" in p:
        kw["sdf_source"] = p["train_sdf_source"]
    if p.get("train_reward"):
        kw["reward_weights"] = {**kw.get("reward_weights", {}), **p["train_reward"]}
    return kw


class _Clock:
    """Wall and CPU seconds since the run started (the learning curve's time axis)."""

    def __init__(self):
        self.wall, self.cpu = time.perf_counter(), time.process_time()

    def row(self, steps):
        return {"steps": int(steps), "wall_s": time.perf_counter() - self.wall, "cpu_s": time.process_time() - self.cpu}


def _score(env_id, policy, p, curve, clock, steps):
    """Append the dev-world success and collision rates of ``policy`` at ``steps`` to ``curve``
    (in the default slam mode, or with ``eval_mode: "train"`` in the recipe's training mode)."""
    row = clock.row(steps)
    kw = dict(policy.env_kwargs)
    if p.get("eval_mode") == "train":  # the training mode's pose and map, the env's own reward
        kw.update(pose_source=p["train_pose_source"], sdf_source=p["train_sdf_source"])
    _, s = evaluate(env_id, policy, episodes=p["eval_episodes"], seed=DEV_SEED, env_kwargs=kw, progress=False)
    row.update(success=s["success_rate"], collision=s["mean_collision"], eval_wall_s=clock.row(steps)["wall_s"]
               - row["wall_s"])
    curve.append(row)


def _dagger(env_id, p, seed, curve, progress, clock=None):
    clock = clock or _Clock()
    cfg = DAggerConfig(rounds=p["rounds"], steps_per_round=p["steps_per_round"], beta_decay=p["beta_decay"],
                       hidden=tuple(p["hidden"]), activation=p["activation"], epochs=p["epochs"],
                       batch_size=p["batch_size"], lr=p["lr"], obs_keys=tuple(p["obs_keys"]), seed=seed,
                       known_var=p["known_var"], head=BINS if p.get("head") == "bins" else None,
                       near_weight=p.get("near_weight", 1.0))

    def after_round(k, policy, row):
        if p["eval_every"] and ((k + 1) * p["steps_per_round"]) % p["eval_every"] < p["steps_per_round"]:
            _score(env_id, policy, p, curve, clock, row["steps"])

    recipe = {"name": "dagger", "params": p, "seed": seed, "train_seeds": list(TRAIN_SEEDS)}
    policy, hist = train_dagger(env_id, expert=p["expert"], config=cfg, env_kwargs=_train_env_kwargs(p),
                                policy_env_kwargs=dict(p["env_kwargs"]), recipe=recipe,
                                progress=progress, callback=after_round)
    return policy, hist[-1]["steps"]


def _dagger_map(env_id, p, seed, curve, progress):
    clock = _Clock()
    cfg = MapDAggerConfig(rounds=p["rounds"], steps_per_round=p["steps_per_round"], beta_decay=p["beta_decay"],
                          hidden=tuple(p["hidden"]), activation=p["activation"], epochs=p["epochs"],
                          batch_size=p["batch_size"], lr=p["lr"], seed=seed, head=BINS if p["head"] == "bins" else None,
                          near_weight=p["near_weight"])

    def after_round(k, policy, row):
        if p["eval_every"] and ((k + 1) * p["steps_per_round"]) % p["eval_every"] < p["steps_per_round"]:
            _score(env_id, policy, p, curve, clock, row["steps"])

    recipe = {"name": "dagger_map", "params": p, "seed": seed, "train_seeds": list(TRAIN_SEEDS)}
    policy, hist = train_dagger_map(env_id, config=cfg, env_kwargs=_train_env_kwargs(p),
                                    policy_env_kwargs=dict(p["env_kwargs"]), recipe=recipe, progress=progress,
                                    callback=after_round)
    return policy, hist[-1]["steps"]


class _EpisodeTally:
    """Outcomes of the training episodes that ended since the last :meth:`row`: the learning
    curve in the training mode itself, at no extra cost (the dev checkpoints score other worlds)."""

    def __init__(self):
        self.ended = []

    def add(self, dones, infos):
        for done, info in zip(dones, infos):
            if done:
                self.ended.append((bool(info.get("is_success")), bool(info.get("collision")),
                                   int(info.get("episode", {}).get("l", 0)), float(info.get("episode", {}).get("r", 0))))

    def row(self):
        """``train_episodes`` and the mean ``train_success``, ``train_collision``, ``train_length``,
        ``train_return`` (the env's reward, before normalisation) of the episodes since the last call."""
        e, self.ended = np.array(self.ended, float).reshape(-1, 4), []
        m = e.mean(0) if len(e) else np.full(4, np.nan)
        return {"train_episodes": len(e), "train_success": m[0], "train_collision": m[1], "train_length": m[2],
                "train_return": m[3]}


class _Progress(BaseCallback):
    """A tqdm bar over the env steps, a dev-world checkpoint every ``every`` steps (with ``curve``:
    the training episodes' outcomes since the last one added to its row), and the curriculum's
    ``schedule`` (if any) moved to the step count."""

    def __init__(self, total, desc, progress, every=0, checkpoint=None, schedule=None, curve=None):
        super().__init__()
        self.bar = tqdm(total=total, desc=desc, unit="step", disable=bar_disable(progress))
        self.every, self.checkpoint, self.next, self.schedule = every, checkpoint, every, schedule
        self.curve, self.tally = curve, _EpisodeTally()

    def _on_step(self):
        self.bar.update(self.num_timesteps - self.bar.n)
        self.tally.add(self.locals.get("dones", ()), self.locals.get("infos", ()))
        if self.schedule is not None:
            self.schedule.update(self.num_timesteps)
        if self.every and self.num_timesteps >= self.next:
            self.next += self.every
            self.checkpoint(self.num_timesteps)
            if self.curve:
                self.curve[-1].update(self.tally.row())
        return True

    def _on_training_end(self):
        self.bar.close()


def _vec_env(env_id, p, seed, wrapper, wrapper_kwargs):
    return make_vec_env("polar_sim.envs:" + env_id, n_envs=p["n_envs"], seed=TRAIN_SEEDS[0] + seed * 97,
                        env_kwargs=_train_env_kwargs(p), wrapper_class=wrapper, wrapper_kwargs=wrapper_kwargs)


def _feature_wrapper(env, action, keys, mean=None, std=None, known_var=None, schedule=None, clutter_start=0,
                     far_unknown=False):
    if schedule is not None:  # Monitor outside: the episodes of every clutter level have their length and return
        env = Monitor(ClutterCurriculum(env, schedule, clutter_start))
    if far_unknown:
        env = FarAsUnknown(env)
    return FeatureObservation(wrap_action(env, action), keys, mean, std, known_var=known_var)


def _schedule(p):
    """The clutter curriculum of ``p``: from ``curriculum_start`` pieces to the tier's own over
    ``curriculum_steps`` (None when 0)."""
    if not p.get("curriculum_steps"):
        return None
    return Ramp(p["curriculum_steps"])


def _ppo_kwargs(p, hidden, log_std_init, activation="tanh"):
    kw = {k: p[k] for k in ("learning_rate", "n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda",
                            "clip_range", "ent_coef")}
    kw["policy_kwargs"] = {"net_arch": {"pi": list(hidden), "vf": list(hidden)}, "log_std_init": log_std_init,
                           "activation_fn": activation}
    return kw


def _mlp_of(model, venv, p, keys, recipe, env_id, mean=None, std=None, known_var=None):
    """The numpy policy of a PPO MlpPolicy on FeatureObservation (normalised by ``venv`` if
    ``mean`` is None)."""
    if mean is None:
        rms = venv.obs_rms
        mean, std, clip = rms.mean, np.sqrt(rms.var + venv.epsilon), venv.clip_obs
    else:
        clip = 10.0
    space = venv.unwrapped.envs[0].unwrapped.observation_space
    shapes = {k: space[k].shape for k in keys}
    return export_mlp(model, mean, std, keys=keys, obs_shapes=shapes, recipe=recipe, clip=clip, env_id=env_id,
                      env_kwargs=dict(p["env_kwargs"]), known_var=known_var)


def _ppo(env_id, p, seed, curve, progress):
    if p["obs_mode"] == "grid" or p["far_unknown"]:  # an SB3 policy file (the numpy MLP reads no far mask)
        return _sb3(env_id, p, seed, curve, progress, name="ppo")
    clock = _Clock()
    keys = list(p["obs_keys"])
    action = {"name": "forward_drive", "kwargs": {}}
    recipe = {"name": "ppo", "algorithm": "PPO", "policy": "MlpPolicy", "params": p, "seed": seed,
              "kwargs": _ppo_kwargs(p, p["hidden"], p["log_std_init"]), "action": action}
    kv, schedule = p["known_var"], _schedule(p)
    wk = {"action": action, "keys": keys, "known_var": kv, "schedule": schedule, "clutter_start": p["curriculum_start"]}
    venv = VecNormalize(_vec_env(env_id, p, seed, _feature_wrapper, wk), norm_obs=True, norm_reward=True,
                        clip_obs=10.0, gamma=p["gamma"])
    model = make_model(recipe, venv, seed=seed)

    def ckpt(n):
        _score(env_id, _mlp_of(model, venv, p, keys, recipe, env_id, known_var=kv), p, curve, clock, n)

    model.learn(p["steps"], callback=_Progress(p["steps"], f"ppo {env_id}", progress, p["eval_every"], ckpt,
                                               schedule, curve))
    policy = _mlp_of(model, venv, p, keys, recipe, env_id, known_var=kv)
    venv.close()
    return policy, model.num_timesteps


def _initial_policy(env_id, p, seed, curve, progress, clock):
    """The imitation policy to fine-tune and its env steps: ``dagger``'s, or ``init_policy``'s (0 steps)."""
    if not p["init_policy"]:
        return _dagger(env_id, p, seed, curve, progress, clock)
    if p["init_policy"] == "pretrained":
        from polar_sim.envs.shipped import pretrained

        policy = pretrained(env_id)
        if not isinstance(policy, MLPPolicy):
            raise ValueError(f"init_policy: the policy shipped for {env_id} is a {type(policy).__name__}; PPO "
                             f"fine-tunes an MLP imitation policy (a v1 tier's, or a .npz of the dagger recipe)")
    else:
        policy = MLPPolicy.load(p["init_policy"], name="init_policy")
    if policy.action is not None or policy.env_id != env_id:
        raise ValueError(f"init_policy: expected an imitation policy of {env_id} (env action), got one of "
                         f"{policy.env_id} with action {policy.action}")
    return policy, 0


def _dagger_ppo(env_id, p, seed, curve, progress):
    clock = _Clock()
    imitation, steps0 = _initial_policy(env_id, p, seed, curve, progress, clock)
    keys = imitation.obs_keys
    hidden = [w.shape[0] for w in imitation.weights[:-1]]
    recipe = {"name": "dagger_ppo", "algorithm": "PPO", "policy": "MlpPolicy", "params": p, "seed": seed,
              "kwargs": _ppo_kwargs(p, hidden, p["log_std_init"], imitation.activation), "action": None}
    wk = {"action": None, "keys": keys, "mean": imitation.mean, "std": imitation.std, "known_var": imitation.known_var}
    venv = VecNormalize(_vec_env(env_id, p, seed, _feature_wrapper, wk), norm_obs=False, norm_reward=True,
                        gamma=p["gamma"])
    model = load_mlp_into(make_model(recipe, venv, seed=seed), imitation)

    def export():
        return _mlp_of(model, venv, p, keys, recipe, env_id, imitation.mean, imitation.std, imitation.known_var)

    actor = list(model.policy.mlp_extractor.policy_net.parameters()) + list(model.policy.action_net.parameters()) \
        + [model.policy.log_std]
    total = p["critic_warmup_steps"] + p["finetune_steps"]
    cb = _Progress(total, f"dagger_ppo {env_id}", progress, p["eval_every"],
                   lambda n: _score(env_id, export(), p, curve, clock, steps0 + n))
    if p["critic_warmup_steps"]:
        # A fresh critic's advantages are noise: fit it with the imitation actor frozen first,
        # so that the first policy updates do not undo the imitation.
        for t in actor:
            t.requires_grad_(False)
        model.learn(p["critic_warmup_steps"], callback=cb)
        for t in actor:
            t.requires_grad_(True)
    model.learn(p["finetune_steps"], callback=cb, reset_num_timesteps=not p["critic_warmup_steps"])
    policy = export()
    venv.close()
    return policy, steps0 + model.num_timesteps


def _sb3(env_id, p, seed, curve, progress, name):
    """PPO on the grid, RecurrentPPO, SAC, TQC: SB3 policies on the Dict observation."""
    clock = _Clock()
    if name in ("sac", "tqc"):
        recipe = sb3_recipe(name.upper())
        recipe["kwargs"].update({k: p[k] for k in ("learning_rate", "buffer_size", "learning_starts", "batch_size",
                                                   "gamma")})
    else:
        recipe = ppo_recipe(p["obs_mode"], recurrent=name == "recurrent_ppo")
        recipe["kwargs"].update({k: p[k] for k in ("learning_rate", "n_steps", "batch_size", "n_epochs", "gamma",
                                                   "gae_lambda", "clip_range", "ent_coef")})
        recipe["kwargs"]["policy_kwargs"]["log_std_init"] = p["log_std_init"]
    recipe.update(name=name, params=p, seed=seed)
    env_kwargs = {**p["env_kwargs"], "obs_mode": p["obs_mode"]}
    pp = {**p, "env_kwargs": env_kwargs}
    schedule = _schedule(p)
    if p["obs_mode"] == "stencil":  # the masked stencil as one vector, as PPO's MLP reads it
        recipe["features"] = {"keys": list(p["obs_keys"]), "known_var": p["known_var"],
                              "far_unknown": p["far_unknown"]}
        if "hidden" in p:
            recipe["kwargs"]["policy_kwargs"]["net_arch"] = {"pi": list(p["hidden"]), "vf": list(p["hidden"])}
        recipe["policy"] = recipe["policy"].replace("MultiInput", "Mlp")
        wrapper, wk = _feature_wrapper, {"action": recipe["action"], **recipe["features"], "schedule": schedule,
                                         "clutter_start": p["curriculum_start"]}
    else:
        wrapper, wk = wrap_action, {"action": recipe["action"]}
    venv = VecNormalize(_vec_env(env_id, pp, seed, wrapper, wk), norm_obs=True,
                        norm_reward=name not in ("sac", "tqc"), clip_obs=10.0, gamma=p["gamma"])
    model = make_model(recipe, venv, seed=seed)

    def export():
        return SB3Policy(model, ObsNormaliser.from_vecnormalize(venv), recipe, env_id, env_kwargs)

    model.learn(p["steps"], callback=_Progress(p["steps"], f"{name} {env_id}", progress, p["eval_every"],
                                               lambda n: _score(env_id, export(), pp, curve, clock, n), schedule,
                                               curve))
    policy = export()
    venv.close()
    return policy, model.num_timesteps


RUNNERS = {"dagger": _dagger, "dagger_map": _dagger_map, "dagger_ppo": _dagger_ppo, "ppo": _ppo,
           "recurrent_ppo": lambda *a: _sb3(*a, name="recurrent_ppo"),
           "sac": lambda *a: _sb3(*a, name="sac"), "tqc": lambda *a: _sb3(*a, name="tqc")}
