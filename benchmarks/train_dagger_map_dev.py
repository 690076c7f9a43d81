"""One map-memory DAgger run (``SDFNavigator`` expert) scored on dev worlds: how the ``dagger_map``
recipe's choices and the shipped multi-room policies were made.

Usage::

    python benchmarks/train_dagger_map_dev.py ENV_ID STEPS_PER_ROUND ROUNDS N_DEV ['{"env": {...}, "cfg": {...}}'] [TAG]

``train_dagger_map`` (``polar_sim.envs.imitation_map``) with ``MapDAggerConfig(rounds=ROUNDS,
steps_per_round=STEPS_PER_ROUND, **cfg)`` and the training env ``{"pose_source": "slam", **env}`` (train where
it is scored), one torch thread; prints each round's rollout statistics, saves the policy to
``polar_sim_out/dagger_map_dev/<id>_<TAG>.npz`` and scores it on N_DEV dev worlds (seeds 1000..) in the
default slam mode.
"""

import json
import sys
import time
from pathlib import Path

import torch

import polar_sim.envs  # noqa: F401
from polar_sim.envs.evaluate import evaluate
from polar_sim.envs.imitation_map import MapDAggerConfig, train_dagger_map


def main():
    torch.set_num_threads(1)
    env_id, steps, rounds, n_dev = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    extra = json.loads(sys.argv[5]) if len(sys.argv) > 5 else {}
    tag = sys.argv[6] if len(sys.argv) > 6 else "0"
    cfg = MapDAggerConfig(rounds=rounds, steps_per_round=steps, **extra.get("cfg", {}))
    env_kwargs = {"pose_source": "slam", **extra.get("env", {})}
    out = Path("polar_sim_out/dagger_map_dev")
    out.mkdir(parents=True, exist_ok=True)

    def each_round(k, policy, row):
        print("round", row, flush=True)
        policy.save(out / f"{env_id.split('/')[1]}_{tag}_r{k}.npz")

    policy, _ = train_dagger_map(env_id, config=cfg, env_kwargs=env_kwargs, progress=False, callback=each_round)
    policy.save(out / f"{env_id.split('/')[1]}_{tag}.npz")
    t, c = time.perf_counter(), time.process_time()
    _, s = evaluate(env_id, policy, episodes=n_dev, seed=1000, env_kwargs=policy.env_kwargs, progress=False)
    print("DEV slam", {k: s[k] for k in ("success_rate", "mean_collision", "mean_length")},
          "wall", time.perf_counter() - t, "cpu", time.process_time() - c, flush=True)


if __name__ == "__main__":
    main()
