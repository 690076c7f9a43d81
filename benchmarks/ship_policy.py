"""Copy a trained numpy policy (MLP or map CNN) into the package as a tier's shipped policy, with its recipe header.

Usage::

    python benchmarks/ship_policy.py POLICY.npz ENV_ID RECIPE 'PARAMS_JSON' SEED "HOW IT WAS TRAINED"

The recipe's parameters are checked (``check_recipe``) and stored in the policy's ``recipe`` with
the seed, the training worlds and the command that trained it; the policy is checked against
``ENV_ID``'s observation space (made with the policy's ``env_kwargs``) and written to
``polar_sim/data/policies/<id>.npz``.
"""

import json
import sys
from pathlib import Path

import gymnasium as gym

import polar_sim.envs
from polar_sim.envs.imitation import TRAIN_SEEDS
from polar_sim.envs.recipes import check_recipe
from polar_sim.envs.shipped import load_numpy_policy


def main():
    src, env_id, recipe, params, seed, how = sys.argv[1:7]
    p = load_numpy_policy(src)
    params = check_recipe(recipe, json.loads(params), env_id)
    p.env_id = env_id
    p.recipe = {"name": recipe, "params": params, "seed": int(seed), "train_seeds": list(TRAIN_SEEDS),
                "trained_by": how}
    env = gym.make(env_id, **p.env_kwargs)
    p.check_env(env)
    env.close()
    dest = Path(polar_sim.envs.__file__).parent.parent / "data" / "policies" / (env_id.split("/")[1] + ".npz")
    p.save(dest)
    print(f"{dest}: {dest.stat().st_size} bytes")


if __name__ == "__main__":
    main()
