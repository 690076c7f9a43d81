"""One DAgger run scored on dev worlds: how the recipe's choices and the shipped policies were made.

Usage::

    python benchmarks/train_dagger_dev.py ENV_ID EXPERT STEPS_PER_ROUND ROUNDS N_DEV ['{"env": {...}, "cfg": {...}}'] [TAG]

``train_dagger`` (``polar_sim.envs.imitation``) of ``EXPERT`` on ``ENV_ID`` with ``DAggerConfig(rounds=ROUNDS,
steps_per_round=STEPS_PER_ROUND, **cfg)`` and the training env ``{"pose_source": "truth", **env}``, one torch
thread, seed 0 (training worlds 0-999); prints each round's rollout statistics, saves the policy to
``polar_sim_out/dagger_dev/<id>_<expert>_<TAG>.npz`` and scores it on N_DEV dev worlds (seeds 1000..) in the
default slam mode. The same run through the recipe is ``polar-sim train dagger --params '{"expert": EXPERT,
"rounds": ROUNDS, "steps_per_round": STEPS_PER_ROUND, "train_pose_source": ..., "env_kwargs": env, ...cfg}'``.
"""

import json
import sys
import time
from pathlib import Path

import torch

import polar_sim.envs  # noqa: F401
from polar_sim.envs.evaluate import evaluate
from polar_sim.envs.imitation import DAggerConfig, train_dagger


def main():
    torch.set_num_threads(1)
    env_id, expert, steps, rounds, n_dev = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
    extra = json.loads(sys.argv[6]) if len(sys.argv) > 6 else {}
    tag = sys.argv[7] if len(sys.argv) > 7 else "0"
    cfg = DAggerConfig(rounds=rounds, steps_per_round=steps, **extra.get("cfg", {}))
    env_kwargs = {"pose_source": "truth", **extra.get("env", {})}
    policy, _ = train_dagger(env_id, expert=expert, config=cfg, env_kwargs=env_kwargs, progress=False,
                             callback=lambda k, pol, row: print("round", row, flush=True))
    out = Path("polar_sim_out/dagger_dev")
    out.mkdir(parents=True, exist_ok=True)
    policy.save(out / f"{env_id.split('/')[1]}_{expert}_{tag}.npz")
    t = time.perf_counter()
    _, s = evaluate(env_id, policy, episodes=n_dev, seed=1000, env_kwargs=policy.env_kwargs, progress=False)
    print("DEV slam", {k: s[k] for k in ("success_rate", "mean_collision", "mean_length")},
          time.perf_counter() - t, flush=True)


if __name__ == "__main__":
    main()
