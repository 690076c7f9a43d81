"""The masked stencil made the same with the exact SDF and the online map (numpy and gymnasium only).

The masked stencil (:func:`polar_sim.envs.features.stencil_vector` with ``known_var``) reads
unknown space as :data:`~polar_sim.envs.features.FAR` with gradient 0 and mask 0. With the exact
SDF (``sdf_source="truth"``) nothing is unknown: the mask is 1 at every point from the first step,
a constant that observation normalisation turns into +-10 wherever the online map leaves a point
unknown (39-55 % of the stencil at the first step of an expert episode on dev worlds, 10-25 % after
50 steps). :func:`far_as_unknown` also reads as unknown every point at ``FAR`` or more from the
nearest surface, in either source: far free space then looks alike in both (distance ``FAR``,
gradient 0, mask 0), and the two modes differ only near surfaces the map has not seen yet.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from polar_sim.envs.features import FAR, stencil_vector

__all__ = ["UNKNOWN_VAR", "far_as_unknown", "FarAsUnknown", "feature_vector"]

#: The variance :func:`far_as_unknown` writes at far points (the observation space's upper bound).
UNKNOWN_VAR = 1e6


def far_as_unknown(obs, far=FAR):
    """A copy of ``obs`` whose ``sdf_var`` is :data:`UNKNOWN_VAR` where ``sdf >= far`` (m)."""
    out = dict(obs)
    sdf = np.asarray(obs["sdf"])
    out["sdf_var"] = np.where(sdf >= far, UNKNOWN_VAR, obs["sdf_var"]).astype(np.asarray(obs["sdf_var"]).dtype)
    return out


class FarAsUnknown(gym.ObservationWrapper):
    """:func:`far_as_unknown` on every observation of a GPISNav stencil env (spaces unchanged)."""

    def __init__(self, env, far=FAR):
        if "sdf_var" not in getattr(env.observation_space, "spaces", {}):
            raise ValueError(f"env: expected a stencil observation with 'sdf_var', got {env.observation_space!r}")
        super().__init__(env)
        self.far = float(far)

    def observation(self, obs):
        return far_as_unknown(obs, self.far)


def feature_vector(obs, keys, known_var=None, far_unknown=False):
    """:func:`~polar_sim.envs.features.stencil_vector` of ``obs``, first :func:`far_as_unknown`
    when ``far_unknown``: the flat vector an SB3 policy of the RL recipes reads."""
    return stencil_vector(far_as_unknown(obs) if far_unknown else obs, keys, known_var)
