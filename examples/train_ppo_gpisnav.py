"""Train stable-baselines3 PPO on GPISNav-v0 and plot its learning curve.

Usage:
    python examples/train_ppo_gpisnav.py --steps 200000 --out polar_sim_out/ppo_gpisnav

Every ``--eval-every`` steps the deterministic policy is scored on held-out worlds (episode
seeds 10000, 10001, ...), beside a uniformly random policy on the same worlds. Writes
``curve.csv``, ``curve.png`` (success rate against training steps) and the model. CPU only
(``pip install torch==2.13.0`` gives the CPU wheel); about 40 minutes for 200k steps on 2 cores.
"""

import argparse
import csv
from pathlib import Path

import gymnasium as gym
import numpy as np

import polar_sim  # noqa: F401  (registers the ids)
from polar_sim.envs.evaluate import RandomPolicy


def success_rate(env_id, policy, episodes, env_kwargs, seed=10_000):
    env = gym.make(env_id, **env_kwargs)
    wins = 0
    for i in range(episodes):
        obs, info = env.reset(seed=seed + i)
        done = False
        while not done:
            obs, r, term, trunc, info = env.step(policy(obs))
            done = term or trunc
        wins += bool(info["is_success"])
    env.close()
    return wins / episodes


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=200_000)
    ap.add_argument("--eval-every", type=int, default=25_000)
    ap.add_argument("--eval-episodes", type=int, default=20)
    ap.add_argument("--envs", type=int, default=2, help="parallel training environments (subprocesses)")
    ap.add_argument("--sdf-source", default="gpis", choices=["gpis", "truth", "occupancy_edt"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="polar_sim_out/ppo_gpisnav")
    args = ap.parse_args()

    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    torch.set_num_threads(1)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env_id = "polar_sim:polar_sim/GPISNav-v0"
    kwargs = {"sdf_source": args.sdf_source}
    venv = make_vec_env(env_id, n_envs=args.envs, seed=args.seed, env_kwargs=kwargs,
                        vec_env_cls=SubprocVecEnv if args.envs > 1 else None,
                        vec_env_kwargs={"start_method": "spawn"} if args.envs > 1 else None)
    # The goal (metres, up to the world's diagonal), the SDF and its variance span very different
    # scales; running normalisation lets one learning rate serve them all.
    venv = VecNormalize(venv, norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=0.99)
    # 200k steps is a small budget for PPO, so: short rollouts (1024 steps per update, ~195
    # updates), and a narrow initial action noise (std 0.37), so that early episodes are not
    # spent flailing at the action bounds into the nearest wall.
    model = PPO("MultiInputPolicy", venv, n_steps=512, batch_size=128, n_epochs=10, learning_rate=3e-4,
                gamma=0.99, gae_lambda=0.95, ent_coef=0.0, seed=args.seed, verbose=0, device="cpu",
                policy_kwargs={"net_arch": {"pi": [128, 128], "vf": [128, 128]}, "log_std_init": -1.0})
    def ppo_policy(obs):
        # Score with the normalisation statistics frozen at their current values.
        return model.predict(venv.normalize_obs(obs), deterministic=True)[0]

    probe = gym.make(env_id, **kwargs)
    random_rate = success_rate(env_id, RandomPolicy(probe.action_space, seed=args.seed), args.eval_episodes, kwargs)
    probe.close()
    untrained = success_rate(env_id, ppo_policy, args.eval_episodes, kwargs)
    rows = [{"steps": 0, "ppo_success": untrained, "random_success": random_rate}]
    print(f"random policy: success {random_rate:.2f}; untrained PPO {untrained:.2f}", flush=True)

    class Evaluate(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next = args.eval_every

        def _on_step(self):
            if self.num_timesteps >= self.next:
                self.next += args.eval_every
                rate = success_rate(env_id, ppo_policy, args.eval_episodes, kwargs)
                rows.append({"steps": self.num_timesteps, "ppo_success": rate, "random_success": random_rate})
                print(f"{self.num_timesteps} steps: PPO success {rate:.2f} (random {random_rate:.2f})", flush=True)
                with open(out / "curve.csv", "w", newline="") as fh:
                    w = csv.DictWriter(fh, fieldnames=list(rows[0]))
                    w.writeheader()
                    w.writerows(rows)
            return True

    model.learn(total_timesteps=args.steps, callback=Evaluate(), progress_bar=False)
    model.save(out / "ppo_gpisnav")
    # The observation statistics the policy expects, as plain arrays (not SB3's pickle).
    rms = venv.obs_rms
    np.savez(out / "obs_normalisation.npz", format_version=1, clip=10.0,
             **{f"{k}_mean": r.mean for k, r in rms.items()}, **{f"{k}_var": r.var for k, r in rms.items()})
    venv.close()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = np.array([r["steps"] for r in rows])
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(steps, [r["ppo_success"] for r in rows], "o-", label="PPO (deterministic)")
    ax.axhline(random_rate, color="grey", ls="--", label="random policy")
    ax.set_xlabel("training steps")
    ax.set_ylabel(f"success rate ({args.eval_episodes} held-out worlds)")
    ax.set_ylim(0, 1)
    ax.set_title(f"PPO on GPISNav-v0 (sdf_source={args.sdf_source})")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "curve.png", dpi=110)
    print(f"wrote {out / 'curve.png'}; final PPO success {rows[-1]['ppo_success']:.2f}, random {random_rate:.2f}")


if __name__ == "__main__":
    main()
