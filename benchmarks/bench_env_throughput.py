"""Environment throughput (issue 32, item 1): GPISNav's steps per CPU-second as a fraction of
``HalfCheetah-v5``'s, measured side by side in one process, and the wall-clock gain of an
``AsyncVectorEnv`` of 2 workers over one process.

The machine's speed swings 2-3x with its load, so nothing here is read alone:

- **single**: every configuration steps ``--steps`` times in each of ``--rounds`` rounds, in an
  order that rotates every round (so each one is measured before and after every other); the CPU
  time (``time.process_time``) of a block gives its steps per CPU-second, and its ratio to the
  HalfCheetah block of the same round is the figure. Episodes that end are reset and the reset is
  timed with the steps, as in training.
- **vector**: one process and ``make_async_vector_env(id, 2)`` (spawn, workers pinned to CPUs)
  alternate ``--pairs`` times on the same action stream; wall-clock steps per second, the vector
  env counting the steps of both workers. Two independent processes side by side are measured
  too: the machine's own ceiling for 2 workers at that moment.

Actions: random, forward-biased, seeded (``v`` uniform in [0, 1] of ``max_speed``, ``omega``
uniform in [-1, 1]); HalfCheetah's ``action_space.sample()`` seeded the same way. MuJoCo's
threads are not used; run with ``OMP_NUM_THREADS=1``.

Writes ``benchmarks/results/env_throughput.md`` (tables) and ``.json`` (every block);
``env_throughput_single`` / ``env_throughput_vector`` with ``--part``.

Usage: python benchmarks/bench_env_throughput.py [--rounds 5] [--steps 2000] [--part single|vector|all]
       [--configs room_v1_truth,room_v1_slam,...]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import polar_sim.envs  # noqa: E402,F401  (registers the ids)

OUT = Path(__file__).parent / "results" / "env_throughput"
TRUTH = {"pose_source": "truth", "sdf_source": "truth"}
#: name -> (env id, gym.make kwargs)
CONFIGS = {
    "halfcheetah": ("HalfCheetah-v5", {}),
    "room_v1_truth": ("polar_sim/GPISNav-Room-v1", TRUTH),
    "room_v1_slam": ("polar_sim/GPISNav-Room-v1", {}),
    "rooms2_v1_truth": ("polar_sim/GPISNav-Rooms2-v1", TRUTH),
    "v1_truth": ("polar_sim/GPISNav-v1", TRUTH),
    "v1_slam": ("polar_sim/GPISNav-v1", {}),
}
DEFAULT = ("halfcheetah", "room_v1_truth", "room_v1_slam")


def _register_v2():
    """The kinematic ids, where this version of polar_sim has them."""
    from polar_sim.envs import ENV_IDS

    for tier, suffix in (("room", "Room-"), ("rooms2", "Rooms2-"), ("rooms3", "")):
        env_id = f"polar_sim/GPISNav-{suffix}v2"
        if env_id in ENV_IDS:
            short = {"room": "room", "rooms2": "rooms2", "rooms3": ""}[tier]
            CONFIGS[f"{short + '_' if short else ''}v2_truth"] = (env_id, TRUTH)
            CONFIGS[f"{short + '_' if short else ''}v2_slam"] = (env_id, {})


_register_v2()


class Runner:
    """One environment and its seeded action stream; ``block(n)`` steps it ``n`` times."""

    def __init__(self, name, seed=0):
        env_id, kwargs = CONFIGS[name]
        self.env = gym.make(env_id, **kwargs)
        self.rng = np.random.default_rng(seed)
        self.cheetah = env_id.startswith("HalfCheetah")
        if self.cheetah:
            self.env.action_space.seed(seed)
        self.env.reset(seed=seed)
        self.resets = 0

    def action(self):
        if self.cheetah:
            return self.env.action_space.sample()
        return np.array([self.rng.uniform(0.0, 1.0), self.rng.uniform(-1.0, 1.0)], np.float32)

    def block(self, n):
        """(CPU s, wall s, resets) of ``n`` steps (episodes that end are reset, timed)."""
        c0, t0, r0 = time.process_time(), time.perf_counter(), self.resets
        env = self.env
        for _ in range(n):
            _, _, term, trunc, _ = env.step(self.action())
            if term or trunc:
                env.reset()
                self.resets += 1
        return time.process_time() - c0, time.perf_counter() - t0, self.resets - r0


def single(names, rounds, steps):
    runners = {n: Runner(n) for n in names}
    for r in runners.values():  # warm up: numba compilation, caches, first episodes
        r.block(200)
    rows = []
    for k in range(rounds):
        order = names[k % len(names):] + names[: k % len(names)]
        row = {"round": k, "load": os.getloadavg()[0]}
        for n in order:
            cpu, wall, resets = runners[n].block(steps)
            row[n] = {"cpu_s": cpu, "wall_s": wall, "resets": resets, "steps_per_cpu_s": steps / cpu}
        rows.append(row)
        print({n: round(row[n]["steps_per_cpu_s"]) for n in names}, f"load {row['load']:.1f}", flush=True)
    for r in runners.values():
        r.env.close()
    summary = {}
    for n in names:
        rate = [row[n]["steps_per_cpu_s"] for row in rows]
        ratio = [row[n]["steps_per_cpu_s"] / row["halfcheetah"]["steps_per_cpu_s"] for row in rows]
        summary[n] = {"steps_per_cpu_s_median": float(np.median(rate)), "ratio_median": float(np.median(ratio)),
                      "ratio_min": float(np.min(ratio)), "ratio_max": float(np.max(ratio)),
                      "steps_per_episode": steps * rounds / max(1, sum(row[n]["resets"] for row in rows))}
    return {"rounds": rows, "summary": summary}


def _one_process_rate(name, steps, seed=0):
    r = Runner(name, seed)
    r.block(100)
    _, wall, _ = r.block(steps)
    r.env.close()
    return steps / wall


def _vector_rate(name, steps):
    from polar_sim.envs.vector import make_async_vector_env

    env_id, kwargs = CONFIGS[name]
    venv = make_async_vector_env(env_id, 2, **kwargs)
    rng = np.random.default_rng(0)
    venv.reset(seed=[0, 1])

    def act():
        return np.stack([[rng.uniform(0.0, 1.0), rng.uniform(-1.0, 1.0)] for _ in range(2)]).astype(np.float32)

    for _ in range(100):
        venv.step(act())
    t0 = time.perf_counter()
    for _ in range(steps):
        venv.step(act())
    wall = time.perf_counter() - t0
    venv.close()
    return 2 * steps / wall


def _two_processes_rate(name, steps):
    """Two independent one-process runs side by side: steps of both over the longer wall time."""
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import bench_env_throughput as b; "
            f"print(b._one_process_rate({name!r}, {steps}, seed=int(sys.argv[1])))")
    t0 = time.perf_counter()
    procs = [subprocess.Popen([sys.executable, "-c", code, str(s)], stdout=subprocess.PIPE, text=True)
             for s in (0, 1)]
    rates = [float(p.communicate()[0].split()[-1]) for p in procs]
    return float(sum(rates)), time.perf_counter() - t0


def vector(names, pairs, steps):
    out = {}
    for n in names:
        rows = []
        for k in range(pairs):
            one = _one_process_rate(n, steps)
            vec = _vector_rate(n, steps)
            two, _ = _two_processes_rate(n, steps)
            rows.append({"one": one, "vector2": vec, "two_processes": two, "ratio": vec / one,
                         "ceiling": two / one, "load": os.getloadavg()[0]})
            print(n, {k: round(v, 2) for k, v in rows[-1].items()}, flush=True)
        out[n] = {"pairs": rows, "ratio_median": float(np.median([r["ratio"] for r in rows])),
                  "ceiling_median": float(np.median([r["ceiling"] for r in rows]))}
    return out


def _commit():
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                          cwd=Path(__file__).parent).stdout.strip()


def write(results, args):
    out = OUT if args.part == "all" else OUT.with_name(f"{OUT.name}_{args.part}")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(results, indent=1))
    lines = [f"# Environment throughput ({results['date']}, commit {results['commit']})", "",
             f"`{results['command']}`", ""]
    if "single" in results:
        lines += ["## One process, steps per CPU-second, against HalfCheetah-v5 in the same rounds", "",
                  "| configuration | id, kwargs | steps/CPU-s (median) | / HalfCheetah (median, min-max) | "
                  "steps per episode |", "|---|---|---|---|---|"]
        for n, s in results["single"]["summary"].items():
            env_id, kw = CONFIGS[n]
            lines.append(f"| {n} | `{env_id}` {kw or ''} | {s['steps_per_cpu_s_median']:.0f} | "
                         f"{s['ratio_median']:.3f} ({s['ratio_min']:.3f}-{s['ratio_max']:.3f}) | "
                         f"{s['steps_per_episode']:.0f} |")
        loads = [r["load"] for r in results["single"]["rounds"]]
        lines += ["", f"load average (1 min) during the rounds: {min(loads):.1f}-{max(loads):.1f}", ""]
    if "vector" in results:
        lines += ["## AsyncVectorEnv, 2 workers (pinned), against one process: wall-clock steps/s", "",
                  "| configuration | pair | one process | 2 workers | ratio | two independent processes "
                  "(ceiling) | load |", "|---|---|---|---|---|---|---|"]
        for n, v in results["vector"].items():
            for k, r in enumerate(v["pairs"]):
                lines.append(f"| {n} | {k + 1} | {r['one']:.0f} | {r['vector2']:.0f} | {r['ratio']:.2f} | "
                             f"{r['ceiling']:.2f} | {r['load']:.1f} |")
            lines.append(f"| {n} | median | | | **{v['ratio_median']:.2f}** | {v['ceiling_median']:.2f} | |")
        lines.append("")
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out.with_suffix('.md')}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="all", choices=["all", "single", "vector"])
    ap.add_argument("--configs", default=",".join(DEFAULT),
                    help=f"comma-separated, among {', '.join(CONFIGS)} (halfcheetah is always added)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--steps", type=int, default=2000, help="steps per block (single) or per run (vector)")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--vector-configs", default="room_v1_truth,room_v1_slam")
    args = ap.parse_args()
    names = [n for n in args.configs.split(",") if n and n != "halfcheetah"]
    unknown = [n for n in names + args.vector_configs.split(",") if n not in CONFIGS]
    if unknown:
        raise SystemExit(f"unknown configuration(s) {unknown}; known: {list(CONFIGS)}")
    results = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "commit": _commit(),
               "command": "python benchmarks/bench_env_throughput.py " + " ".join(sys.argv[1:]),
               "load_start": os.getloadavg()}
    if args.part in ("all", "single"):
        results["single"] = single(["halfcheetah"] + names, args.rounds, args.steps)
    if args.part in ("all", "vector"):
        results["vector"] = vector([n for n in args.vector_configs.split(",") if n], args.pairs, args.steps)
    results["load_end"] = os.getloadavg()
    write(results, args)


if __name__ == "__main__":
    main()
