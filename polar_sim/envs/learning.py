"""PPO recipes for GPISNav on 2 CPU cores (stable-baselines3, sb3-contrib), and a policy file
format without pickle.

Needs ``stable-baselines3`` and ``sb3-contrib`` (the ``[test]`` extra) and CPU torch.

- :func:`ppo_recipe` gives the algorithm, policy and keyword arguments for an observation mode
  and whether the policy is recurrent.
- :class:`SDFGridExtractor` reads the ``sdf_grid`` image with a small CNN (SB3's ``NatureCNN``
  needs 36x36 uint8 images; the grid is 32x32 float32 in metres) and the vector keys as they are.
- :func:`save_policy` / :func:`load_policy` store the policy's weights, the recipe and the
  observation normalisation in one ``.npz`` (SB3's own ``save`` pickles parts of the model).
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

__all__ = ["SDFGridExtractor", "ppo_recipe", "make_model", "ObsNormaliser", "save_policy", "load_policy",
           "POLICY_FORMAT_VERSION"]

POLICY_FORMAT_VERSION = 1


class SDFGridExtractor(BaseFeaturesExtractor):
    """Features of a ``Dict`` observation: a CNN over ``sdf_grid`` (C, N, N), N divisible by 8,
    beside the other keys flattened.

    The CNN is three 3x3 convolutions (16, 32, 32 channels), each followed by ReLU and a 2x2 max
    pool, so a 32x32 image (8 m at 0.25 m) becomes 4x4 cells of 2 m, then a linear layer to
    ``cnn_features``.
    """

    def __init__(self, observation_space: gym.spaces.Dict, cnn_features: int = 128):
        grid = observation_space["sdf_grid"]
        c, n, m = grid.shape
        if n != m or n % 8:
            raise ValueError(f"sdf_grid: expected a square image with a side divisible by 8, got {grid.shape}")
        flat = int(sum(int(np.prod(s.shape)) for k, s in observation_space.spaces.items() if k != "sdf_grid"))
        super().__init__(observation_space, features_dim=cnn_features + flat)
        self.cnn = nn.Sequential(
            nn.Conv2d(c, 16, 3, padding=1), nn.ReLU(), nn.MaxPool2d(2),
            nn.Conv2d(16, 32, 3, padding=1), nn.ReLU(), nn.MaxPool2d(2),
            nn.Conv2d(32, 32, 3, padding=1), nn.ReLU(), nn.MaxPool2d(2),
            nn.Flatten(), nn.Linear(32 * (n // 8) ** 2, cnn_features), nn.ReLU())
        self.keys = [k for k in observation_space.spaces if k != "sdf_grid"]

    def forward(self, obs):
        parts = [self.cnn(obs["sdf_grid"])] + [obs[k].flatten(1) for k in self.keys]
        return torch.cat(parts, dim=1)


def ppo_recipe(obs_mode="stencil", recurrent=False):
    """The recipe: ``{"algorithm": "PPO" | "RecurrentPPO", "policy": ..., "kwargs": {...}}``.

    Chosen on dev seeds (< 10,000) for 300k steps on one CPU core: 4 environments in one process,
    2048 steps per update (512 per environment), 10 epochs of minibatches of 256, learning rate
    3e-4, gamma 0.99, a narrow initial action noise (std 0.37) so that early episodes are not
    spent at the action bounds, and two hidden layers of 128. The grid adds
    :class:`SDFGridExtractor`; the recurrent policy an LSTM of 128 (sb3-contrib's RecurrentPPO,
    sequences of 128 steps per environment and update).
    """
    if obs_mode not in ("stencil", "grid"):
        raise ValueError(f"obs_mode: expected 'stencil' or 'grid', got {obs_mode!r}")
    policy_kwargs = {"net_arch": {"pi": [128, 128], "vf": [128, 128]}, "log_std_init": -1.0}
    if obs_mode == "grid":
        policy_kwargs.update(features_extractor_class="SDFGridExtractor", features_extractor_kwargs={})
    kwargs = {"n_steps": 512, "batch_size": 256, "n_epochs": 10, "learning_rate": 3e-4, "gamma": 0.99,
              "gae_lambda": 0.95, "ent_coef": 0.0, "policy_kwargs": policy_kwargs}
    if recurrent:
        policy_kwargs.update(lstm_hidden_size=128, n_lstm_layers=1, net_arch={"pi": [128], "vf": [128]})
        kwargs.update(n_steps=128, batch_size=128)
        return {"algorithm": "RecurrentPPO", "policy": "MultiInputLstmPolicy", "kwargs": kwargs}
    return {"algorithm": "PPO", "policy": "MultiInputPolicy", "kwargs": kwargs}


def _resolved(recipe):
    kw = json.loads(json.dumps(recipe["kwargs"]))
    pk = kw["policy_kwargs"]
    if pk.get("features_extractor_class") == "SDFGridExtractor":
        pk["features_extractor_class"] = SDFGridExtractor
    return kw


def make_model(recipe, env, *, seed=0):
    """The SB3 model of ``recipe`` on ``env`` (a VecEnv or an Env), CPU."""
    if recipe["algorithm"] == "RecurrentPPO":
        from sb3_contrib import RecurrentPPO as algo
    else:
        from stable_baselines3 import PPO as algo
    return algo(recipe["policy"], env, seed=seed, device="cpu", verbose=0, **_resolved(recipe))


class ObsNormaliser:
    """The observation normalisation of SB3's ``VecNormalize`` as plain arrays:
    ``clip((obs[k] - mean[k]) / sqrt(var[k] + eps), -clip, clip)`` per key."""

    def __init__(self, mean, var, clip=10.0, eps=1e-8):
        self.mean = {k: np.asarray(v, np.float64) for k, v in mean.items()}
        self.var = {k: np.asarray(v, np.float64) for k, v in var.items()}
        self.clip, self.eps = float(clip), float(eps)

    @classmethod
    def from_vecnormalize(cls, venv):
        rms = venv.obs_rms
        return cls({k: r.mean for k, r in rms.items()}, {k: r.var for k, r in rms.items()}, venv.clip_obs,
                   venv.epsilon)

    def __call__(self, obs):
        return {k: np.clip((np.asarray(obs[k], np.float64) - self.mean[k]) / np.sqrt(self.var[k] + self.eps),
                           -self.clip, self.clip).astype(np.float32) for k in self.mean}


def save_policy(path, model, recipe, normaliser):
    """Write the policy's weights, the recipe and the normalisation to ``path`` (.npz), atomically."""
    path = Path(path)
    arrays = {f"policy/{k}": v.detach().cpu().numpy() for k, v in model.policy.state_dict().items()}
    arrays.update({f"obs_mean/{k}": v for k, v in normaliser.mean.items()})
    arrays.update({f"obs_var/{k}": v for k, v in normaliser.var.items()})
    meta = {"format_version": POLICY_FORMAT_VERSION, "recipe": recipe, "clip": normaliser.clip, "eps": normaliser.eps}
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp.npz")
    os.close(fd)
    try:
        np.savez(tmp, meta=np.array(json.dumps(meta)), **arrays)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def load_policy(path, env):
    """``(model, normaliser)`` from :func:`save_policy`'s file, on ``env`` (spaces as trained)."""
    with np.load(path, allow_pickle=False) as f:
        meta = json.loads(str(f["meta"]))
        if meta.get("format_version") != POLICY_FORMAT_VERSION:
            raise ValueError(f"path: policy format version {meta.get('format_version')!r}, expected "
                             f"{POLICY_FORMAT_VERSION}")
        state = {k[len("policy/"):]: torch.as_tensor(f[k]) for k in f.files if k.startswith("policy/")}
        mean = {k[len("obs_mean/"):]: f[k] for k in f.files if k.startswith("obs_mean/")}
        var = {k[len("obs_var/"):]: f[k] for k in f.files if k.startswith("obs_var/")}
    model = make_model(meta["recipe"], env)
    model.policy.load_state_dict(state)
    return model, ObsNormaliser(mean, var, meta["clip"], meta["eps"])
