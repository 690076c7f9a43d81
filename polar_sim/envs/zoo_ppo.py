"""rl-zoo3 hyperparameters for PPO on the GPISNav tiers (v2 and v1) (``--conf-file polar_sim.envs.zoo_ppo``).

rl-zoo3 reads a Python module given to ``--conf-file`` by its ``hyperparams`` dict, keyed by env
id, so the file ships inside polar_sim and needs no path::

    python -m rl_zoo3.train --algo ppo --env polar_sim/GPISNav-Room-v1 --gym-packages polar_sim.envs \\
        --conf-file polar_sim.envs.zoo_ppo --eval-freq -1 -f logs/
    python -m rl_zoo3.enjoy --algo ppo --env polar_sim/GPISNav-Room-v1 --gym-packages polar_sim.envs \\
        -f logs/ --no-render -n 600

The values are :func:`polar_sim.envs.learning.ppo_recipe`'s (stencil MLP, the forward-drive
action, observation and reward normalisation), trained with the true pose (``pose_source:
truth``, faster per step) on the online map. rl-zoo3 evaluates in the training env; score a zoo
model in the default slam mode with ``--env-kwargs pose_source:"'slam'"`` in ``enjoy``. rl-zoo3
saves its models with SB3's own ``save`` (a zip with pickled parts), not polar_sim's policy file.
"""

from polar_sim.envs.learning import ppo_recipe

__all__ = ["hyperparams"]

_TIME_STEPS = {"polar_sim/GPISNav-Room-v2": 300_000, "polar_sim/GPISNav-Rooms2-v2": 1_000_000,
               "polar_sim/GPISNav-v2": 1_000_000, "polar_sim/GPISNav-Room-v1": 300_000,
               "polar_sim/GPISNav-Rooms2-v1": 1_000_000, "polar_sim/GPISNav-v1": 1_000_000}


def _ppo(env_id):
    kw = ppo_recipe("stencil")["kwargs"]
    return {"n_timesteps": _TIME_STEPS[env_id], "policy": "MultiInputPolicy", "n_envs": 4, "normalize": True,
            "env_wrapper": "polar_sim.envs.action_maps.ForwardDriveAction", "env_kwargs": {"pose_source": "truth"},
            **{k: v for k, v in kw.items() if k != "policy_kwargs"}, "policy_kwargs": dict(kw["policy_kwargs"])}


#: env id -> rl-zoo3 hyperparameters of PPO.
hyperparams = {env_id: _ppo(env_id) for env_id in _TIME_STEPS}
