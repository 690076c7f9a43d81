"""Imitation of a scripted expert: behaviour cloning, then DAgger (the expert labels the states
the learner visits), in torch; the result is a numpy :class:`~polar_sim.envs.mlp_policy.MLPPolicy`.

Why not the ``imitation`` library: its latest release (1.0.1) pins ``gymnasium==0.29.1`` and
``stable-baselines3==2.2.1``, and polar_sim needs gymnasium >= 1.0 and works with SB3 2.9
(checked with ``pip install --dry-run imitation``). The loop here follows DAgger (Ross, Gordon
and Bagnell, AISTATS 2011) as that library's ``SimpleDAggerTrainer`` does: round 0 rolls out the
expert and fits the learner to its actions (behaviour cloning); round k >= 1 rolls out a mixture
that executes the expert's action with probability ``beta_decay ** k`` and the learner's
otherwise, labels every visited state with the expert's action, aggregates, and refits.

The expert is stateful (``SDFReactive``'s follow mode, ``SDFNavigator``'s map): it is called
on every step of every rollout, whoever acts, so its state follows the trajectory driven.
"""

from __future__ import annotations

import dataclasses
import time

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from polar_sim._validation import as_float, as_int, check_choice
from polar_sim.envs.features import KNOWN_VAR, MASKED_KEYS, stencil_vector
from polar_sim.envs.mlp_policy import MLPPolicy
from polar_sim.envs.policies import SDFNavigator, SDFReactive

__all__ = ["DAggerConfig", "EXPERTS", "make_expert", "rollout", "fit_mlp", "train_dagger", "TRAIN_SEEDS"]

#: Experts by name; each reads the stencil observation (``obs_mode="stencil"``).
EXPERTS = {"reactive": SDFReactive, "navigator": SDFNavigator}
#: The training worlds: episode seeds cycle through this range (dev worlds start at 1000, held-out at 10,000).
TRAIN_SEEDS = (0, 1000)


@dataclasses.dataclass(frozen=True)
class DAggerConfig:
    """The DAgger recipe's parameters (defaults chosen on dev worlds, seeds 1000-1029; docs/guide/learning.md).

    Attributes
    ----------
    rounds : int
        Rounds of data collection; round 0 is behaviour cloning on the expert's own rollouts.
    steps_per_round : int
        Environment steps collected (and expert-labelled) per round.
    beta_decay : float
        Round k >= 1 executes the expert's action with probability ``beta_decay ** k``.
    hidden : tuple of int
        Hidden layer widths of the MLP.
    activation : {"tanh", "relu"}
    epochs : int
        Passes over the aggregated data after each round (the net is warm-started). 20 left the
        net underfitted (training loss 0.029 against 0.0064 with 100 after behaviour cloning).
    batch_size : int
    lr : float
        Adam's learning rate.
    obs_keys : tuple of str
        Observation keys the learner reads. ``pose`` is left out (its range differs between
        tiers); ``sdf_var`` is read only as the known mask of ``known_var`` (the raw variance's
        scale differs between map sources, see docs/guide/learning.md).
    seed : int
        Seeds torch, the mixture's coin and the first training world (``TRAIN_SEEDS``).
    known_var : float or None, default=KNOWN_VAR
        Mask the stencil's unknown space (map variance >= ``known_var``) before the learner sees
        it, as the experts do (None: the raw stencil) (:func:`polar_sim.envs.features.stencil_vector`); needs ``sdf_var``
        in ``obs_keys``.
    """

    rounds: int = 4
    steps_per_round: int = 5000
    beta_decay: float = 0.5
    hidden: tuple = (256, 256)
    activation: str = "tanh"
    epochs: int = 100
    batch_size: int = 256
    lr: float = 1e-3
    obs_keys: tuple = MASKED_KEYS
    seed: int = 0
    known_var: float | None = KNOWN_VAR

    def __post_init__(self):
        as_int(self.rounds, "rounds", minimum=1, maximum=100)
        as_int(self.steps_per_round, "steps_per_round", minimum=1, maximum=10_000_000)
        as_float(self.beta_decay, "beta_decay", minimum=0.0, maximum=1.0)
        if not isinstance(self.hidden, (tuple, list)) or not self.hidden:
            raise ValueError(f"hidden: expected a non-empty tuple of layer widths, got {self.hidden!r}")
        for h in self.hidden:
            as_int(h, "hidden", minimum=1, maximum=4096)
        check_choice(self.activation, ("tanh", "relu"), "activation")
        as_int(self.epochs, "epochs", minimum=1, maximum=10_000)
        as_int(self.batch_size, "batch_size", minimum=1, maximum=1_000_000)
        as_float(self.lr, "lr", minimum=0.0, maximum=1.0, exclusive_minimum=True)
        if not isinstance(self.obs_keys, (tuple, list)) or not self.obs_keys \
                or not all(isinstance(k, str) for k in self.obs_keys):
            raise ValueError(f"obs_keys: expected a non-empty tuple of observation keys, got {self.obs_keys!r}")
        as_int(self.seed, "seed", minimum=0)
        if self.known_var is not None:
            as_float(self.known_var, "known_var", minimum=0.0, maximum=1e6, exclusive_minimum=True)
            if "sdf_var" not in self.obs_keys:
                raise ValueError(f"known_var: masking unknown space needs 'sdf_var' among the obs_keys, got "
                                 f"{tuple(self.obs_keys)}")
        object.__setattr__(self, "hidden", tuple(int(h) for h in self.hidden))
        object.__setattr__(self, "obs_keys", tuple(self.obs_keys))


def make_expert(name, env):
    """The expert ``name`` (a key of :data:`EXPERTS`) for ``env``'s stencil observation."""
    check_choice(name, tuple(EXPERTS), "expert")
    u = env.unwrapped
    stencil = getattr(u, "_stencil", None)
    if "sdf" not in env.observation_space.spaces or stencil is None:
        raise ValueError(f"expert: {name!r} reads the stencil observation; make the env with obs_mode='stencil'")
    return EXPERTS[name](stencil_rays=stencil.n_rays, stencil_radii=tuple(stencil.radii))


def rollout(env, expert, learner, *, beta, steps, rng, seeds, keys, known_var=None, bar=None):
    """Run ``steps`` env steps, each executing the expert's action with probability ``beta`` and
    ``learner``'s otherwise (``learner`` None: always the expert), and return the visited
    features (steps, n), the expert's actions there (steps, 2) and the finished episodes'
    outcomes ``{"episodes", "success", "collision"}``. ``seeds`` yields episode seeds; ``keys`` and
    ``known_var`` make the features (:func:`polar_sim.envs.features.stencil_vector`)."""
    X, Y = [], []
    out = {"episodes": 0, "success": 0, "collision": 0}
    obs, _ = env.reset(seed=next(seeds))
    expert.reset()
    if learner is not None:
        learner.reset()
    for _ in range(steps):
        a_exp = np.asarray(expert(obs), np.float32)
        X.append(stencil_vector(obs, keys, known_var))
        Y.append(a_exp)
        use_expert = learner is None or rng.random() < beta
        a = a_exp if use_expert else learner(obs)
        obs, _, term, trunc, info = env.step(a)
        if bar is not None:
            bar.update(1)
        if term or trunc:
            out["episodes"] += 1
            out["success"] += bool(info.get("is_success"))
            out["collision"] += bool(info.get("collision"))
            obs, _ = env.reset(seed=next(seeds))
            expert.reset()
            if learner is not None:
                learner.reset()
    return np.asarray(X, np.float32), np.asarray(Y, np.float32), out


def _mlp(n_in, hidden, activation):
    act = {"tanh": nn.Tanh, "relu": nn.ReLU}[activation]
    layers, fan = [], n_in
    for h in hidden:
        layers += [nn.Linear(fan, h), act()]
        fan = h
    return nn.Sequential(*layers, nn.Linear(fan, 2))


def fit_mlp(net, X, Y, mean, std, *, epochs, batch_size, lr, generator):
    """Fit ``net`` to ``Y`` (n, 2) from normalised ``X`` (n, d) by mean squared error with Adam;
    returns the final epoch's mean loss."""
    x = torch.as_tensor(np.clip((X - mean) / std, -10, 10), dtype=torch.float32)
    y = torch.as_tensor(Y, dtype=torch.float32)
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    loss_sum = 0.0
    for _ in range(epochs):
        perm = torch.randperm(len(x), generator=generator)
        loss_sum = 0.0
        for i in range(0, len(x), batch_size):
            idx = perm[i:i + batch_size]
            loss = nn.functional.mse_loss(net(x[idx]), y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            loss_sum += loss.item() * len(idx)
    return loss_sum / len(x)


def to_policy(net, mean, std, config, env, env_id, env_kwargs, recipe):
    """The numpy :class:`MLPPolicy` of the torch ``net``."""
    lin = [m for m in net if isinstance(m, nn.Linear)]
    return MLPPolicy([m.weight.detach().numpy() for m in lin], [m.bias.detach().numpy() for m in lin],
                     obs_keys=config.obs_keys,
                     obs_shapes={k: env.observation_space[k].shape for k in config.obs_keys},
                     mean=mean, std=std, activation=config.activation, action=None, env_id=env_id,
                     env_kwargs=env_kwargs, recipe=recipe, known_var=config.known_var)


def train_dagger(env_id, *, expert="reactive", config=DAggerConfig(), env_kwargs=None, policy_env_kwargs=None,
                 recipe=None, progress=True, callback=None):
    """Behaviour cloning and DAgger rounds of ``expert`` on ``env_id``.

    Parameters
    ----------
    env_id : str
        A GPISNav id (stencil observation).
    expert : str
        A key of :data:`EXPERTS`.
    config : DAggerConfig
    env_kwargs : dict, optional
        ``gym.make`` arguments of the training env (e.g. ``{"pose_source": "truth"}``).
    policy_env_kwargs : dict, optional
        The ``gym.make`` arguments stored with the policy (where it is meant to act; default
        ``env_kwargs`` without ``pose_source``, i.e. the default slam mode).
    recipe : dict, optional
        Stored with the policy.
    progress : bool or None
        A tqdm bar over the collected steps (stderr); None: only on a terminal.
    callback : callable, optional
        ``callback(round, policy, history_row)`` after each round (e.g. to score on dev worlds).

    Returns
    -------
    policy : MLPPolicy
    history : list of dict
        Per round: beta, steps, episodes, success and collision of the rollouts, loss, data size,
        wall and CPU seconds since the start.
    """
    if not isinstance(config, DAggerConfig):
        raise TypeError(f"config: expected a DAggerConfig, got {type(config).__name__}")
    env_kwargs = dict(env_kwargs or {})
    if policy_env_kwargs is None:
        policy_env_kwargs = {k: v for k, v in env_kwargs.items() if k != "pose_source"}
    env = gym.make(env_id, **env_kwargs)
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    try:
        ex = make_expert(expert, env)
        missing = [k for k in config.obs_keys if k not in env.observation_space.spaces]
        if missing:
            raise ValueError(f"obs_keys: {missing} are not observed by {env_id} {env_kwargs}")
        rng = np.random.default_rng(config.seed)
        gen = torch.Generator().manual_seed(config.seed)
        torch.manual_seed(config.seed)
        seeds = (TRAIN_SEEDS[0] + (config.seed * 7919 + i) % (TRAIN_SEEDS[1] - TRAIN_SEEDS[0]) for i in range(10**9))
        X = Y = None
        net = mean = std = policy = None
        history = []
        total = config.rounds * config.steps_per_round
        with tqdm(total=total, desc=f"dagger {env_id}", unit="step",
                  disable=None if progress is None else not progress) as bar:
            for k in range(config.rounds):
                beta = 1.0 if k == 0 else config.beta_decay ** k
                x, y, out = rollout(env, ex, policy, beta=beta, steps=config.steps_per_round, rng=rng,
                                    seeds=seeds, keys=config.obs_keys, known_var=config.known_var, bar=bar)
                X = x if X is None else np.concatenate([X, x])
                Y = y if Y is None else np.concatenate([Y, y])
                if net is None:  # the normalisation of the expert's own data, fixed from then on
                    mean = X.mean(0).astype(np.float64)
                    std = np.maximum(X.std(0).astype(np.float64), 1e-3)
                    net = _mlp(X.shape[1], config.hidden, config.activation)
                loss = fit_mlp(net, X, Y, mean, std, epochs=config.epochs, batch_size=config.batch_size,
                               lr=config.lr, generator=gen)
                policy = to_policy(net, mean, std, config, env, env_id, policy_env_kwargs, recipe)
                row = {"round": k, "beta": beta, "steps": int(len(X)), **out, "loss": loss,
                       "wall_s": time.perf_counter() - t_wall, "cpu_s": time.process_time() - t_cpu}
                history.append(row)
                if callback is not None:
                    callback(k, policy, row)
    finally:
        env.close()
    return policy, history
