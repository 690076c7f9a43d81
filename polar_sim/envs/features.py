"""Flat feature vectors of a Dict observation, for learners that take one ``Box`` (an SB3
``MlpPolicy``, RLlib's default model); numpy and gymnasium only."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

__all__ = ["FeatureObservation", "STENCIL_KEYS", "MASKED_KEYS", "KNOWN_VAR", "FAR", "stencil_vector"]

#: The stencil keys a learned GPISNav policy reads by default: ``sdf_var`` and ``pose`` are left
#: out (the variance's scale differs between map sources, the pose's range between tiers).
STENCIL_KEYS = ("goal", "sdf", "sdf_grad", "twist")
#: Map distance (m) beyond which a stencil point tells the experts nothing (``SDFReactive`` drops
#: points at 1.5 m or more): the masked features clip distances to it and put unknown points at it.
FAR = 1.5
#: ``SDFReactive``'s ``max_var``: stencil points with a map variance at or above it are unknown space.
KNOWN_VAR = 0.5
#: The keys the imitation recipe reads by default, with ``known_var=KNOWN_VAR`` (the masked stencil).
MASKED_KEYS = ("goal", "sdf", "sdf_grad", "sdf_var", "twist")


def stencil_vector(obs, keys, known_var=None):
    """The observation's ``keys`` flattened and concatenated, float64 (n_features,).

    With ``known_var`` (m^2), the stencil is first masked as the experts read it: a point whose map
    variance is ``known_var`` or more is unknown space, its ``sdf`` set to :data:`FAR` and its
    ``sdf_grad`` to 0; known distances are clipped to at most ``FAR``; ``sdf_var`` becomes the 0/1
    known mask. The map's values in unknown space (a negative distance, variance about 1 in slam
    and truth-pose modes alike, 1e6 where the map has no value) then never reach the learner.
    """
    if known_var is not None:
        known = np.asarray(obs["sdf_var"], np.float64) < known_var
        masked = {"sdf": np.where(known, np.minimum(np.asarray(obs["sdf"], np.float64), FAR), FAR),
                  "sdf_grad": np.asarray(obs["sdf_grad"], np.float64) * np.repeat(known, 2),
                  "sdf_var": known.astype(np.float64)}
        obs = {k: masked[k] if k in masked else obs[k] for k in keys}
    return np.concatenate([np.asarray(obs[k], np.float64).reshape(-1) for k in keys])


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
    known_var : float, optional
        Mask the stencil's unknown space first (:func:`stencil_vector`).

    Examples
    --------
    >>> import gymnasium as gym, polar_sim.envs
    >>> env = FeatureObservation(gym.make("polar_sim/GPISNav-Room-v1", pose_source="truth"), ["goal", "twist"])
    >>> env.observation_space.shape
    (4,)
    """

    def __init__(self, env, keys, mean=None, std=None, clip=10.0, known_var=None):
        spaces = getattr(env.observation_space, "spaces", None)
        if not isinstance(spaces, dict):
            raise ValueError(f"env: expected a Dict observation space, got {env.observation_space!r}")
        keys = list(keys)
        missing = [k for k in keys if k not in spaces]
        if known_var is not None and "sdf_var" not in keys:
            raise ValueError(f"known_var: masking unknown space needs 'sdf_var' among the keys, got {keys!r}")
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
        self.known_var = None if known_var is None else float(known_var)
        bound = self.clip if mean is not None else np.inf
        self.observation_space = gym.spaces.Box(-bound, bound, (n,), np.float32)

    def observation(self, obs):
        x = stencil_vector(obs, self.keys, self.known_var)
        if self.mean is not None:
            x = np.clip((x - self.mean) / self.std, -self.clip, self.clip)
        return x.astype(np.float32)
