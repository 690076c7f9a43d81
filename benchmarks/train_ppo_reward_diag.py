"""Usage: python benchmarks/train_ppo_reward_diag.py STEPS '{"name": {env kwargs}, ...}'

Short PPO diagnostic of reward variants on GPISNav-Room-v1 (slam): each variant trains
STEPS steps (2 envs, training worlds from seeds 0..), then its deterministic policy is scored on
20 dev worlds (episode seeds 1000-1019). Prints per-rollout training stats and a JSON line per variant."""
import sys, json, time, numpy as np, torch, gymnasium as gym
import polar_sim.envs
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize
from stable_baselines3.common.callbacks import BaseCallback
from polar_sim.envs.learning import make_model, ppo_recipe, ObsNormaliser
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
from train_ppo_gpisnav import run_episodes, learned
torch.set_num_threads(1)
steps = int(sys.argv[1]); variants = json.loads(sys.argv[2])
ENV = "polar_sim/GPISNav-Room-v1"
for name, kw in variants.items():
    t = time.time()
    venv = make_vec_env("polar_sim.envs:" + ENV, n_envs=2, seed=0, env_kwargs=kw,
                        monitor_kwargs={"info_keywords": ("is_success", "collision")})
    venv = VecNormalize(venv, norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=0.99)
    recipe = ppo_recipe("stencil")
    recipe["action"] = None  # as these diagnostics were run: the env's own action, no ForwardDriveAction
    model = make_model(recipe, venv, seed=0)
    eps = []
    class CB(BaseCallback):
        def _on_step(self):
            for info in self.locals["infos"]:
                if "episode" in info:
                    eps.append((self.num_timesteps, info["episode"]["r"], info["episode"]["l"], info["is_success"], info["collision"]))
            return True
        def _on_rollout_end(self):
            w = [e for e in eps if e[0] > self.num_timesteps - 4096]
            if w:
                a = np.array(w, float)
                print(f"{name} {self.num_timesteps}: n={len(w)} R={a[:,1].mean():.2f} L={a[:,2].mean():.0f} succ={a[:,3].mean():.2f} coll={a[:,4].mean():.2f}", flush=True)
    model.learn(steps, callback=CB())
    a = np.array([e for e in eps if e[0] > steps - 4096], float)
    dev = run_episodes(ENV, kw, learned(model, ObsNormaliser.from_vecnormalize(venv), False), np.arange(1000, 1020))
    print("RESULT", json.dumps({"name": name, "kw": kw, "train_last4k_success": float(a[:,3].mean()),
          "train_last4k_collision": float(a[:,4].mean()), "dev": dev, "wall_s": time.time() - t}), flush=True)
    venv.close()
