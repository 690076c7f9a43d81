"""GPISNav-v0 throughput: steps/s in one process per SDF source, and AsyncVectorEnv scaling.

Every step includes the physics (10 Hz control), a 270-beam lidar scan, the map update and the
stencil query (and the exact SDF for info). Actions come from the SDF-reactive baseline so the
robot moves through the world as an agent's would.

AsyncVectorEnv scaling is measured three ways, each against one process with the same action
stream: the reactive baseline (one policy per worker), uniform random actions (which collide and
reset every ~35 steps; a reset builds a new world), and, as the machine's own ceiling, two
independent single processes run side by side (no vector env at all). AsyncVectorEnv steps its
workers in lockstep, so every vector step costs the slower worker's step.

Usage: python benchmarks/bench_envs_gpisnav.py [--quick]
"""

import argparse
import multiprocessing as mp
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import polar_sim  # noqa: E402,F401
from polar_sim.envs.policies import SDFReactive  # noqa: E402


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


def _one_random(args):
    return single_random(*args)


def side_by_side(source, steps, n):
    """n independent single processes at once (spawn): their summed steps/s."""
    with mp.get_context("spawn").Pool(n) as pool:
        return sum(pool.map(_one_random, [(source, steps)] * n))


def vector_reactive(source, steps, n):
    """AsyncVectorEnv with one SDF-reactive policy per worker (resets its policy at autoreset)."""
    fns = [lambda: gym.make("polar_sim:polar_sim/GPISNav-v0", sdf_source=source) for _ in range(n)]
    venv = gym.vector.AsyncVectorEnv(fns, context="spawn")
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


def vector(source, steps, n):
    fns = [lambda: gym.make("polar_sim:polar_sim/GPISNav-v0", sdf_source=source) for _ in range(n)]
    venv = gym.vector.AsyncVectorEnv(fns, context="spawn")
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
    args = ap.parse_args()
    steps = 60 if args.quick else 400
    print(f"load before: {os.getloadavg()[0]:.2f}")
    print("| sdf_source | steps/s (wall) | steps/s (CPU) |\n|---|---|---|")
    rates = {}
    for src in ("gpis", "truth", "occupancy_edt"):
        w, c = single(src, steps)
        rates[src] = w
        print(f"| {src} | {w:.1f} | {c:.1f} |", flush=True)
    vr = vector_reactive("gpis", steps, 2)
    print(f"\nreactive actions, gpis: one process {rates['gpis']:.1f} steps/s; AsyncVectorEnv, 2 workers (spawn): "
          f"{vr:.1f} steps/s = {vr / rates['gpis']:.2f}x one process", flush=True)
    one = single_random("gpis", steps)
    v = vector("gpis", steps, 2)
    both = side_by_side("gpis", steps, 2)
    print(f"random actions (resets included), gpis: one process {one:.1f} steps/s; AsyncVectorEnv, 2 workers "
          f"(spawn): {v:.1f} steps/s = {v / one:.2f}x; two independent processes side by side: {both:.1f} "
          f"steps/s = {both / one:.2f}x (the machine's ceiling)")
    print(f"load after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
