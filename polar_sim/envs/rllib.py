"""Ray RLlib on GPISNav: PPO with env runners on a Ray cluster (the ``[rllib]`` extra).

RLlib samples with *env runners*, Ray actors that each step their own copies of the env, so
sampling spreads over the cluster's cores and machines while one learner updates the policy::

    import ray
    from polar_sim.envs.rllib import rllib_config

    ray.init()                                  # or ray.init(address="auto") on a cluster
    algo = rllib_config("polar_sim/GPISNav-Room-v1", num_env_runners=2).build_algo()
    for _ in range(10):
        result = algo.train()                   # one iteration: sample, then update

The env is the tier with the forward-drive action and the stencil keys flattened into one vector
(:class:`~polar_sim.envs.features.FeatureObservation`), RLlib's default MLP on it; the recipe's
PPO values (:func:`polar_sim.envs.learning.ppo_recipe`). ``ray[rllib]`` 2.60 pins
``gymnasium==1.2.2``; the ``[rllib]`` extra installs RLlib's own dependencies beside ``ray``
instead, so polar_sim keeps the gymnasium it has (>= 1.0; tested on 1.4).
"""

from __future__ import annotations

import gymnasium as gym

from polar_sim._validation import as_int
from polar_sim.envs.action_maps import ForwardDriveAction
from polar_sim.envs.features import STENCIL_KEYS, FeatureObservation

__all__ = ["make_rllib_env", "rllib_config", "ENV_NAME"]

#: The name the env creator is registered under with Ray Tune.
ENV_NAME = "polar_sim_gpisnav"


def make_rllib_env(config):
    """The env an RLlib env runner steps: ``config["env_id"]`` made with ``config["env_kwargs"]``,
    the forward-drive action, the ``config["obs_keys"]`` flattened. ``config`` is RLlib's
    ``EnvContext`` (a dict)."""
    import polar_sim.envs  # noqa: F401  (registers the ids inside the Ray worker)

    env = gym.make(config["env_id"], **dict(config.get("env_kwargs") or {}))
    return FeatureObservation(ForwardDriveAction(env), list(config.get("obs_keys") or STENCIL_KEYS))


def rllib_config(env_id, *, env_kwargs=None, num_env_runners=1, train_batch_size=2048, minibatch_size=256,
                 num_epochs=10, seed=0):
    """An RLlib ``PPOConfig`` for ``env_id`` (a GPISNav-v1 tier).

    Parameters
    ----------
    env_id : str
    env_kwargs : dict, optional
        ``gym.make`` arguments (default ``{"pose_source": "truth"}``: train on the true pose, score
        in the default slam mode).
    num_env_runners : int
        Ray actors that sample (0: sample in the driver).
    train_batch_size, minibatch_size, num_epochs : int
        Env steps per iteration, SGD minibatch and epochs per iteration.
    seed : int
    """
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.tune.registry import register_env

    from polar_sim.envs.recipes import LEARNING_ENV_IDS

    if env_id not in LEARNING_ENV_IDS:
        raise ValueError(f"env_id: expected one of {', '.join(LEARNING_ENV_IDS)}, got {env_id!r}")
    n = as_int(num_env_runners, "num_env_runners", minimum=0, maximum=1024)
    batch = as_int(train_batch_size, "train_batch_size", minimum=1)
    mb = as_int(minibatch_size, "minibatch_size", minimum=1, maximum=batch)
    register_env(ENV_NAME, make_rllib_env)
    env_config = {"env_id": env_id, "env_kwargs": {"pose_source": "truth"} if env_kwargs is None else dict(env_kwargs),
                  "obs_keys": list(STENCIL_KEYS)}
    return (PPOConfig()
            .environment(ENV_NAME, env_config=env_config)
            .framework("torch")
            .env_runners(num_env_runners=n, num_envs_per_env_runner=1, num_cpus_per_env_runner=1,
                         rollout_fragment_length="auto")
            .learners(num_learners=0)
            .training(train_batch_size_per_learner=batch, minibatch_size=mb,
                      num_epochs=as_int(num_epochs, "num_epochs", minimum=1), lr=3e-4, gamma=0.99, lambda_=0.95)
            .debugging(seed=as_int(seed, "seed", minimum=0)))
