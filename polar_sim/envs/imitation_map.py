"""DAgger with a map memory: the learner of :mod:`polar_sim.envs.imitation`, given the remembered
map that ``SDFNavigator`` plans on, imitating ``SDFNavigator``; the result is a numpy
:class:`~polar_sim.envs.map_policy.MapCNNPolicy`.

The loop is :func:`polar_sim.envs.dagger.run_dagger`, shared with the memoryless learner; the
learner's memory sees every observation of the trajectory driven, whoever acts, so the expert's
label and the learner's input describe the same history.
"""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from polar_sim._validation import as_float, as_int, check_choice
from polar_sim.envs.action_head import BINS, head_outputs
from polar_sim.envs.dagger import key_columns, TorchLearner, check_fit, run_dagger
from polar_sim.envs.features import KNOWN_VAR, MASKED_KEYS, stencil_vector
from polar_sim.envs.imitation import make_expert
from polar_sim.envs.map_memory import DEFAULT_SCALES, MAP_CHANNELS, MapMemory
from polar_sim.envs.map_policy import MapCNNPolicy

__all__ = ["MapDAggerConfig", "MapLearner", "train_dagger_map", "MapNet"]


@dataclasses.dataclass(frozen=True)
class MapDAggerConfig:
    """The ``dagger_map`` recipe's parameters: those of the shipped ``GPISNav-Rooms2-v2`` and ``GPISNav-v2`` policies
    (the discrete action head, 6 rounds of 5,000 steps, 30 epochs; 82 % and 74 % of 50 dev worlds; the shipped
    ``GPISNav-Room-v2`` policy is ``rounds=3, steps_per_round=7000``, 92 % of 50 dev worlds; benchmarks/RESULTS.md,
    fourth push).

    Attributes
    ----------
    rounds, steps_per_round, beta_decay
        As :class:`~polar_sim.envs.imitation.DAggerConfig`.
    convs : tuple of (int, int)
        (channels, stride) of each 3x3 ReLU convolution over the map crops.
    hidden : tuple of int
        Dense layer widths after the convolutions and the stencil features.
    activation : {"tanh", "relu"}
        Between the dense layers.
    epochs, batch_size, lr
        The fit after each round (Adam, warm-started).
    scales : tuple of (int, float)
        The memory's crops (:class:`~polar_sim.envs.map_memory.MapMemory`).
    seed : int
        Seeds torch, the mixture's coin and the first training world.
    head : dict or None, default=action_head.BINS
        The action head (:mod:`polar_sim.envs.action_head`; None: regression by mean squared error).
    near_weight : float, default=1.0
        The loss weight of a sample near an obstacle (a known stencil distance below
        ``near_distance`` m) relative to the others (1: all alike).
    near_distance : float, default=0.5
    """

    rounds: int = 6
    steps_per_round: int = 5000
    beta_decay: float = 0.5
    convs: tuple = ((16, 1), (32, 2), (32, 2))
    hidden: tuple = (256, 256)
    activation: str = "tanh"
    epochs: int = 30
    batch_size: int = 256
    lr: float = 1e-3
    scales: tuple = DEFAULT_SCALES
    seed: int = 0
    head: dict | None = dataclasses.field(default_factory=lambda: dict(BINS))
    near_weight: float = 1.0
    near_distance: float = 0.5

    def __post_init__(self):
        as_int(self.rounds, "rounds", minimum=1, maximum=100)
        as_int(self.steps_per_round, "steps_per_round", minimum=1, maximum=10_000_000)
        as_float(self.beta_decay, "beta_decay", minimum=0.0, maximum=1.0)
        if not isinstance(self.convs, (tuple, list)) or not self.convs:
            raise ValueError(f"convs: expected a non-empty tuple of (channels, stride), got {self.convs!r}")
        for c in self.convs:
            if not isinstance(c, (tuple, list)) or len(c) != 2 or c[1] not in (1, 2):
                raise ValueError(f"convs: expected (channels, stride 1 or 2) pairs, got {c!r}")
            as_int(c[0], "convs", minimum=1, maximum=512)
        if not isinstance(self.hidden, (tuple, list)) or not self.hidden:
            raise ValueError(f"hidden: expected a non-empty tuple of layer widths, got {self.hidden!r}")
        for h in self.hidden:
            as_int(h, "hidden", minimum=1, maximum=4096)
        check_choice(self.activation, ("tanh", "relu"), "activation")
        object.__setattr__(self, "head", check_fit(self.epochs, self.batch_size, self.lr, self.head,
                                                           self.near_weight, self.near_distance))
        as_int(self.seed, "seed", minimum=0)
        MapMemory(np.zeros((1, 2)), scales=self.scales)  # checks the scales
        object.__setattr__(self, "convs", tuple((int(c), int(s)) for c, s in self.convs))
        object.__setattr__(self, "hidden", tuple(int(h) for h in self.hidden))
        object.__setattr__(self, "scales", tuple((int(n), float(r)) for n, r in self.scales))


class MapNet(nn.Module):
    """The torch twin of :class:`MapCNNPolicy`'s network (same layouts, same order of features)."""

    def __init__(self, image_shape, n_vec, config):
        super().__init__()
        c, h, _ = image_shape
        convs = []
        for out, stride in config.convs:
            convs += [nn.Conv2d(c, out, 3, stride=stride, padding=1), nn.ReLU()]
            c, h = out, -(-h // stride)
        self.convs = nn.Sequential(*convs)
        act = {"tanh": nn.Tanh, "relu": nn.ReLU}[config.activation]
        layers, fan = [], c * h * h + n_vec
        for width in config.hidden:
            layers += [nn.Linear(fan, width), act()]
            fan = width
        self.head = nn.Sequential(*layers, nn.Linear(fan, head_outputs(config.head)))

    def forward(self, image, vector):
        return self.head(torch.cat([self.convs(image).flatten(1), vector], 1))


def _to_policy(net, mean, std, memory_params, config, env, env_id, env_kwargs, recipe):
    convs = [m for m in net.convs if isinstance(m, nn.Conv2d)]
    lin = [m for m in net.head if isinstance(m, nn.Linear)]
    return MapCNNPolicy([(m.weight.detach().numpy(), m.bias.detach().numpy(), s)
                         for m, (_, s) in zip(convs, config.convs)],
                        [m.weight.detach().numpy() for m in lin], [m.bias.detach().numpy() for m in lin],
                        memory=memory_params, obs_keys=MASKED_KEYS,
                        obs_shapes={k: env.observation_space[k].shape for k in MASKED_KEYS}, mean=mean, std=std,
                        activation=config.activation, known_var=KNOWN_VAR, env_id=env_id, env_kwargs=env_kwargs,
                        recipe=recipe, head=config.head)


class MapLearner(TorchLearner):
    """The learner with a map memory: a sample is the memory's crops (float16) and the masked
    stencil features, read by :class:`MapNet` (exported as :class:`MapCNNPolicy`)."""

    dtypes = (np.float16, np.float32)

    def __init__(self, env, config, env_id, env_kwargs, recipe):
        super().__init__(epochs=config.epochs, batch_size=config.batch_size, lr=config.lr, head=config.head,
                         near_weight=config.near_weight, near_distance=config.near_distance)
        self.sdf_columns = key_columns(MASKED_KEYS, env.observation_space)
        if config.near_weight != 1.0 and self.sdf_columns.stop == 0:
            raise ValueError("near_weight: weighing the samples near obstacles needs 'sdf' among the features")
        stencil = env.unwrapped._stencil
        self.memory_params = {"half": 18.0, "cell": 0.2, "max_var": 0.5, "scales": [list(s) for s in config.scales],
                              "stencil_rays": int(stencil.n_rays),
                              "stencil_radii": [float(r) for r in stencil.radii]}
        self.memory = MapMemory(stencil.points_robot, half=18.0, cell=0.2, max_var=0.5, scales=config.scales)
        self.image_shape = (len(MAP_CHANNELS) * len(config.scales),) + (config.scales[0][0],) * 2
        self.env, self.config, self.env_id, self.env_kwargs, self.recipe = env, config, env_id, env_kwargs, recipe

    def reset(self):
        self.memory.reset()

    def observe(self, obs):
        self.memory.update(obs)
        return self.memory.crops(), stencil_vector(obs, MASKED_KEYS, KNOWN_VAR)

    def inputs(self, sample):
        return sample[0], self.normalised(sample[1])

    def make_net(self, data):
        return MapNet(self.image_shape, data[-1].shape[1], self.config)

    def export(self):
        return _to_policy(self.net, self.mean, self.std, self.memory_params, self.config, self.env, self.env_id,
                          self.env_kwargs, self.recipe)


def train_dagger_map(env_id, *, config=MapDAggerConfig(), env_kwargs=None, policy_env_kwargs=None, recipe=None,
                     progress=True, callback=None):
    """Behaviour cloning and DAgger rounds of ``SDFNavigator`` on ``env_id`` for a map-memory learner.

    Parameters
    ----------
    env_id : str
        A GPISNav v1/v2 id (stencil observation with ``pose``).
    config : MapDAggerConfig
    env_kwargs, policy_env_kwargs, recipe, progress, callback
        As :func:`polar_sim.envs.imitation.train_dagger`.

    Returns
    -------
    policy : MapCNNPolicy
    history : list of dict
        Per round: beta, steps, episodes, success and collision of the rollouts, loss, data size,
        wall and CPU seconds since the start.
    """
    if not isinstance(config, MapDAggerConfig):
        raise TypeError(f"config: expected a MapDAggerConfig, got {type(config).__name__}")
    env_kwargs = dict(env_kwargs or {})
    if policy_env_kwargs is None:
        policy_env_kwargs = {k: v for k, v in env_kwargs.items() if k != "pose_source"}
    env = gym.make(env_id, **env_kwargs)
    try:
        expert = make_expert("navigator", env)
        if "pose" not in env.observation_space.spaces:
            raise ValueError(f"env_id: the map memory reads the estimated pose; {env_id} does not observe it "
                             f"(use a v1 or v2 id)")
        learner = MapLearner(env, config, env_id, policy_env_kwargs, recipe)
        return run_dagger(env, expert, learner, rounds=config.rounds, steps_per_round=config.steps_per_round,
                          beta_decay=config.beta_decay, seed=config.seed, desc=f"dagger_map {env_id}",
                          progress=progress, callback=callback)
    finally:
        env.close()
