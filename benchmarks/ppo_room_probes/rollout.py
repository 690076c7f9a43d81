import sys
import numpy as np
import gymnasium as gym

import polar_sim.envs  # noqa: F401  (registers the environment ids)
from polar_sim.envs.evaluate import load_policy

env = gym.make(
    "polar_sim/GPISNav-Room-v2",
    pose_source="truth",
    sdf_source="truth",
    clutter=int(sys.argv[2]) if len(sys.argv) > 2 else None,
)
pol = load_policy(sys.argv[1], env)
for s in range(1000, 1006):
    obs, info = env.reset(seed=s)
    pol.reset()
    acts = []
    n = 0
    while True:
        a = pol(obs)
        acts.append(a)
        obs, r, te, tr, info = env.step(a)
        n += 1
        if te or tr:
            break
    acts = np.array(acts)
    print(
        s,
        "succ",
        info["is_success"],
        "coll",
        info["collision"],
        "len",
        n,
        "geo left {:.2f}".format(info["geodesic_distance"]),
        f"v mean {acts[:, 0].mean():.2f} omega mean {acts[:, 1].mean():.2f} |omega| {np.abs(acts[:, 1]).mean():.2f}",
    )
