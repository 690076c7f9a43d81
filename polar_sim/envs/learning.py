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

__all__ = ["ForwardDriveAction", "SDFGridExtractor", "ppo_recipe", "wrap_action", "env_action", "make_model",
           "ObsNormaliser", "save_policy", "load_policy", "POLICY_FORMAT_VERSION"]

POLICY_FORMAT_VERSION = 1


class ForwardDriveAction(gym.ActionWrapper):
    """The policy's action ``b`` in ``Box(-1, 1, (2,))`` mapped to the env's normalised
    ``(v, omega)``: ``v = min_drive + (1 - min_drive) * (b0 + 1) / 2`` (forward only, in
    ``[min_drive, 1]`` of ``max_speed``) and ``omega = b1``; ``b`` is first clipped to the box.

    A zero action then drives at ``(1 + min_drive) / 2`` of ``max_speed`` instead of standing
    still, so a freshly initialised Gaussian policy (mean 0) explores by driving: the progress
    term of the reward is seen from the first rollout. The env (its action space, reward and
    dynamics) is unchanged; only the learner's parametrisation is.

    Parameters
    ----------
    env : gymnasium.Env
        An env whose action space is ``Box(-1, 1, (2,))`` (normalised speed and yaw rate).
    min_drive : float, default=0.0
        The forward speed at ``b0 = -1``, as a fraction of ``max_speed``, in [0, 1).
    """

    def __init__(self, env, min_drive=0.0):
        sp = env.action_space
        if not (isinstance(sp, gym.spaces.Box) and sp.shape == (2,) and np.all(sp.low == -1) and np.all(sp.high == 1)):
            raise ValueError(f"env: expected an action space Box(-1, 1, (2,)), got {sp!r}")
        self.min_drive = _check_min_drive(min_drive)
        super().__init__(env)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    @staticmethod
    def map_action(b, min_drive=0.0):
        """The env action (2,) float32 of the policy action ``b`` (2,)."""
        m = _check_min_drive(min_drive)
        b = np.clip(np.asarray(b, np.float64).reshape(2), -1.0, 1.0)
        return np.array([m + (1.0 - m) * (b[0] + 1.0) / 2.0, b[1]], np.float32)

    def action(self, action):
        return self.map_action(action, self.min_drive)


def _check_min_drive(m):
    if isinstance(m, bool) or not isinstance(m, (int, float, np.integer, np.floating)) or not (0.0 <= m < 1.0):
        raise ValueError(f"min_drive: expected a number in [0, 1), got {m!r}")
    return float(m)


#: Action wrappers a recipe may name (``recipe["action"]``).
ACTION_WRAPPERS = {"forward_drive": ForwardDriveAction}


def wrap_action(env, action):
    """``env`` wrapped as ``action`` says (a recipe's ``"action"``: None, or ``{"name": ...,
    "kwargs": {...}}`` with a name of :data:`ACTION_WRAPPERS`)."""
    if action is None:
        return env
    if not isinstance(action, dict) or action.get("name") not in ACTION_WRAPPERS:
        raise ValueError(f"action: expected None or {{'name': one of {sorted(ACTION_WRAPPERS)}, 'kwargs': ...}}, "
                         f"got {action!r}")
    return ACTION_WRAPPERS[action["name"]](env, **action.get("kwargs", {}))


def env_action(action, b):
    """The env action of the policy action ``b`` under a recipe's ``action`` (None: ``b`` clipped)."""
    if action is None:
        return np.clip(np.asarray(b, np.float64), -1.0, 1.0).astype(np.float32)
    cls = ACTION_WRAPPERS.get(action.get("name")) if isinstance(action, dict) else None
    if cls is None:
        raise ValueError(f"action: unknown action parametrisation {action!r}")
    return cls.map_action(b, **action.get("kwargs", {}))


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

    ``recipe["action"]`` is the policy's action parametrisation, applied by :func:`wrap_action`
    (training) and :func:`env_action` (evaluation): ``{"name": "forward_drive", "kwargs": {}}``
    (:class:`ForwardDriveAction`, forward speed in [0, 1] of ``max_speed``; a zero action drives
    at half speed). With the env's own symmetric action the initial policy (mean 0) stands still,
    and PPO learned to stand still even in an empty room: 0 % on 20 dev worlds after 20k steps
    (clutter 0, pose truth), against 30 % with ``forward_drive`` (benchmarks/RESULTS.md).
    """
    if obs_mode not in ("stencil", "grid"):
        raise ValueError(f"obs_mode: expected 'stencil' or 'grid', got {obs_mode!r}")
    policy_kwargs = {"net_arch": {"pi": [128, 128], "vf": [128, 128]}, "log_std_init": -1.0}
    if obs_mode == "grid":
        policy_kwargs.update(features_extractor_class="SDFGridExtractor", features_extractor_kwargs={})
    action = {"name": "forward_drive", "kwargs": {}}
    kwargs = {"n_steps": 512, "batch_size": 256, "n_epochs": 10, "learning_rate": 3e-4, "gamma": 0.99,
              "gae_lambda": 0.95, "ent_coef": 0.0, "policy_kwargs": policy_kwargs}
    if recurrent:
        policy_kwargs.update(lstm_hidden_size=128, n_lstm_layers=1, net_arch={"pi": [128], "vf": [128]})
        kwargs.update(n_steps=128, batch_size=128)
        return {"algorithm": "RecurrentPPO", "policy": "MultiInputLstmPolicy", "kwargs": kwargs, "action": action}
    return {"algorithm": "PPO", "policy": "MultiInputPolicy", "kwargs": kwargs, "action": action}


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
