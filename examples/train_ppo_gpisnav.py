"""Train PPO (stable-baselines3, or sb3-contrib's RecurrentPPO) on a GPISNav-v1 tier and plot its
learning curve beside random actions and the scripted baselines.

Usage:
    python examples/train_ppo_gpisnav.py --tier room --obs-mode stencil --steps 300000 \\
        --out polar_sim_out/ppo_room --docs docs/img
    python examples/train_ppo_gpisnav.py --tier rooms2 --obs-mode grid ...
    python examples/train_ppo_gpisnav.py --tier rooms2 --recurrent ...

Every ``--eval-every`` steps the deterministic policy is scored on ``--curve-episodes`` dev
worlds (episode seeds 1000, 1001, ...: the split the recipe was chosen on; ``--curve-split test``:
the held-out worlds 10000, 10001, ..., with ``--stop-at`` ending the run once a checkpoint
reaches that success, nothing else being chosen on them); random actions,
``SDFReactive`` and ``SDFNavigator`` are scored once on the same worlds (the scripted ones on the
stencil observation of the same tier and pose source). At the end the final policy (not a
chosen checkpoint) and the baselines are scored on ``--test-episodes`` held-out worlds (seeds
10000, 10001, ...). Writes ``curve.csv``, ``curve.png``, ``summary.json`` and the policy
(``policy.npz``: weights, recipe and observation normalisation, no pickle) to ``--out``, and the
plot to ``--docs`` as ``ppo_gpisnav_<tier>_<mode>.png``. CPU torch (``pip install
torch==2.13.0``); one process, one core.
"""

import argparse
import csv
import json
import shutil
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import polar_sim.envs  # noqa: F401  (registers the ids)
from polar_sim.envs.evaluate import RandomPolicy
from polar_sim.envs.learning import env_action
from polar_sim.envs.policies import SDFNavigator, SDFReactive

TIER_IDS = {"room": "polar_sim/GPISNav-Room-v1", "rooms2": "polar_sim/GPISNav-Rooms2-v1",
            "rooms3": "polar_sim/GPISNav-v1"}
DEV_SEED, TEST_SEED = 1000, 10_000


def run_episodes(env_id, env_kwargs, policy, seeds):
    """Success rate, collision rate and mean episode length of ``policy`` on the episode ``seeds``.
    ``policy`` is ``(act(obs) -> action, reset())``."""
    act, reset = policy
    env = gym.make(env_id, **env_kwargs)
    wins = hits = steps = 0
    try:
        for s in seeds:
            obs, info = env.reset(seed=int(s))
            reset()
            done = False
            while not done:
                obs, r, term, trunc, info = env.step(act(obs))
                steps += 1
                done = term or trunc
            wins += bool(info["is_success"])
            hits += bool(info["collision"])
    finally:
        env.close()
    n = max(len(seeds), 1)
    return {"success": wins / n, "collision": hits / n, "mean_length": steps / n, "episodes": len(seeds)}


def scripted(cls):
    pol = cls()
    return pol, pol.reset


def learned(model, normaliser, recurrent, action=None):
    """(act, reset) of a trained model: deterministic actions on normalised observations, mapped
    to the env's action by the recipe's ``action`` parametrisation (None: clipped to the box)."""
    state = {"h": None, "start": True}

    def act(obs):
        o = {k: v[None] for k, v in normaliser(obs).items()}
        if recurrent:
            a, state["h"] = model.predict(o, state=state["h"], episode_start=np.array([state["start"]]),
                                          deterministic=True)
            state["start"] = False
        else:
            a, _ = model.predict(o, deterministic=True)
        return env_action(action, a[0])

    def reset():
        state.update(h=None, start=True)

    return act, reset


def plot_curve(rows, label, baselines, n_dev, title, path, split="dev"):
    """Success against training steps (``rows`` of curve.csv) with the baselines' dev success as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    ax.plot([r["steps"] for r in rows], [r["ppo_success"] for r in rows], "o-", color="C0", label=label)
    styles = {"random": ("grey", ":"), "reactive": ("C1", "--"), "navigator": ("C2", "-.")}
    labels = {"random": "random actions", "reactive": "SDFReactive", "navigator": "SDFNavigator"}
    for b in baselines:
        ax.axhline(rows[0][f"{b}_success"], color=styles[b][0], ls=styles[b][1], label=labels[b])
    ax.set_xlabel("training steps")
    ax.set_ylabel(f"success rate ({n_dev} {split} worlds)")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def replot(curve_csv, title, path, n_dev, split="dev"):
    """Plot a curve.csv written so far (e.g. by a run stopped before its end)."""
    with open(curve_csv, newline="") as fh:
        rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(fh)]
    wanted = [b for b in ("random", "reactive", "navigator") if f"{b}_success" in rows[0]]
    plot_curve(rows, "PPO (stencil)", wanted, n_dev, title, path, split)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tier", default="room", choices=sorted(TIER_IDS))
    ap.add_argument("--obs-mode", default="stencil", choices=["stencil", "grid"])
    ap.add_argument("--grid-visited", action="store_true", help="grid: add the visited channel")
    ap.add_argument("--recurrent", action="store_true", help="sb3-contrib RecurrentPPO (an LSTM policy)")
    ap.add_argument("--pose-source", default="slam", choices=["slam", "odometry", "truth"])
    ap.add_argument("--steps", type=int, default=300_000)
    ap.add_argument("--envs", type=int, default=4, help="training environments, stepped in this one process")
    ap.add_argument("--eval-every", type=int, default=25_000)
    ap.add_argument("--curve-episodes", type=int, default=20, help="dev worlds per point of the curve")
    ap.add_argument("--test-episodes", type=int, default=50, help="held-out worlds of the final score (>= 1)")
    ap.add_argument("--baselines", default="random,reactive,navigator",
                    help="comma-separated subset of random,reactive,navigator (empty: none)")
    ap.add_argument("--curve-split", default="dev", choices=["dev", "test"],
                    help="the worlds of the checkpoints (test: held-out, seeds 10000..)")
    ap.add_argument("--stop-at", type=float, default=None,
                    help="stop training once a checkpoint's success reaches this (e.g. 0.8)")
    ap.add_argument("--skip-start-eval", action="store_true", help="no checkpoint at 0 steps")
    ap.add_argument("--env-kwargs", default="{}", help="JSON dict of extra env arguments (e.g. reward_weights)")
    ap.add_argument("--eval-pose-source", default=None, choices=["slam", "odometry", "truth"],
                    help="pose source of every evaluation (checkpoints, baselines, final); default --pose-source")
    ap.add_argument("--action", default=None, choices=["box", "forward_drive"],
                    help="the policy's action parametrisation (default: the recipe's)")
    ap.add_argument("--recipe-kwargs", default="{}", help="JSON dict overriding the recipe's PPO kwargs")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="polar_sim_out/ppo_gpisnav")
    ap.add_argument("--docs", default=None, help="also copy the plot into this folder (e.g. docs/img)")
    ap.add_argument("--replot", nargs=2, metavar=("CURVE_CSV", "PNG"), default=None,
                    help="only plot an existing curve.csv (with --title) and exit")
    ap.add_argument("--title", default="", help="--replot: the plot's title")
    args = ap.parse_args()
    if args.replot:
        return replot(args.replot[0], args.title, args.replot[1], args.curve_episodes,
                      "held-out" if args.curve_split == "test" else "dev")
    if min(args.curve_episodes, args.test_episodes, args.envs, args.steps) < 1:
        ap.error("--curve-episodes, --test-episodes, --envs and --steps must be >= 1")

    import torch
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    from polar_sim.envs.learning import ObsNormaliser, load_model, make_model, ppo_recipe, save_policy, wrap_action

    torch.set_num_threads(1)
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env_id = TIER_IDS[args.tier]
    kwargs = {"obs_mode": args.obs_mode, "pose_source": args.pose_source, **json.loads(args.env_kwargs)}
    if args.grid_visited:
        kwargs["grid_visited"] = True
    eval_kwargs = {**kwargs, "pose_source": args.eval_pose_source or args.pose_source}
    scripted_kwargs = {**eval_kwargs, "obs_mode": "stencil"}
    scripted_kwargs.pop("grid_visited", None)
    name = f"{args.tier}_{args.obs_mode}{'_visited' if args.grid_visited else ''}{'_lstm' if args.recurrent else ''}"
    dev = np.arange(DEV_SEED if args.curve_split == "dev" else TEST_SEED,
                    (DEV_SEED if args.curve_split == "dev" else TEST_SEED) + args.curve_episodes)
    test = np.arange(TEST_SEED, TEST_SEED + args.test_episodes)

    # Training episodes start from seeds 0.. (make_vec_env) and continue unseeded: their worlds are
    # neither the dev nor the test worlds.
    recipe = ppo_recipe(args.obs_mode, args.recurrent)
    if args.action is not None:
        recipe["action"] = None if args.action == "box" else {"name": args.action, "kwargs": {}}
    overrides = json.loads(args.recipe_kwargs)
    recipe["kwargs"]["policy_kwargs"].update(overrides.pop("policy_kwargs", {}))
    recipe["kwargs"].update(overrides)
    venv = make_vec_env("polar_sim.envs:" + env_id, n_envs=args.envs, seed=args.seed, env_kwargs=kwargs,
                        wrapper_class=wrap_action, wrapper_kwargs={"action": recipe.get("action")})
    # The goal (metres, up to the world's diagonal), the SDF and its variance span very different
    # scales; running normalisation lets one learning rate serve them all.
    venv = VecNormalize(venv, norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=recipe["kwargs"]["gamma"])
    model = make_model(recipe, venv, seed=args.seed)

    wanted = [b for b in args.baselines.split(",") if b]
    probe = gym.make(env_id, **eval_kwargs)
    makers = {"random": lambda: (lambda p: (p, p.reset))(RandomPolicy(probe.action_space, seed=args.seed)),
              "reactive": lambda: scripted(SDFReactive), "navigator": lambda: scripted(SDFNavigator)}

    def baselines(seeds):
        res = {}
        for b in wanted:
            kw = eval_kwargs if b == "random" else scripted_kwargs
            res[b] = run_episodes(env_id, kw, makers[b](), seeds)
            print(f"  {b}: {res[b]}", flush=True)
        return res

    print(f"{env_id} {kwargs}, {recipe['algorithm']}: baselines on {len(dev)} {args.curve_split} worlds", flush=True)
    base_dev = baselines(dev)
    rows = []

    def evaluate_now(steps):
        norm = ObsNormaliser.from_vecnormalize(venv)
        r = run_episodes(env_id, eval_kwargs, learned(model, norm, args.recurrent, recipe.get("action")), dev)
        rows.append({"steps": steps, "ppo_success": r["success"], "ppo_collision": r["collision"],
                     "ppo_mean_length": r["mean_length"], "wall_s": time.perf_counter() - t_wall,
                     **{f"{b}_success": base_dev[b]["success"] for b in wanted}})
        print(f"{steps} steps: PPO {r} ({rows[-1]['wall_s']:.0f} s)", flush=True)
        save_policy(out / "policy.npz", model, recipe, norm)  # the latest checkpoint, should the run be stopped
        with open(out / "curve.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)

    class Evaluate(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next = args.eval_every

        def _on_step(self):
            if self.num_timesteps >= self.next:
                self.next += args.eval_every
                evaluate_now(self.num_timesteps)
                if args.stop_at is not None and rows[-1]["ppo_success"] >= args.stop_at:
                    print(f"stopping: checkpoint success {rows[-1]['ppo_success']:.2f} >= {args.stop_at}", flush=True)
                    return False
            return True

    if not args.skip_start_eval:
        evaluate_now(0)
    model.learn(total_timesteps=args.steps, callback=Evaluate(), progress_bar=False)
    if not rows or rows[-1]["steps"] != model.num_timesteps:
        evaluate_now(model.num_timesteps)
    train_wall, train_cpu = time.perf_counter() - t_wall, time.process_time() - t_cpu
    save_policy(out / "policy.npz", model, recipe, ObsNormaliser.from_vecnormalize(venv))
    venv.close()

    # The final policy as saved (reloaded from its file) on the held-out worlds.
    loaded, norm, _ = load_model(out / "policy.npz", probe)
    probe.close()
    print(f"final policy and baselines on {len(test)} held-out worlds", flush=True)
    final = run_episodes(env_id, eval_kwargs, learned(loaded, norm, args.recurrent, recipe.get("action")), test)
    print(f"  PPO: {final}", flush=True)
    same = args.curve_split == "test" and args.test_episodes == args.curve_episodes
    base_test = base_dev if same else baselines(test)
    summary = {"env_id": env_id, "env_kwargs": kwargs, "eval_env_kwargs": eval_kwargs, "recipe": recipe, "steps": int(model.num_timesteps),
               "training_wall_s": train_wall, "training_cpu_s": train_cpu, "dev_seeds": [int(dev[0]), int(dev[-1])],
               "test_seeds": [int(test[0]), int(test[-1])], "ppo_test": final, "baselines_test": base_test,
               "baselines_dev": base_dev, "curve": rows}
    (out / "summary.json").write_text(json.dumps(summary, indent=2))

    ps = args.pose_source if eval_kwargs["pose_source"] == args.pose_source else \
        f"train {args.pose_source}, eval {eval_kwargs['pose_source']}"
    title = (f"{env_id.split('/')[1]} (pose_source={ps}), simulated; "
             f"held-out: PPO {final['success']:.0%}")
    plot_curve(rows, f"{recipe['algorithm']} ({args.obs_mode}{', LSTM' if args.recurrent else ''})", wanted,
               len(dev), title, out / "curve.png", "held-out" if args.curve_split == "test" else "dev")
    if args.docs:
        Path(args.docs).mkdir(parents=True, exist_ok=True)
        shutil.copy(out / "curve.png", Path(args.docs) / f"ppo_gpisnav_{name}.png")
    print(f"wrote {out}; held-out success PPO {final['success']:.2f}; "
          + ", ".join(f"{b} {base_test[b]['success']:.2f}" for b in wanted)
          + f"; training {train_wall / 60:.1f} min wall, {train_cpu / 60:.1f} min CPU", flush=True)


if __name__ == "__main__":
    main()
