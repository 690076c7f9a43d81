"""GPISNav-v1: closed-loop localisation against the truth, the scripted baselines per tier and pose
source, and throughput, on held-out worlds (episode seeds 10000, 10001, ...; ``--split dev``
uses 0, 1, ..., the seeds the defaults were chosen on).

Parts (``--part``, default all):

- ``localisation``: ``SDFNavigator`` on the default tier (3x3 rooms) with ``pose_source`` slam,
  odometry and truth at default noise: success, collisions, time-outs, and the pose error
  against the truth over every step (median, p95, max per episode and pooled), divergences
  (> 0.5 m) and ICP-G's failures.
- ``tiers``: random actions, ``SDFReactive`` and ``SDFNavigator`` on every tier (slam).
- ``throughput``: steps/s in one process with SDF-reactive actions, slam and truth alternating
  (``--repeats`` pairs; speed swings with the machine's load, so read the ratio of a pair).
- ``render``: the README's image ``docs/img/env_gpisnav_v1.png`` (not part of ``all``).

Writes ``benchmarks/results/envs_gpisnav_v1.md`` (tables) and ``.json`` (every episode).

Usage: python benchmarks/bench_envs_gpisnav_v1.py [--episodes 50] [--part tiers] [--split dev]
"""

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
from tqdm.auto import tqdm  # noqa: E402

import polar_sim.envs  # noqa: E402,F401  (registers the ids)
from polar_sim.envs.evaluate import RandomPolicy  # noqa: E402
from polar_sim.envs.policies import SDFNavigator, SDFReactive  # noqa: E402

TIERS = {"room": "polar_sim/GPISNav-Room-v1", "rooms2": "polar_sim/GPISNav-Rooms2-v1", "rooms3": "polar_sim/GPISNav-v1"}
OUT = Path(__file__).parent / "results" / "envs_gpisnav_v1"


def episodes(env_id, policy_name, seeds, **kw):
    """One dict per episode: outcome, length, and the pose error over its steps."""
    env = gym.make(env_id, **kw)
    pol = {"random": lambda: RandomPolicy(env.action_space, seed=0), "reactive": SDFReactive,
           "navigator": SDFNavigator}[policy_name]()
    rows = []
    for s in tqdm(seeds, desc=f"{env_id.split('/')[1]} {policy_name} {kw.get('pose_source', 'slam')}", leave=False):
        obs, info = env.reset(seed=int(s))
        pol.reset()
        err, done, n = [info["pose_error"]], False, 0
        c0 = time.process_time()
        while not done:
            obs, r, term, trunc, info = env.step(pol(obs))
            err.append(info["pose_error"])
            done, n = term or trunc, n + 1
        e = np.array(err)
        rows.append({"seed": int(s), "success": bool(info["is_success"]), "collision": bool(info["collision"]),
                     "timeout": bool(not term), "steps": n, "cpu_s": time.process_time() - c0,
                     "path_length": info["path_length"], "err_median": float(np.median(e)),
                     "err_p95": float(np.percentile(e, 95)), "err_max": float(e.max()),
                     "err_final": float(e[-1]), "failures": int(info["localization_failures"]),
                     "errors": e.tolist()})
    env.close()
    return rows


def summarise(rows):
    pooled = np.concatenate([r["errors"] for r in rows])
    f = lambda k: float(np.mean([r[k] for r in rows]))  # noqa: E731
    return {"episodes": len(rows), "success": f("success"), "collision": f("collision"), "timeout": f("timeout"),
            "mean_steps": f("steps"), "pose_err_median": float(np.median(pooled)),
            "pose_err_p95": float(np.percentile(pooled, 95)), "pose_err_max": float(pooled.max()),
            "episodes_median_le_3cm_p95_le_10cm": float(np.mean([r["err_median"] <= 0.03 and r["err_p95"] <= 0.10
                                                                 for r in rows])),
            "no_divergence_0.5m": float(np.mean([r["err_max"] <= 0.5 for r in rows])),
            "failures_per_episode": f("failures"), "cpu_ms_per_step": 1e3 * sum(r["cpu_s"] for r in rows)
            / max(sum(r["steps"] for r in rows), 1)}


def throughput(pose_source, steps):
    env = gym.make("polar_sim/GPISNav-v1", pose_source=pose_source)
    pol = SDFReactive()
    obs, _ = env.reset(seed=0)
    for k in range(20 + steps):
        if k == 20:
            t0, c0 = time.perf_counter(), time.process_time()
        obs, r, te, tr, _ = env.step(pol(obs))
        if te or tr:
            obs, _ = env.reset()
            pol.reset()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    env.close()
    return steps / wall, steps / cpu


def render_image(path, seed=10_001, steps=120):
    """``render()`` of GPISNav-v1 (slam) after ``steps`` of SDFNavigator on a held-out world."""
    import cv2

    env = gym.make("polar_sim/GPISNav-v1", render_mode="rgb_array")
    pol = SDFNavigator()
    obs, _ = env.reset(seed=seed)
    for _ in range(steps):
        obs, r, te, tr, info = env.step(pol(obs))
        if te or tr:
            break
    img = env.render()
    env.close()
    cv2.imwrite(str(path), img[..., ::-1])
    print(f"wrote {path} (pose error {info['pose_error']:.3f} m)")


def fmt_row(name, s):
    return (f"| {name} | {s['success']:.0%} | {s['collision']:.0%} | {s['timeout']:.0%} | {s['mean_steps']:.0f} | "
            f"{100 * s['pose_err_median']:.1f} / {100 * s['pose_err_p95']:.1f} / {100 * s['pose_err_max']:.1f} | "
            f"{s['no_divergence_0.5m']:.0%} | {s['failures_per_episode']:.1f} | {s['cpu_ms_per_step']:.1f} |")


HEADER = ("| configuration | success | collisions | time-outs | mean steps | pose error median / p95 / max, cm | "
          "episodes without divergence > 0.5 m | ICP-G failures per episode | CPU ms per step (env + policy) |\n"
          "|---|---|---|---|---|---|---|---|---|")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--split", default="test", choices=["test", "dev"])
    ap.add_argument("--part", default="all", choices=["all", "localisation", "tiers", "throughput", "render"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=600, help="throughput: timed steps per run")
    args = ap.parse_args()
    if args.part == "render":
        return render_image(Path(__file__).parents[1] / "docs" / "img" / "env_gpisnav_v1.png")
    seed0 = 10_000 if args.split == "test" else 0
    seeds = np.arange(seed0, seed0 + args.episodes)
    out = Path(f"{OUT}{'' if args.split == 'test' else '_dev'}")
    results = json.loads(out.with_suffix(".json").read_text()) if out.with_suffix(".json").exists() else {}
    results["seeds"] = [int(seeds[0]), int(seeds[-1])]
    results["split"] = args.split
    ran = {"seeds", "split"}
    if args.part in ("all", "localisation"):
        res = {}
        for ps in ("slam", "odometry", "truth"):
            rows = episodes("polar_sim/GPISNav-v1", "navigator", seeds, pose_source=ps)
            res[ps] = {"summary": summarise(rows), "episodes": rows}
            print(ps, res[ps]["summary"], flush=True)
        results["localisation"] = res
        ran.add("localisation")
    if args.part in ("all", "tiers"):
        res = {}
        for tier, env_id in TIERS.items():
            for pol in ("random", "reactive", "navigator"):
                rows = episodes(env_id, pol, seeds)
                res[f"{tier}/{pol}"] = {"summary": summarise(rows), "episodes": rows}
                print(tier, pol, res[f"{tier}/{pol}"]["summary"], flush=True)
        results["tiers"] = res
        ran.add("tiers")
    if args.part in ("all", "throughput"):
        runs = []
        for _ in range(args.repeats):
            pair = {ps: throughput(ps, args.steps) for ps in ("slam", "truth")}
            runs.append(pair)
            print("throughput", pair, flush=True)
        results["throughput"] = {"runs": runs, "load": os.getloadavg()}
        ran.add("throughput")
    # Parts may run in parallel processes: merge with what the others wrote meanwhile.
    latest = json.loads(out.with_suffix(".json").read_text()) if out.with_suffix(".json").exists() else {}
    results = {**latest, **{k: v for k, v in results.items() if k not in latest or k in ran}}
    out.with_suffix(".json").write_text(json.dumps(results))

    lines = [f"# GPISNav-v1 benchmark ({args.split} split: episode seeds {seeds[0]}-{seeds[-1]})", "",
             f"`python benchmarks/bench_envs_gpisnav_v1.py --episodes {args.episodes}"
             f"{'' if args.split == 'test' else ' --split dev'}`; "
             f"{time.strftime('%Y-%m-%d')}. Default noise (lidar 1 cm, 1 % dropout; wheel odometry).", ""]
    if "localisation" in results:
        lines += ["## SDFNavigator on the default tier (3x3 rooms) by pose source", "", HEADER]
        lines += [fmt_row(ps, r["summary"]) for ps, r in results["localisation"].items()] + [""]
    if "tiers" in results:
        lines += ["## Tiers (pose_source slam)", "", HEADER]
        lines += [fmt_row(k, r["summary"]) for k, r in results["tiers"].items()] + [""]
    if "throughput" in results:
        lines += ["## Throughput, one process, SDF-reactive actions (steps/s wall / CPU)", "",
                  "| run | slam | truth | slam / truth |", "|---|---|---|---|"]
        for i, p in enumerate(results["throughput"]["runs"]):
            lines.append(f"| {i + 1} | {p['slam'][0]:.0f} / {p['slam'][1]:.0f} | {p['truth'][0]:.0f} / "
                         f"{p['truth'][1]:.0f} | {p['slam'][1] / p['truth'][1]:.2f} (CPU) |")
        lines += ["", f"load average at the end: {results['throughput']['load'][0]:.1f}", ""]
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out.with_suffix('.md')}")


if __name__ == "__main__":
    main()
