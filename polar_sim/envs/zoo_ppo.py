"""rl-zoo3 hyperparameters for PPO on the GPISNav tiers (v2 and v1) (``--conf-file polar_sim.envs.zoo_ppo``).

rl-zoo3 reads a Python module given to ``--conf-file`` by its ``hyperparams`` dict, keyed by env
id, so the file ships inside polar_sim and needs no path::

    python -m rl_zoo3.train --algo ppo --env polar_sim/GPISNav-Room-v2 --gym-packages polar_sim.envs \\
        --conf-file polar_sim.envs.zoo_ppo --eval-freq -1 -f logs/
    python -m rl_zoo3.enjoy --algo ppo --env polar_sim/GPISNav-Room-v2 --gym-packages polar_sim.envs \\
        -f logs/ --no-render -n 600 --env-kwargs pose_source:"'slam'" sdf_source:"'gpis'"

The values are the ``ppo`` recipe's defaults (:data:`polar_sim.envs.recipes.RECIPES`): the masked
stencil as one vector (:class:`~polar_sim.envs.features.FeatureObservation` with ``known_var``,
after :class:`~polar_sim.envs.far_mask.FarAsUnknown`),
the forward-drive action, an MLP of two layers of 128, observation and reward normalisation, 4
environments, trained where a step is cheapest (``pose_source: truth``, ``sdf_source: truth``).
rl-zoo3 evaluates in the training env; score a zoo model in the default slam mode with the
``--env-kwargs`` of ``enjoy`` above. rl-zoo3 saves its models with SB3's own ``save`` (a zip with
pickled parts), not polar_sim's policy file. rl-zoo3 does not run the recipe's clutter curriculum.
"""

from polar_sim.envs.recipes import RECIPES

__all__ = ["hyperparams"]

_TIME_STEPS = {"polar_sim/GPISNav-Room-v2": 300_000, "polar_sim/GPISNav-Rooms2-v2": 1_000_000,
               "polar_sim/GPISNav-v2": 1_000_000, "polar_sim/GPISNav-Room-v1": 300_000,
               "polar_sim/GPISNav-Rooms2-v1": 1_000_000, "polar_sim/GPISNav-v1": 1_000_000}


def _ppo(env_id):
    p = RECIPES["ppo"]
    features = {"keys": list(p["obs_keys"]), "known_var": p["known_var"]}
    return {"n_timesteps": _TIME_STEPS[env_id], "policy": "MlpPolicy", "n_envs": p["n_envs"], "normalize": True,
            "env_wrapper": ["polar_sim.envs.action_maps.ForwardDriveAction"]
            + (["polar_sim.envs.far_mask.FarAsUnknown"] if p["far_unknown"] else [])
            + [{"polar_sim.envs.features.FeatureObservation": features}],
            "env_kwargs": {"pose_source": p["train_pose_source"], "sdf_source": p["train_sdf_source"],
                           **({"reward_weights": dict(p["train_reward"])} if p["train_reward"] else {})},
            **{k: p[k] for k in ("n_steps", "batch_size", "n_epochs", "learning_rate", "gamma", "gae_lambda",
                                 "clip_range", "ent_coef")},
            "policy_kwargs": {"net_arch": {"pi": list(p["hidden"]), "vf": list(p["hidden"])},
                              "log_std_init": p["log_std_init"]}}


#: env id -> rl-zoo3 hyperparameters of PPO.
hyperparams = {env_id: _ppo(env_id) for env_id in _TIME_STEPS}
