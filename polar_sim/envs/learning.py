"""stable-baselines3 / sb3-contrib recipes for GPISNav on 2 CPU cores, and their policy files.

Needs ``stable-baselines3`` and ``sb3-contrib`` (the ``[test]`` extra) and CPU torch.

- :func:`ppo_recipe` gives the algorithm, policy and keyword arguments for an observation mode
  and whether the policy is recurrent; :func:`sb3_recipe` the same for SAC and TQC.
- :class:`SDFGridExtractor` reads the ``sdf_grid`` image with a small CNN (SB3's ``NatureCNN``
  needs 36x36 uint8 images; the grid is 32x32 float32 in metres) and the vector keys as they are.
- :class:`FeatureObservation` flattens chosen keys into one normalised vector, so that an SB3
  ``MlpPolicy`` is exactly an :class:`~polar_sim.envs.mlp_policy.MLPPolicy` (:func:`export_mlp`)
  and can start from imitation weights (:func:`load_mlp_into`).
- :func:`save_policy` / :func:`load_model` store an SB3 policy's weights, the recipe and the
  observation normalisation in one ``.npz`` of kind ``"sb3"`` (SB3's own ``save`` pickles parts of
  the model); :class:`SB3Policy` acts with it as ``policy(obs) -> action``. Users load any policy
  file with :func:`polar_sim.envs.evaluate.load_policy`.
"""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from polar_sim.envs.action_maps import ACTION_WRAPPERS, ForwardDriveAction, env_action, wrap_action
from polar_sim.envs.far_mask import FarAsUnknown, feature_vector
from polar_sim.envs.features import FeatureObservation
from polar_sim.envs.mlp_policy import MLPPolicy
from polar_sim.envs.policy_file import check_observation_space, read_policy_file, write_policy_file

__all__ = ["ForwardDriveAction", "ACTION_WRAPPERS", "SDFGridExtractor", "FeatureObservation", "ppo_recipe",
           "sb3_recipe", "wrap_action", "env_action", "make_model", "ObsNormaliser", "save_policy", "load_model",
           "SB3Policy", "export_mlp", "load_mlp_into", "ALGORITHMS"]

#: SB3 algorithms a recipe may name, and where they live.
ALGORITHMS = {"PPO": "stable_baselines3", "RecurrentPPO": "sb3_contrib", "SAC": "stable_baselines3",
              "TQC": "sb3_contrib"}


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


def sb3_recipe(algorithm):
    """An off-policy recipe (``"SAC"`` or ``"TQC"``) on the stencil: two layers of 256, a replay
    buffer of 100k steps, 1,000 random steps first, one gradient step per env step, the
    forward-drive action."""
    if algorithm not in ("SAC", "TQC"):
        raise ValueError(f"algorithm: expected 'SAC' or 'TQC', got {algorithm!r}")
    kwargs = {"buffer_size": 100_000, "learning_starts": 1000, "batch_size": 256, "learning_rate": 3e-4,
              "gamma": 0.99, "policy_kwargs": {"net_arch": [256, 256]}}
    return {"algorithm": algorithm, "policy": "MultiInputPolicy", "kwargs": kwargs,
            "action": {"name": "forward_drive", "kwargs": {}}}


def _resolved(recipe):
    kw = json.loads(json.dumps(recipe["kwargs"]))
    pk = kw.get("policy_kwargs", {})
    if pk.get("features_extractor_class") == "SDFGridExtractor":
        pk["features_extractor_class"] = SDFGridExtractor
    if pk.get("activation_fn") in ("tanh", "relu"):
        pk["activation_fn"] = {"tanh": nn.Tanh, "relu": nn.ReLU}[pk["activation_fn"]]
    return kw


def _algorithm(name):
    if name not in ALGORITHMS:
        raise ValueError(f"algorithm: expected one of {sorted(ALGORITHMS)}, got {name!r}")
    import importlib

    return getattr(importlib.import_module(ALGORITHMS[name]), name)


def make_model(recipe, env, *, seed=0):
    """The SB3 model of ``recipe`` on ``env`` (a VecEnv or an Env), CPU."""
    return _algorithm(recipe["algorithm"])(recipe["policy"], env, seed=seed, device="cpu", verbose=0,
                                           **_resolved(recipe))


class ObsNormaliser:
    """The observation normalisation of SB3's ``VecNormalize`` as plain arrays:
    ``clip((obs[k] - mean[k]) / sqrt(var[k] + eps), -clip, clip)`` per key (``mean`` an array
    instead of a dict: the whole observation, for a flat ``Box``)."""

    def __init__(self, mean, var, clip=10.0, eps=1e-8):
        self.flat = not isinstance(mean, dict)
        m, v = ({"": mean}, {"": var}) if self.flat else (mean, var)
        self.mean = {k: np.asarray(x, np.float64) for k, x in m.items()}
        self.var = {k: np.asarray(x, np.float64) for k, x in v.items()}
        self.clip, self.eps = float(clip), float(eps)

    @classmethod
    def from_vecnormalize(cls, venv):
        rms = venv.obs_rms
        if isinstance(rms, dict):
            return cls({k: r.mean for k, r in rms.items()}, {k: r.var for k, r in rms.items()}, venv.clip_obs,
                       venv.epsilon)
        return cls(rms.mean, rms.var, venv.clip_obs, venv.epsilon)

    @classmethod
    def identity(cls, space):
        """No normalisation (mean 0, variance 1 - eps, no clip) for the keys of ``space``."""
        spaces = getattr(space, "spaces", None) or {"": space}
        ob = cls({k: np.zeros(s.shape) for k, s in spaces.items()}, {k: np.ones(s.shape) for k, s in spaces.items()},
                 np.inf, 0.0)
        ob.flat = not hasattr(space, "spaces")
        return ob

    def __call__(self, obs):
        if self.flat:
            return self._one("", obs)
        return {k: self._one(k, obs[k]) for k in self.mean}

    def _one(self, k, x):
        return np.clip((np.asarray(x, np.float64) - self.mean[k]) / np.sqrt(self.var[k] + self.eps),
                       -self.clip, self.clip).astype(np.float32)


def save_policy(path, model, recipe, normaliser, *, env_id=None, env_kwargs=None):
    """Write an SB3 model's policy weights, the recipe and the normalisation to ``path`` (.npz,
    kind ``"sb3"``), atomically."""
    space = model.observation_space
    shapes = {k: s.shape for k, s in space.spaces.items()} if hasattr(space, "spaces") else {"": space.shape}
    arrays = {f"policy/{k}": v.detach().cpu().numpy() for k, v in model.policy.state_dict().items()}
    arrays.update({f"obs_mean/{k}": v for k, v in normaliser.mean.items()})
    arrays.update({f"obs_var/{k}": v for k, v in normaliser.var.items()})
    meta = {"kind": "sb3", "recipe": recipe, "clip": normaliser.clip, "eps": normaliser.eps,
            "obs_shapes": shapes, "env_id": env_id, "env_kwargs": env_kwargs or {}}
    write_policy_file(path, meta, arrays)
    return path


def load_model(path, env, name="path"):
    """``(model, normaliser, meta)`` from :func:`save_policy`'s file, on ``env`` (spaces as trained)."""
    meta, arrays = read_policy_file(path, name)
    if meta["kind"] != "sb3":
        raise ValueError(f"{name}: a policy of kind {meta['kind']!r}, expected 'sb3'")
    features = meta["recipe"].get("features")
    if features:  # trained on the flat (masked) stencil: rebuild on the same vector
        if features.get("far_unknown"):
            env = FarAsUnknown(env)
        env = FeatureObservation(env, features["keys"], known_var=features["known_var"])
    shapes = meta.get("obs_shapes", {})
    if "" in shapes:
        if tuple(env.observation_space.shape or ()) != tuple(shapes[""]):
            raise ValueError(f"env: observation mismatch: shape {env.observation_space.shape} in the env, "
                             f"{tuple(shapes[''])} in the policy")
    else:
        check_observation_space(shapes, env.observation_space)
    state = {k[len("policy/"):]: torch.as_tensor(v) for k, v in arrays.items() if k.startswith("policy/")}
    mean = {k[len("obs_mean/"):]: v for k, v in arrays.items() if k.startswith("obs_mean/")}
    var = {k[len("obs_var/"):]: v for k, v in arrays.items() if k.startswith("obs_var/")}
    if set(mean) == {""}:
        mean, var = mean[""], var[""]
    model = make_model(meta["recipe"], env)
    try:
        model.policy.load_state_dict(state)
    except RuntimeError as exc:
        raise ValueError(f"{name}: the weights do not fit the recipe's network ({str(exc)[:200]})") from None
    return model, ObsNormaliser(mean, var, meta["clip"], meta["eps"]), meta


class SB3Policy:
    """``policy(obs) -> action`` of an SB3 model: deterministic actions on normalised
    observations (first flattened as the recipe's ``features`` say, ``{"keys", "known_var",
    "far_unknown"}``, if it has them: :func:`~polar_sim.envs.far_mask.feature_vector`), mapped to the env's action by
    the recipe's ``action``; ``reset()`` clears a recurrent policy's state."""

    def __init__(self, model, normaliser, recipe, env_id=None, env_kwargs=None):
        self.model, self.normaliser, self.recipe = model, normaliser, recipe
        self.features = recipe.get("features")
        self.recurrent = recipe["algorithm"] == "RecurrentPPO"
        self.env_id, self.env_kwargs = env_id, dict(env_kwargs or {})
        self.reset()

    def reset(self):
        self._state, self._start = None, True

    def save(self, path):
        """Write the policy to ``path`` (.npz, kind ``"sb3"``)."""
        return save_policy(path, self.model, self.recipe, self.normaliser, env_id=self.env_id,
                           env_kwargs=self.env_kwargs)

    def __call__(self, obs):
        if self.features:
            obs = feature_vector(obs, **self.features)
        o = self.normaliser(obs)
        o = o[None] if self.normaliser.flat else {k: v[None] for k, v in o.items()}
        if self.recurrent:
            a, self._state = self.model.predict(o, state=self._state, episode_start=np.array([self._start]),
                                                deterministic=True)
            self._start = False
        else:
            a, _ = self.model.predict(o, deterministic=True)
        return env_action(self.recipe.get("action"), a[0])


def _actor_linears(model):
    """The Linear layers from features to the action mean of an SB3 ``MlpPolicy`` (PPO)."""
    pi = [m for m in model.policy.mlp_extractor.policy_net if isinstance(m, nn.Linear)]
    return pi + [model.policy.action_net]


def export_mlp(model, mean, std, *, keys, obs_shapes, recipe, clip=10.0, env_id=None, env_kwargs=None,
               known_var=None):
    """The numpy :class:`MLPPolicy` of a PPO ``MlpPolicy`` trained on :class:`FeatureObservation`
    (``keys``, ``known_var``) normalised by ``mean``/``std``; its deterministic action is the same."""
    act = model.policy.mlp_extractor.policy_net
    acts = {type(m) for m in act if not isinstance(m, nn.Linear)}
    activation = "relu" if acts == {nn.ReLU} else "tanh"
    if acts - {nn.Tanh, nn.ReLU} or len(acts) > 1:
        raise ValueError(f"model: only tanh or relu MLP policies export, got {acts}")
    lin = _actor_linears(model)
    return MLPPolicy([m.weight.detach().numpy() for m in lin], [m.bias.detach().numpy() for m in lin],
                     obs_keys=keys, obs_shapes=obs_shapes, mean=mean, std=std, clip=clip, activation=activation,
                     action=recipe.get("action"), env_id=env_id, env_kwargs=env_kwargs, recipe=recipe,
                     known_var=known_var)


def load_mlp_into(model, policy):
    """Copy an :class:`MLPPolicy`'s layers into a PPO ``MlpPolicy`` of the same widths (the
    imitation weights as PPO's starting actor; the critic is left as initialised)."""
    lin = _actor_linears(model)
    if len(lin) != len(policy.weights) or any(m.weight.shape != w.shape for m, w in zip(lin, policy.weights)):
        raise ValueError(f"policy: layers {[w.shape for w in policy.weights]} do not fit the model's "
                         f"{[tuple(m.weight.shape) for m in lin]}")
    with torch.no_grad():
        for m, w, b in zip(lin, policy.weights, policy.biases):
            m.weight.copy_(torch.as_tensor(w, dtype=torch.float32))
            m.bias.copy_(torch.as_tensor(b, dtype=torch.float32))
    return model
