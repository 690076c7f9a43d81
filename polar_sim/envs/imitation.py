"""Imitation of a scripted expert by a memoryless MLP: behaviour cloning, then DAgger (the expert
labels the states the learner visits), in torch; the result is a numpy
:class:`~polar_sim.envs.mlp_policy.MLPPolicy`.

Why not the ``imitation`` library: its latest release (1.0.1) pins ``gymnasium==0.29.1`` and
``stable-baselines3==2.2.1``, and polar_sim needs gymnasium >= 1.0 and works with SB3 2.9
(checked with ``pip install --dry-run imitation``). The loop (:func:`polar_sim.envs.dagger.run_dagger`,
shared with the map learner) follows DAgger (Ross, Gordon and Bagnell, AISTATS 2011) as that
library's ``SimpleDAggerTrainer`` does.

The expert is stateful (``SDFReactive``'s follow mode, ``SDFNavigator``'s map): it is called
on every step of every rollout, whoever acts, so its state follows the trajectory driven.
"""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
from torch import nn

from polar_sim._validation import as_float, as_int, check_choice
from polar_sim.envs.dagger import key_columns, TRAIN_SEEDS, TorchLearner, check_fit, run_dagger
from polar_sim.envs.features import KNOWN_VAR, MASKED_KEYS, stencil_vector
from polar_sim.envs.mlp_policy import MLPPolicy
from polar_sim.envs.policies import SDFNavigator, SDFReactive

__all__ = ["DAggerConfig", "EXPERTS", "make_expert", "MLPLearner", "train_dagger", "TRAIN_SEEDS"]

#: Experts by name; each reads the stencil observation (``obs_mode="stencil"``).
EXPERTS = {"reactive": SDFReactive, "navigator": SDFNavigator}


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
    head : dict or None, default=None
        The action head (:mod:`polar_sim.envs.action_head`): None regresses (v, omega) by mean
        squared error; ``action_head.BINS`` classifies over action bins (soft cross-entropy).
    near_weight : float, default=1.0
        The loss weight of a sample near an obstacle (a known stencil distance below
        ``near_distance`` m) relative to the others (1: all alike).
    near_distance : float, default=0.5
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
    head: dict | None = None
    near_weight: float = 1.0
    near_distance: float = 0.5

    def __post_init__(self):
        as_int(self.rounds, "rounds", minimum=1, maximum=100)
        as_int(self.steps_per_round, "steps_per_round", minimum=1, maximum=10_000_000)
        as_float(self.beta_decay, "beta_decay", minimum=0.0, maximum=1.0)
        if not isinstance(self.hidden, (tuple, list)) or not self.hidden:
            raise ValueError(f"hidden: expected a non-empty tuple of layer widths, got {self.hidden!r}")
        for h in self.hidden:
            as_int(h, "hidden", minimum=1, maximum=4096)
        check_choice(self.activation, ("tanh", "relu"), "activation")
        object.__setattr__(self, "head", check_fit(self.epochs, self.batch_size, self.lr, self.head,
                                                           self.near_weight, self.near_distance))
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


def _mlp(n_in, hidden, activation, n_out=2):
    act = {"tanh": nn.Tanh, "relu": nn.ReLU}[activation]
    layers, fan = [], n_in
    for h in hidden:
        layers += [nn.Linear(fan, h), act()]
        fan = h
    return nn.Sequential(*layers, nn.Linear(fan, n_out))


def to_policy(net, mean, std, config, env, env_id, env_kwargs, recipe):
    """The numpy :class:`MLPPolicy` of the torch ``net``."""
    lin = [m for m in net if isinstance(m, nn.Linear)]
    return MLPPolicy([m.weight.detach().numpy() for m in lin], [m.bias.detach().numpy() for m in lin],
                     obs_keys=config.obs_keys,
                     obs_shapes={k: env.observation_space[k].shape for k in config.obs_keys},
                     mean=mean, std=std, activation=config.activation, action=None, env_id=env_id,
                     env_kwargs=env_kwargs, recipe=recipe, known_var=config.known_var, head=config.head)


class MLPLearner(TorchLearner):
    """The memoryless learner: the (masked) stencil features of ``config.obs_keys`` through an MLP
    (:class:`~polar_sim.envs.dagger.TorchLearner`; exported as :class:`MLPPolicy`)."""

    dtypes = (np.float32,)

    def __init__(self, env, config, env_id, env_kwargs, recipe):
        super().__init__(epochs=config.epochs, batch_size=config.batch_size, lr=config.lr, head=config.head,
                         near_weight=config.near_weight, near_distance=config.near_distance)
        self.sdf_columns = key_columns(config.obs_keys, env.observation_space)
        if config.near_weight != 1.0 and self.sdf_columns.stop == 0:
            raise ValueError("near_weight: weighing the samples near obstacles needs 'sdf' among the features")
        self.env, self.config, self.env_id, self.env_kwargs, self.recipe = env, config, env_id, env_kwargs, recipe

    def observe(self, obs):
        return (stencil_vector(obs, self.config.obs_keys, self.config.known_var),)

    def inputs(self, sample):
        return (self.normalised(sample[0]),)

    def make_net(self, data):
        return _mlp(data[-1].shape[1], self.config.hidden, self.config.activation, self.n_out)

    def export(self):
        return to_policy(self.net, self.mean, self.std, self.config, self.env, self.env_id, self.env_kwargs,
                         self.recipe)


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
    try:
        ex = make_expert(expert, env)
        missing = [k for k in config.obs_keys if k not in env.observation_space.spaces]
        if missing:
            raise ValueError(f"obs_keys: {missing} are not observed by {env_id} {env_kwargs}")
        learner = MLPLearner(env, config, env_id, policy_env_kwargs, recipe)
        return run_dagger(env, ex, learner, rounds=config.rounds, steps_per_round=config.steps_per_round,
                          beta_decay=config.beta_decay, seed=config.seed, desc=f"dagger {env_id}", progress=progress,
                          callback=callback)
    finally:
        env.close()
