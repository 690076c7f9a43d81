"""Flat feature vectors of a Dict observation, for learners that take one ``Box`` (an SB3
``MlpPolicy``, RLlib's default model); numpy and gymnasium only."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

__all__ = ["FeatureObservation", "STENCIL_KEYS"]

#: The stencil keys a learned GPISNav policy reads by default: ``sdf_var`` and ``pose`` are left
#: out (the variance's scale differs between map sources, the pose's range between tiers).
STENCIL_KEYS = ("goal", "sdf", "sdf_grad", "twist")


class FeatureObservation(gym.ObservationWrapper):
    """The ``Dict`` observation's ``keys`` flattened and concatenated into one float32 vector,
    normalised as ``clip((x - mean) / std, -clip, clip)`` when ``mean``/``std`` are given.

    Parameters
    ----------
    env : gymnasium.Env
        An env with a ``Dict`` observation holding ``keys``.
    keys : sequence of str
    mean, std : ndarray of shape (n_features,), optional
        A fixed normalisation (e.g. an imitation policy's); None leaves the features raw (then
        normalise with SB3's ``VecNormalize``).
    clip : float, default=10.0

    Examples
    --------
    >>> import gymnasium as gym, polar_sim.envs
    >>> env = FeatureObservation(gym.make("polar_sim/GPISNav-Room-v1", pose_source="truth"), ["goal", "twist"])
    >>> env.observation_space.shape
    (4,)
    """

    def __init__(self, env, keys, mean=None, std=None, clip=10.0):
        spaces = getattr(env.observation_space, "spaces", None)
        if not isinstance(spaces, dict):
            raise ValueError(f"env: expected a Dict observation space, got {env.observation_space!r}")
        keys = list(keys)
        missing = [k for k in keys if k not in spaces]
        if not keys or missing:
            raise ValueError(f"keys: expected a non-empty list of observation keys among {sorted(spaces)}, "
                             f"got {keys!r}")
        n = int(sum(np.prod(spaces[k].shape) for k in keys))
        if (mean is None) != (std is None):
            raise ValueError("mean, std: give both or neither")
        if mean is not None:
            mean, std = np.asarray(mean, np.float64), np.asarray(std, np.float64)
            if mean.shape != (n,) or std.shape != (n,) or not (std > 0).all():
                raise ValueError(f"mean, std: expected shape ({n},) and std > 0, got {mean.shape}, {std.shape}")
        super().__init__(env)
        self.keys, self.mean, self.std, self.clip = keys, mean, std, float(clip)
        bound = self.clip if mean is not None else np.inf
        self.observation_space = gym.spaces.Box(-bound, bound, (n,), np.float32)

    def observation(self, obs):
        x = np.concatenate([np.asarray(obs[k], np.float64).reshape(-1) for k in self.keys])
        if self.mean is not None:
            x = np.clip((x - self.mean) / self.std, -self.clip, self.clip)
        return x.astype(np.float32)
