"""Sample throughput of RLlib PPO on GPISNav-Room-v1 with 1 and 2 local env runners.

Usage: python benchmarks/bench_rllib_throughput.py [--iterations 4] [--batch 1024]

For each runner count: a local Ray with 3 CPUs (one for the driver/learner), ``rllib_config``
with ``pose_source="truth"``, ``--iterations`` training iterations of ``--batch`` env steps; the
first iteration (actor start-up, JIT) is dropped, and the throughput is the env steps sampled
divided by the wall seconds of the remaining ``algo.train()`` calls (sampling and the update;
RLlib samples synchronously in PPO, so this is what a user gets per wall second). The machine's
load average is printed beside each figure: on a shared machine the ratio between the two
counts, measured in one run, is the figure to read.
"""

import argparse
import json
import os
import time

import ray

from polar_sim.envs.rllib import rllib_config


def measure(n_runners, iterations, batch):
    ray.init(num_cpus=3, include_dashboard=False, log_to_driver=False)
    try:
        algo = rllib_config("polar_sim/GPISNav-Room-v1", num_env_runners=n_runners, train_batch_size=batch,
                            minibatch_size=min(256, batch), num_epochs=1).build_algo()
        algo.train()
        t, steps0 = time.perf_counter(), None
        for _ in range(iterations - 1):
            r = algo.train()
            steps0 = steps0 if steps0 is not None else r["env_runners"]["num_env_steps_sampled_lifetime"] - \
                r["env_runners"]["num_env_steps_sampled"]
        wall = time.perf_counter() - t
        steps = r["env_runners"]["num_env_steps_sampled_lifetime"] - steps0
        algo.stop()
    finally:
        ray.shutdown()
    return {"env_runners": n_runners, "env_steps": int(steps), "wall_s": wall, "steps_per_s": steps / wall,
            "load_average": os.getloadavg()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=4)
    ap.add_argument("--batch", type=int, default=1024)
    args = ap.parse_args()
    rows = [measure(n, args.iterations, args.batch) for n in (1, 2, 1, 2)]  # alternated, twice
    for r in rows:
        print(json.dumps(r), flush=True)
    by = {n: [r["steps_per_s"] for r in rows if r["env_runners"] == n] for n in (1, 2)}
    print(f"mean env steps/s: 1 runner {sum(by[1]) / 2:.1f}, 2 runners {sum(by[2]) / 2:.1f}, "
          f"ratio {sum(by[2]) / sum(by[1]):.2f}", flush=True)


if __name__ == "__main__":
    main()
