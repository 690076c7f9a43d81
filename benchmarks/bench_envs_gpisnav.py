"""GPISNav-v0 throughput: steps/s in one process per SDF source, and AsyncVectorEnv scaling.

Every step includes the physics (10 Hz control), a 270-beam lidar scan, the map update and the
stencil query (and the exact SDF for info). Actions come from the SDF-reactive baseline so the
robot moves through the world as an agent's would.

AsyncVectorEnv scaling is measured three ways, each against one process with the same action
stream: the reactive baseline (one policy per worker), uniform random actions (which collide and
reset every ~35 steps; a reset builds a new world), and, as the machine's own ceiling, two
independent single processes run side by side (no vector env at all). AsyncVectorEnv steps its
workers in lockstep, so every vector step costs the slower worker's step.

Usage: python benchmarks/bench_envs_gpisnav.py [--quick] [--repeats 3]
"""

import argparse
import multiprocessing as mp
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import polar_sim.envs  # noqa: E402,F401  (registers the ids)
from polar_sim.envs.policies import SDFReactive  # noqa: E402
from polar_sim.envs.vector import make_async_vector_env  # noqa: E402


def single(source, steps):
    env = gym.make("polar_sim/GPISNav-v0", sdf_source=source)
    pol = SDFReactive()
    obs, _ = env.reset(seed=0)
    for _ in range(20):  # warm-up: numba compilation, first map
        obs, r, te, tr, _ = env.step(pol(obs))
        if te or tr:
            obs, _ = env.reset()
            pol.reset()
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(steps):
        obs, r, te, tr, _ = env.step(pol(obs))
        if te or tr:
            obs, _ = env.reset()
            pol.reset()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    env.close()
    return steps / wall, steps / cpu


def single_random(source, steps):
    """One process with the vector run's action stream (uniform random, resets included): the
    like-for-like baseline of the AsyncVectorEnv ratio (random actions collide and reset far more
    often than the reactive baseline, and a reset builds a new world)."""
    env = gym.make("polar_sim/GPISNav-v0", sdf_source=source)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    act = lambda: rng.uniform([0.0, -1.0], [0.8, 1.0], 2).astype(np.float32)  # noqa: E731
    for _ in range(20):
        _, _, te, tr, _ = env.step(act())
        if te or tr:
            env.reset()
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, te, tr, _ = env.step(act())
        if te or tr:
            env.reset()
    rate = steps / (time.perf_counter() - t0)
    env.close()
    return rate


def _timed_random(source, steps, barrier, out):
    """single_random's stream in a child process: warm up, wait for the others, then time."""
    env = gym.make("polar_sim/GPISNav-v0", sdf_source=source)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for k in range(20 + steps):
        if k == 20:
            barrier.wait()
            t0 = time.perf_counter()
        _, _, te, tr, _ = env.step(rng.uniform([0.0, -1.0], [0.8, 1.0], 2).astype(np.float32))
        if te or tr:
            env.reset()
    out.put(time.perf_counter() - t0)
    env.close()


def side_by_side(source, steps, n):
    """n independent single processes (spawn) started together after their warm-up: their
    summed steps over the time until the last one finishes."""
    ctx = mp.get_context("spawn")
    barrier, out = ctx.Barrier(n), ctx.Queue()
    procs = [ctx.Process(target=_timed_random, args=(source, steps, barrier, out)) for _ in range(n)]
    for p in procs:
        p.start()
    times = [out.get() for _ in procs]
    for p in procs:
        p.join()
    return n * steps / max(times)


def vector_reactive(source, steps, n, pin=False):
    """AsyncVectorEnv with one SDF-reactive policy per worker (resets its policy at autoreset)."""
    venv = make_async_vector_env("polar_sim/GPISNav-v0", n, pin_workers=pin, sdf_source=source)
    obs, _ = venv.reset(seed=list(range(n)))
    pols = [SDFReactive() for _ in range(n)]

    def act(obs, done):
        for k in np.flatnonzero(done):
            pols[k].reset()
        return np.stack([pols[k]({key: v[k] for key, v in obs.items()}) for k in range(n)])

    done = np.zeros(n, bool)
    for _ in range(20):
        obs, r, te, tr, _ = venv.step(act(obs, done))
        done = te | tr
    t0 = time.perf_counter()
    for _ in range(steps):
        obs, r, te, tr, _ = venv.step(act(obs, done))
        done = te | tr
    rate = n * steps / (time.perf_counter() - t0)
    venv.close()
    return rate


class _TimedStep(gym.Wrapper):
    """Puts the wall time of each step (or autoreset) into info["step_s"]."""

    def step(self, action):
        t0 = time.perf_counter()
        obs, r, te, tr, info = self.env.step(action)
        return obs, r, te, tr, {**info, "step_s": time.perf_counter() - t0}

    def reset(self, **kw):
        t0 = time.perf_counter()
        obs, info = self.env.reset(**kw)
        return obs, {**info, "step_s": time.perf_counter() - t0}


def _timed_env(source):
    return _TimedStep(gym.make("polar_sim.envs:polar_sim/GPISNav-v0", sdf_source=source))


def lockstep_breakdown(source, steps, n):
    """Where a vector step's wall time goes: the workers' mean step, the slower worker's step
    (lockstep: the vector step waits for it), and the rest (the main process and the pipes)."""
    import functools

    venv = gym.vector.AsyncVectorEnv([functools.partial(_timed_env, source)] * n, context="spawn")
    venv.reset(seed=list(range(n)))
    rng = np.random.default_rng(0)
    wall, worker = [], []
    for k in range(20 + steps):
        t0 = time.perf_counter()
        *_, info = venv.step(rng.uniform([0.0, -1.0], [0.8, 1.0], (n, 2)).astype(np.float32))
        if k >= 20:
            wall.append(time.perf_counter() - t0)
            worker.append(info["step_s"])
    venv.close()
    wall, worker = 1e3 * np.mean(wall), 1e3 * np.asarray(worker)
    return worker.mean(), worker.max(1).mean(), wall


def vector(source, steps, n, pin=False):
    venv = make_async_vector_env("polar_sim/GPISNav-v0", n, pin_workers=pin, sdf_source=source)
    venv.reset(seed=list(range(n)))
    rng = np.random.default_rng(0)
    act = lambda: rng.uniform([0.0, -1.0], [0.8, 1.0], (n, 2)).astype(np.float32)  # noqa: E731
    for _ in range(20):
        venv.step(act())
    t0 = time.perf_counter()
    for _ in range(steps):
        venv.step(act())
    rate = n * steps / (time.perf_counter() - t0)
    venv.close()
    return rate


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeats", type=int, default=3, help="alternating pairs for the vector scaling")
    args = ap.parse_args()
    steps = 60 if args.quick else 400
    print(f"load before: {os.getloadavg()[0]:.2f}")
    print("| sdf_source | steps/s (wall) | steps/s (CPU) |\n|---|---|---|")
    rates = {}
    for src in ("gpis", "truth", "occupancy_edt"):
        w, c = single(src, steps)
        rates[src] = w
        print(f"| {src} | {w:.1f} | {c:.1f} |", flush=True)
    # The machine's speed drifts by 20 % between runs of the same code (shared cores), so the
    # scaling is measured in alternating pairs (one process, then the vector env) and the
    # ratio of each pair is reported, with their median.
    pairs = {"reactive": [], "reactive pinned": [], "random": [], "pinned": [], "side by side": []}
    vsteps = steps * 2
    for _ in range(args.repeats):
        one = single("gpis", vsteps)[0]
        pairs["reactive"].append((one, vector_reactive("gpis", vsteps, 2)))
        one = single("gpis", vsteps)[0]
        pairs["reactive pinned"].append((one, vector_reactive("gpis", vsteps, 2, pin=True)))
        one = single_random("gpis", vsteps)
        pairs["random"].append((one, vector("gpis", vsteps, 2)))
        one = single_random("gpis", vsteps)
        pairs["pinned"].append((one, vector("gpis", vsteps, 2, pin=True)))
        one = single_random("gpis", vsteps)
        pairs["side by side"].append((one, side_by_side("gpis", vsteps, 2)))
    mean, slowest, wall = lockstep_breakdown("gpis", vsteps, 2)
    print(f"\nlockstep breakdown (random actions, 2 workers): worker step {mean:.2f} ms mean, the slower of "
          f"the two {slowest:.2f} ms (lockstep: +{100 * (slowest / mean - 1):.0f} %), vector step {wall:.2f} ms "
          f"(main process and pipes: +{wall - slowest:.2f} ms); at the workers' own step time 2 workers give "
          f"{2 * mean / wall:.2f}x")
    print("\n| action stream | one process, steps/s | 2 workers, steps/s | ratio per pair | median |\n|---|---|---|---|---|")
    for name, ps in pairs.items():
        label = {"reactive": "SDF-reactive, AsyncVectorEnv (spawn)",
                 "reactive pinned": "SDF-reactive, `make_async_vector_env` (workers pinned to CPUs)", "random": "random (resets), AsyncVectorEnv (spawn)",
                 "pinned": "random (resets), `make_async_vector_env` (workers pinned to CPUs)",
                 "side by side": "random, two independent processes (the machine's ceiling)"}[name]
        ratios = [b / a for a, b in ps]
        print(f"| {label} | {' / '.join(f'{a:.0f}' for a, _ in ps)} | {' / '.join(f'{b:.0f}' for _, b in ps)} | "
              f"{' / '.join(f'{r:.2f}' for r in ratios)} | {np.median(ratios):.2f}x |", flush=True)
    print(f"load after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
