"""DAgger with a map memory: the learner of :mod:`polar_sim.envs.imitation`, given the remembered
map that ``SDFNavigator`` plans on, imitating ``SDFNavigator``; the result is a numpy
:class:`~polar_sim.envs.map_policy.MapCNNPolicy`.

Round 0 rolls out the expert and fits the learner to its actions (behaviour cloning); round k >= 1
executes the expert's action with probability ``beta_decay ** k`` and the learner's otherwise,
labels every visited state with the expert's action, aggregates, and refits (warm-started). The
expert and the learner's memory both see every observation of the trajectory driven, whoever
acts, so the expert's label and the learner's input describe the same history.
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
from polar_sim.envs.imitation import TRAIN_SEEDS, make_expert
from polar_sim.envs.map_memory import DEFAULT_SCALES, MAP_CHANNELS, MapMemory
from polar_sim.envs.map_policy import MapCNNPolicy

__all__ = ["MapDAggerConfig", "train_dagger_map", "MapNet"]


@dataclasses.dataclass(frozen=True)
class MapDAggerConfig:
    """The ``dagger_map`` recipe's parameters: those of the shipped ``GPISNav-Rooms2-v2`` policy (70 % of 10 dev
    worlds; a longer run, 4 x 5,000 steps with 20 epochs, scored 60 % of 20 on ``GPISNav-Room-v2``; benchmarks/RESULTS.md).

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
        The fit after each round (Adam, mean squared error, warm-started).
    scales : tuple of (int, float)
        The memory's crops (:class:`~polar_sim.envs.map_memory.MapMemory`).
    seed : int
        Seeds torch, the mixture's coin and the first training world.
    """

    rounds: int = 3
    steps_per_round: int = 3000
    beta_decay: float = 0.5
    convs: tuple = ((16, 1), (32, 2), (32, 2))
    hidden: tuple = (256, 256)
    activation: str = "tanh"
    epochs: int = 15
    batch_size: int = 256
    lr: float = 1e-3
    scales: tuple = DEFAULT_SCALES
    seed: int = 0

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
        as_int(self.epochs, "epochs", minimum=1, maximum=10_000)
        as_int(self.batch_size, "batch_size", minimum=1, maximum=1_000_000)
        as_float(self.lr, "lr", minimum=0.0, maximum=1.0, exclusive_minimum=True)
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
        self.head = nn.Sequential(*layers, nn.Linear(fan, 2))

    def forward(self, image, vector):
        return self.head(torch.cat([self.convs(image).flatten(1), vector], 1))


def _rollout(env, expert, memory, learner, *, beta, steps, rng, seeds, bar):
    """``steps`` env steps of the beta-mixture; returns the crops (steps, C, n, n) float16, the raw
    stencil features (steps, n_vec), the expert's actions (steps, 2) and the finished episodes'
    outcomes."""
    images, vectors, actions = [], [], []
    out = {"episodes": 0, "success": 0, "collision": 0}

    def start():
        obs, _ = env.reset(seed=next(seeds))
        expert.reset()
        memory.reset()
        return obs

    obs = start()
    for _ in range(steps):
        a_exp = np.asarray(expert(obs), np.float32)
        memory.update(obs)
        img, vec = memory.crops(), stencil_vector(obs, MASKED_KEYS, KNOWN_VAR)
        images.append(img.astype(np.float16))
        vectors.append(vec.astype(np.float32))
        actions.append(a_exp)
        if learner is None or rng.random() < beta:
            a = a_exp
        else:
            a = learner.act(img, np.clip((vec - learner.mean) / learner.std, -learner.clip, learner.clip))
        obs, _, term, trunc, info = env.step(a)
        bar.update(1)
        if term or trunc:
            out["episodes"] += 1
            out["success"] += bool(info.get("is_success"))
            out["collision"] += bool(info.get("collision"))
            obs = start()
    return np.asarray(images), np.asarray(vectors), np.asarray(actions), out


def _fit(net, images, vectors, actions, mean, std, config, generator):
    """Adam on the mean squared error over every sample, ``config.epochs`` passes; the last pass's loss."""
    img = torch.as_tensor(images)
    vec = torch.as_tensor(np.clip((vectors - mean) / std, -10, 10), dtype=torch.float32)
    y = torch.as_tensor(actions, dtype=torch.float32)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    loss_sum = 0.0
    for _ in range(config.epochs):
        perm = torch.randperm(len(y), generator=generator)
        loss_sum = 0.0
        for i in range(0, len(y), config.batch_size):
            idx = perm[i:i + config.batch_size]
            loss = nn.functional.mse_loss(net(img[idx].float(), vec[idx]), y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            loss_sum += loss.item() * len(idx)
    return loss_sum / len(y)


def _to_policy(net, mean, std, memory_params, config, env, env_id, env_kwargs, recipe):
    convs = [m for m in net.convs if isinstance(m, nn.Conv2d)]
    lin = [m for m in net.head if isinstance(m, nn.Linear)]
    return MapCNNPolicy([(m.weight.detach().numpy(), m.bias.detach().numpy(), s)
                         for m, (_, s) in zip(convs, config.convs)],
                        [m.weight.detach().numpy() for m in lin], [m.bias.detach().numpy() for m in lin],
                        memory=memory_params, obs_keys=MASKED_KEYS,
                        obs_shapes={k: env.observation_space[k].shape for k in MASKED_KEYS}, mean=mean, std=std,
                        activation=config.activation, known_var=KNOWN_VAR, env_id=env_id, env_kwargs=env_kwargs,
                        recipe=recipe)


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
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    try:
        expert = make_expert("navigator", env)
        if "pose" not in env.observation_space.spaces:
            raise ValueError(f"env_id: the map memory reads the estimated pose; {env_id} does not observe it "
                             f"(use a v1 or v2 id)")
        stencil = env.unwrapped._stencil
        memory_params = {"half": 18.0, "cell": 0.2, "max_var": 0.5, "scales": [list(s) for s in config.scales],
                         "stencil_rays": int(stencil.n_rays), "stencil_radii": [float(r) for r in stencil.radii]}
        memory = MapMemory(stencil.points_robot, half=18.0, cell=0.2, max_var=0.5, scales=config.scales)
        image_shape = (len(MAP_CHANNELS) * len(config.scales),) + (config.scales[0][0],) * 2
        rng = np.random.default_rng(config.seed)
        gen = torch.Generator().manual_seed(config.seed)
        torch.manual_seed(config.seed)
        span = TRAIN_SEEDS[1] - TRAIN_SEEDS[0]
        seeds = (TRAIN_SEEDS[0] + (config.seed * 7919 + i) % span for i in range(10**9))
        data = None
        net = mean = std = policy = None
        history = []
        with tqdm(total=config.rounds * config.steps_per_round, desc=f"dagger_map {env_id}", unit="step",
                  disable=None if progress is None else not progress) as bar:
            for k in range(config.rounds):
                beta = 1.0 if k == 0 else config.beta_decay ** k
                *new, out = _rollout(env, expert, memory, policy, beta=beta, steps=config.steps_per_round, rng=rng,
                                     seeds=seeds, bar=bar)
                data = new if data is None else [np.concatenate([a, b]) for a, b in zip(data, new)]
                if net is None:  # the normalisation of the expert's own data, fixed from then on
                    mean = data[1].mean(0).astype(np.float64)
                    std = np.maximum(data[1].std(0).astype(np.float64), 1e-3)
                    net = MapNet(image_shape, len(mean), config)
                loss = _fit(net, *data, mean, std, config, gen)
                policy = _to_policy(net, mean, std, memory_params, config, env, env_id, policy_env_kwargs, recipe)
                row = {"round": k, "beta": beta, "steps": int(len(data[2])), **out, "loss": loss,
                       "wall_s": time.perf_counter() - t_wall, "cpu_s": time.process_time() - t_cpu}
                history.append(row)
                if callback is not None:
                    callback(k, policy, row)
    finally:
        env.close()
    return policy, history
