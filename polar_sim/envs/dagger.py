"""The one DAgger loop every imitation recipe shares (Ross, Gordon and Bagnell, AISTATS 2011), with
the learner as a parameter: the memoryless MLP (:mod:`polar_sim.envs.imitation`), the map-memory
CNN (:mod:`polar_sim.envs.imitation_map`), either with a regression or a discrete action head.

Round 0 rolls out the expert and fits the learner to its actions (behaviour cloning); round k >= 1
executes the expert's action with probability ``beta_decay ** k`` and the learner's otherwise,
labels every visited state with the expert's action, aggregates, and refits (warm-started). The
expert and the learner both see every observation of the trajectory driven, whoever acts, so the
expert's label and the learner's input (its memory included) describe the same history.

A learner has ``reset()`` (episode start), ``observe(obs)`` (the sample of one observation: a
tuple of arrays whose last is the stencil feature vector; called on every step), ``act(sample)``
(its current policy's action), ``dtypes`` (how each array of a sample is stored), ``fit(data,
actions, generator)`` (refit on all the data; returns the loss) and ``policy`` (the numpy policy of
the last fit).
:class:`TorchLearner` implements all but the network and the export.
"""

from __future__ import annotations

import time

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from polar_sim._validation import as_float, as_int
from polar_sim.envs.action_head import check_head, head_outputs, two_hot

__all__ = ["TRAIN_SEEDS", "training_seeds", "rollout", "run_dagger", "fit_net", "TorchLearner", "check_fit",
           "key_columns"]

#: The training worlds: episode seeds cycle through this range (dev worlds start at 1000, held-out at 10,000).
TRAIN_SEEDS = (0, 1000)


def training_seeds(seed):
    """The episode seeds of a run seeded ``seed``: the training worlds in order from a seed-dependent start."""
    span = TRAIN_SEEDS[1] - TRAIN_SEEDS[0]
    return (TRAIN_SEEDS[0] + (seed * 7919 + i) % span for i in range(10**9))


def rollout(env, expert, learner, *, beta, steps, rng, seeds, acting=True, bar=None):
    """Run ``steps`` env steps, each executing the expert's action with probability ``beta`` and
    the learner's otherwise (``acting`` False: always the expert; the coin is then not drawn).

    Returns the samples (one array per element of ``learner.observe``'s tuple, stacked with
    ``learner.dtypes``), the expert's actions (steps, 2) float32 and the finished episodes'
    outcomes ``{"episodes", "success", "collision"}``. ``seeds`` yields episode seeds."""
    samples, actions = [], []
    out = {"episodes": 0, "success": 0, "collision": 0}

    def start():
        obs, _ = env.reset(seed=next(seeds))
        expert.reset()
        learner.reset()
        return obs

    obs = start()
    for _ in range(steps):
        a_exp = np.asarray(expert(obs), np.float32)
        sample = learner.observe(obs)
        samples.append(tuple(np.asarray(x, dt) for x, dt in zip(sample, learner.dtypes)))
        actions.append(a_exp)
        a = a_exp if not acting or rng.random() < beta else learner.act(sample)
        obs, _, term, trunc, info = env.step(a)
        if bar is not None:
            bar.update(1)
        if term or trunc:
            out["episodes"] += 1
            out["success"] += bool(info.get("is_success"))
            out["collision"] += bool(info.get("collision"))
            obs = start()
    return [np.asarray(col) for col in zip(*samples)], np.asarray(actions, np.float32), out


def run_dagger(env, expert, learner, *, rounds, steps_per_round, beta_decay, seed, desc="dagger", progress=True,
               callback=None):
    """Behaviour cloning, then ``rounds - 1`` DAgger rounds, of ``expert`` by ``learner`` on ``env``.

    ``seed`` seeds torch, the mixture's coin and the first training world. ``callback(round,
    policy, history_row)`` runs after each round. Returns the last round's policy and the history:
    per round beta, the data size (``steps``), the rollouts' episodes, successes and collisions, the
    fit's loss, and the wall and CPU seconds since the start."""
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    rng = np.random.default_rng(seed)
    generator = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    seeds = training_seeds(seed)
    data = actions = policy = None
    history = []
    with tqdm(total=rounds * steps_per_round, desc=desc, unit="step",
              disable=None if progress is None else not progress) as bar:
        for k in range(rounds):
            beta = 1.0 if k == 0 else beta_decay ** k
            new, new_actions, out = rollout(env, expert, learner, beta=beta, steps=steps_per_round, rng=rng,
                                            seeds=seeds, acting=k > 0, bar=bar)
            data = new if data is None else [np.concatenate([a, b]) for a, b in zip(data, new)]
            actions = new_actions if actions is None else np.concatenate([actions, new_actions])
            loss = learner.fit(data, actions, generator)
            policy = learner.policy
            row = {"round": k, "beta": beta, "steps": int(len(actions)), **out, "loss": loss,
                   "wall_s": time.perf_counter() - t_wall, "cpu_s": time.process_time() - t_cpu}
            history.append(row)
            if callback is not None:
                callback(k, policy, row)
    return policy, history


def fit_net(net, inputs, targets, loss_fn, *, epochs, batch_size, lr, generator, weights=None):
    """Adam on ``loss_fn(net(*batch), target)`` over shuffled minibatches of ``inputs`` (tensors,
    converted to float32 per batch) and ``targets``, ``epochs`` passes; returns the last pass's mean loss.

    With ``weights`` (n,), ``loss_fn`` returns per-sample losses and a batch's loss is their
    ``weights``-weighted mean."""
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    n = len(targets)
    loss_sum = 0.0
    for _ in range(epochs):
        perm = torch.randperm(n, generator=generator)
        loss_sum = 0.0
        for i in range(0, n, batch_size):
            idx = perm[i:i + batch_size]
            loss = loss_fn(net(*(x[idx].float() for x in inputs)), targets[idx])
            if weights is not None:
                loss = (loss * weights[idx]).sum() / weights[idx].sum()
            opt.zero_grad()
            loss.backward()
            opt.step()
            loss_sum += loss.item() * len(idx)
    return loss_sum / n


def _soft_cross_entropy(logits, target):
    return -(target * torch.log_softmax(logits, 1)).sum(1).mean()


def _per_sample(loss_fn):
    """``loss_fn``'s per-sample twin (n,): the mean over a sample's outputs, or its cross-entropy."""
    if loss_fn is nn.functional.mse_loss:
        return lambda pred, y: ((pred - y) ** 2).mean(1)
    return lambda logits, y: -(y * torch.log_softmax(logits, 1)).sum(1)


def key_columns(keys, space, key="sdf"):
    """The slice of ``key`` in the feature vector of ``keys`` (flattened and concatenated in order)
    of the ``Dict`` observation ``space``; an empty slice if ``key`` is not read."""
    start = 0
    for k in keys:
        n = int(np.prod(space[k].shape))
        if k == key:
            return slice(start, start + n)
        start += n
    return slice(0, 0)


def check_fit(epochs, batch_size, lr, head, near_weight=1.0, near_distance=0.5):
    """Check the fit's parameters (``ValueError`` naming the bad one); returns the checked ``head``."""
    as_int(epochs, "epochs", minimum=1, maximum=10_000)
    as_int(batch_size, "batch_size", minimum=1, maximum=1_000_000)
    as_float(lr, "lr", minimum=0.0, maximum=1.0, exclusive_minimum=True)
    as_float(near_weight, "near_weight", minimum=1.0, maximum=1000.0)
    as_float(near_distance, "near_distance", minimum=0.0, maximum=10.0, exclusive_minimum=True)
    return check_head(head)


class TorchLearner:
    """A learner fitted by :func:`fit_net`: the last array of a sample (the stencil features) is
    normalised by the mean and std of the first round's data (the expert's own, fixed from then on),
    the targets are the expert's actions (regression, mean squared error) or their two-hot bins
    (``head``, soft cross-entropy). Subclasses give ``observe``, ``make_net(data)``, ``inputs``
    (the policy's inputs of a sample), ``export`` and ``sdf_columns`` (where the stencil's
    distances are in the features); the net is made at the first fit.

    ``near_weight`` > 1 weighs the samples near an obstacle (a known stencil distance below
    ``near_distance`` m) that much more in the loss: the states where a wrong action collides."""

    dtypes = ()
    sdf_columns = slice(0, 0)

    def __init__(self, *, epochs, batch_size, lr, head=None, near_weight=1.0, near_distance=0.5):
        self.head = check_fit(epochs, batch_size, lr, head, near_weight, near_distance)
        self.epochs, self.batch_size, self.lr = int(epochs), int(batch_size), float(lr)
        self.near_weight, self.near_distance = float(near_weight), float(near_distance)
        self.net = self.mean = self.std = self.policy = None
        self.n_out = head_outputs(self.head)

    def reset(self):
        """Episode start (nothing to forget by default)."""

    def normalised(self, x):
        """The features ``x`` normalised as the policy reads them."""
        return np.clip((x - self.mean) / self.std, -10, 10)

    def act(self, sample):
        return self.policy.act(*self.inputs(sample))

    def fit(self, data, actions, generator):
        if self.net is None:
            self.mean = data[-1].mean(0).astype(np.float64)
            self.std = np.maximum(data[-1].std(0).astype(np.float64), 1e-3)
            self.net = self.make_net(data)
        inputs = [torch.as_tensor(x) for x in data[:-1]]
        inputs.append(torch.as_tensor(self.normalised(data[-1]), dtype=torch.float32))
        if self.head is None:
            targets, loss_fn = torch.as_tensor(actions, dtype=torch.float32), nn.functional.mse_loss
        else:
            targets, loss_fn = torch.as_tensor(two_hot(self.head, actions), dtype=torch.float32), _soft_cross_entropy
        weights = None
        if self.near_weight != 1.0:
            near = data[-1][:, self.sdf_columns].min(1) < self.near_distance
            weights = torch.as_tensor(np.where(near, self.near_weight, 1.0), dtype=torch.float32)
            loss_fn = _per_sample(loss_fn)
        loss = fit_net(self.net, inputs, targets, loss_fn, epochs=self.epochs, batch_size=self.batch_size,
                       lr=self.lr, generator=generator, weights=weights)
        self.policy = self.export()
        return loss
