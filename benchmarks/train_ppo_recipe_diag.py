"""Usage: python benchmarks/train_ppo_recipe_diag.py STEPS '{"name": {"env": {...}, "eval_env": {...},
"recipe": {...}, "policy_kwargs": {...}, "action": {...} | null, "envs": 2}, ...}'

Short PPO diagnostic of recipe variants on GPISNav-Room-v1: each variant trains STEPS steps
(``envs`` environments in one process, training worlds from seeds 0..; env kwargs ``env``,
default ``pose_source="truth"``), then its deterministic policy is scored on 20 dev worlds (episode
seeds 1000-1019) with the env kwargs ``eval_env`` (default: the training ones). ``recipe`` overrides
``ppo_recipe("stencil")["kwargs"]``, ``policy_kwargs`` its policy kwargs, ``action`` its action
parametrisation. Prints per-rollout training stats and a JSON line per variant."""
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

import polar_sim.envs  # noqa: F401
from polar_sim.envs.learning import ObsNormaliser, make_model, ppo_recipe, wrap_action

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
from train_ppo_gpisnav import learned, run_episodes  # noqa: E402

torch.set_num_threads(1)
steps = int(sys.argv[1])
variants = json.loads(sys.argv[2])
ENV = "polar_sim/GPISNav-Room-v1"
for name, v in variants.items():
    t = time.time()
    kw = {"pose_source": "truth", **v.get("env", {})}
    recipe = ppo_recipe("stencil")
    if "action" in v:
        recipe["action"] = v["action"]
    recipe["kwargs"].update(v.get("recipe", {}))
    recipe["kwargs"]["policy_kwargs"].update(v.get("policy_kwargs", {}))
    venv = make_vec_env("polar_sim.envs:" + ENV, n_envs=v.get("envs", 2), seed=0, env_kwargs=kw,
                        wrapper_class=lambda e: wrap_action(e, recipe.get("action")),
                        monitor_kwargs={"info_keywords": ("is_success", "collision")})
    venv = VecNormalize(venv, norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=recipe["kwargs"]["gamma"])
    model = make_model(recipe, venv, seed=0)
    eps = []

    class CB(BaseCallback):
        def _on_step(self):
            for info in self.locals["infos"]:
                if "episode" in info:
                    eps.append((self.num_timesteps, info["episode"]["r"], info["episode"]["l"], info["is_success"],
                                info["collision"]))
            return True

        def _on_rollout_end(self):
            w = [e for e in eps if e[0] > self.num_timesteps - 4096]
            if w:
                a = np.array(w, float)
                print(f"{name} {self.num_timesteps}: n={len(w)} R={a[:, 1].mean():.2f} L={a[:, 2].mean():.0f} "
                      f"succ={a[:, 3].mean():.2f} coll={a[:, 4].mean():.2f} ({time.time() - t:.0f} s)", flush=True)

    model.learn(steps, callback=CB())
    a = np.array([e for e in eps if e[0] > steps - 4096] or [(0, 0, 0, 0, 0)], float)
    ekw = {**kw, **v.get("eval_env", {})}
    dev = run_episodes(ENV, ekw, learned(model, ObsNormaliser.from_vecnormalize(venv), False, recipe.get("action")),
                       np.arange(1000, 1020))
    print("RESULT", json.dumps({"name": name, "variant": v, "train_last4k_success": float(a[:, 3].mean()),
                                "train_last4k_collision": float(a[:, 4].mean()), "dev": dev,
                                "wall_s": time.time() - t}), flush=True)
    venv.close()
