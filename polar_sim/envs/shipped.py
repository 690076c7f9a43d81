"""Policies that ship with polar_sim: one small ``.npz`` per env id in ``polar_sim/data/policies/``.

>>> import gymnasium as gym, polar_sim.envs
>>> from polar_sim.envs import pretrained
>>> policy = pretrained("polar_sim/GPISNav-Room-v1")
>>> env = gym.make("polar_sim/GPISNav-Room-v1", **policy.env_kwargs)
>>> obs, info = env.reset(seed=10_000); policy.reset()
>>> env.action_space.contains(policy(obs))
True

The files are numpy policies (:class:`~polar_sim.envs.mlp_policy.MLPPolicy`, or
:class:`~polar_sim.envs.map_policy.MapCNNPolicy` with a map memory): acting needs neither torch
nor stable-baselines3. How each was trained, and its held-out score, is in its
``recipe`` (``policy.recipe``) and in docs/guide/learning.md.
"""

from __future__ import annotations

from importlib import resources

from polar_sim.envs.map_policy import MapCNNPolicy
from polar_sim.envs.mlp_policy import MLPPolicy
from polar_sim.envs.policy_file import read_policy_file

__all__ = ["pretrained", "pretrained_ids", "policy_path", "load_numpy_policy"]

_PACKAGE = "polar_sim"


def _file_name(env_id):
    """``polar_sim/GPISNav-Room-v1`` -> ``GPISNav-Room-v1.npz``."""
    return env_id.split("/", 1)[1] + ".npz"


def pretrained_ids():
    """The env ids that have a shipped policy, sorted."""
    folder = resources.files(_PACKAGE) / "data" / "policies"
    if not folder.is_dir():
        return []
    return sorted(f"polar_sim/{p.name[:-4]}" for p in folder.iterdir() if p.name.endswith(".npz"))


def policy_path(env_id):
    """The shipped policy file of ``env_id`` (``ValueError`` listing the ids that have one)."""
    ids = pretrained_ids()
    if not isinstance(env_id, str) or env_id.split(":")[-1] not in ids:
        raise ValueError(f"env_id: no pretrained policy for {env_id!r}; policies ship for: "
                         f"{', '.join(ids) or 'none'}")
    return resources.files(_PACKAGE) / "data" / "policies" / _file_name(env_id.split(":")[-1])


def pretrained(env_id):
    """The shipped policy of ``env_id``: a callable ``policy(obs) -> action`` in the env's own
    action space, with ``reset()``, ``env_kwargs`` (the ``gym.make`` arguments it acts with, e.g.
    ``{"obs_mode": "stencil"}``) and ``recipe`` (how it was trained)."""
    path = policy_path(env_id)
    with resources.as_file(path) as p:
        policy = load_numpy_policy(p, name=f"pretrained policy of {env_id}")
    if policy.env_id != env_id.split(":")[-1]:
        raise ValueError(f"pretrained policy of {env_id}: the file was made for {policy.env_id!r}")
    return policy


def load_numpy_policy(path, env=None, name="path"):
    """The numpy policy in ``path`` (kind ``"mlp"``: :class:`MLPPolicy`, ``"mapcnn"``:
    :class:`MapCNNPolicy`); with ``env``, checked against its observation space."""
    meta, arrays = read_policy_file(path, name)
    if meta["kind"] == "mapcnn":
        return MapCNNPolicy.from_file(meta, arrays, env, name)
    if meta["kind"] == "mlp":
        return MLPPolicy.load(path, env, name)
    raise ValueError(f"{name}: a policy of kind {meta['kind']!r}; the numpy policies are 'mlp' and 'mapcnn'")
