"""Train a recipe on a GPISNav tier over several seeds, score every run and the scripted experts on
the same held-out worlds (default slam mode), and report with rliable.

Usage (one tier; the shipped policies' commands are in benchmarks/RESULTS.md)::

    python benchmarks/train_learning.py --env polar_sim/GPISNav-Room-v1 --recipe dagger --seeds 0 1 2 \\
        --test-episodes 50 --out polar_sim_out/learning/room --ship 0 --docs docs/img

For each seed: ``polar_sim.envs.recipes.train`` on training worlds (seeds 0-999) with its dev
curve (worlds 1000..), then the final policy on ``--test-episodes`` held-out worlds (10000..);
``SDFReactive`` and ``SDFNavigator`` on the same worlds with their own (default) stencil.
Writes ``results.json`` (per seed: held-out success, collisions, wall and CPU time; the rliable
IQM and 95 % stratified bootstrap CI of held-out success over seeds) and ``curves.png``
(dev success against env steps and wall time). ``--ship SEED`` copies that seed's policy (named
before any held-out score is seen) to ``polar_sim/data/policies/``. ``--only-score`` re-scores
the policies already in ``--out``. Runs stop and resume per seed (a seed whose ``summary.json``
exists is not retrained; a held-out score is kept in the seed's ``heldout.json`` and not re-run for
the same worlds), so seeds may train in separate processes (``--seeds 1``, ``--seeds 2``) and a last
``--seeds 0 1 2`` gathers them. ``--train-mode`` also scores each policy, on the same held-out
worlds, in the mode it trained in (the recipe's ``train_pose_source`` / ``train_sdf_source``): the
gap between that and the slam score is the train/test observation shift.
"""

import argparse
import json
import os
import shutil
import time
from pathlib import Path

import polar_sim.envs  # noqa: F401
from polar_sim.envs.evaluate import evaluate, policy_env_kwargs
from polar_sim.envs.recipes import check_recipe, train
from polar_sim.envs.rl_report import iqm_with_ci, plot_learning_curves

TEST_SEED = 10_000
EXPERTS = {"SDFReactive": "polar_sim.envs.policies:SDFReactive", "SDFNavigator": "polar_sim.envs.policies:SDFNavigator"}


def score(env_id, policy, episodes, env_kwargs=None):
    """Held-out success, collision rate and mean length of ``policy`` (default slam mode)."""
    t = time.perf_counter()
    _, s = evaluate(env_id, policy, episodes=episodes, seed=TEST_SEED, env_kwargs=env_kwargs, progress=False)
    return {"success": s["success_rate"], "collision": s["mean_collision"], "mean_length": s["mean_length"],
            "episodes": episodes, "eval_wall_s": time.perf_counter() - t}


def cached_score(run, key, env_id, policy, episodes, env_kwargs=None):
    """``score`` kept in ``run/heldout.json`` under ``key`` (re-run only for other worlds)."""
    path = run / "heldout.json"
    cache = json.loads(path.read_text()) if path.exists() else {}
    if cache.get(key, {}).get("episodes") != episodes:
        cache[key] = score(env_id, policy, episodes, env_kwargs)
        path.write_text(json.dumps(cache, indent=2))
    return cache[key]


def train_mode_kwargs(params, policy_env_kwargs):
    """The ``gym.make`` arguments of the mode a recipe trained in."""
    kw = dict(policy_env_kwargs)
    kw["pose_source"] = params["train_pose_source"]
    if "train_sdf_source" in params:
        kw["sdf_source"] = params["train_sdf_source"]
    return kw


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", required=True)
    ap.add_argument("--recipe", default="dagger")
    ap.add_argument("--params", default="{}", help="JSON object of recipe parameters")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--test-episodes", type=int, default=50)
    ap.add_argument("--experts", default="SDFReactive,SDFNavigator", help="comma-separated; empty: none")
    ap.add_argument("--out", required=True)
    ap.add_argument("--ship", type=int, default=None, help="copy this seed's policy into polar_sim/data/policies")
    ap.add_argument("--docs", default=None, help="also copy curves.png here, named after the tier and recipe")
    ap.add_argument("--only-score", action="store_true")
    ap.add_argument("--train-mode", action="store_true", help="also score each policy in its training mode")
    args = ap.parse_args()
    params = check_recipe(args.recipe, json.loads(args.params), args.env)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"env_id": args.env, "recipe": args.recipe, "params": params, "test_seeds": [TEST_SEED, TEST_SEED +
               args.test_episodes - 1], "runs": {}, "experts": {}, "load_average": os.getloadavg(),
               "date": time.strftime("%Y-%m-%d")}
    curves = []
    for seed in args.seeds:
        run = out / f"seed{seed}"
        if not (run / "summary.json").exists() and not args.only_score:
            train(args.recipe, args.env, params=json.loads(args.params), seed=seed, out=run, progress=False)
        summary = json.loads((run / "summary.json").read_text())
        curves.append(summary["curve"])
        res = cached_score(run, "slam", args.env, str(run / "policy.npz"), args.test_episodes)
        results["runs"][seed] = {"steps": summary["steps"], "wall_s": summary["wall_s"], "cpu_s": summary["cpu_s"],
                                 "test": res}
        if args.train_mode:
            kw = train_mode_kwargs(params, policy_env_kwargs(str(run / "policy.npz"), args.env))
            results["runs"][seed]["test_train_mode"] = cached_score(run, "train_mode", args.env,
                                                                    str(run / "policy.npz"), args.test_episodes, kw)
            results["train_mode_env_kwargs"] = kw
        print(f"seed {seed}: {summary['steps']} steps, {summary['wall_s'] / 60:.1f} min wall, "
              f"{summary['cpu_s'] / 60:.1f} min CPU; held-out {res}; in the training mode "
              f"{results['runs'][seed].get('test_train_mode')}", flush=True)
        (out / "results.json").write_text(json.dumps(results, indent=2))
    for name in filter(None, args.experts.split(",")):
        results["experts"][name] = score(args.env, EXPERTS[name], args.test_episodes)
        print(f"{name}: {results['experts'][name]}", flush=True)
    succ = [[r["test"]["success"]] for r in results["runs"].values()]
    iqm, lo, hi = iqm_with_ci({args.recipe: succ})[args.recipe]
    results["iqm_success"] = {"iqm": iqm, "ci95": [lo, hi], "runs": len(succ)}
    (out / "results.json").write_text(json.dumps(results, indent=2))
    print(f"held-out success over {len(succ)} seeds: IQM {iqm:.3f} [{lo:.3f}, {hi:.3f}]", flush=True)
    if any(curves):
        title = (f"{args.recipe} on {args.env.split('/')[1]}, simulated; dev worlds 1000..; "
                 f"held-out IQM {iqm:.0%} [{lo:.0%}, {hi:.0%}] over {len(succ)} seeds")
        plot_learning_curves({args.recipe: [c for c in curves if c]}, out / "curves.png", title=title,
                             baselines={k: v["success"] for k, v in results["experts"].items()})
        if args.docs:
            name = f"learn_{args.env.split('/')[1].lower()}_{args.recipe}.png"
            shutil.copy(out / "curves.png", Path(args.docs) / name)
    if args.ship is not None:
        dest = Path(polar_sim.envs.__file__).parent.parent / "data" / "policies" / (args.env.split("/")[1] + ".npz")
        shutil.copy(out / f"seed{args.ship}" / "policy.npz", dest)
        print(f"shipped seed {args.ship} as {dest}", flush=True)


if __name__ == "__main__":
    main()
