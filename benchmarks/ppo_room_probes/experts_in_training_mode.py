import numpy as np
import gymnasium as gym

import polar_sim.envs  # noqa: F401  (registers the environment ids)
from polar_sim.envs.policies import SDFReactive

env = gym.make("polar_sim/GPISNav-Room-v2", pose_source="truth", sdf_source="truth")


def run(pol, seeds):
    out = []
    for s in seeds:
        obs, info = env.reset(seed=s)
        pol.reset() if hasattr(pol, "reset") else None
        terms = {}
        R = 0
        n = 0
        d0 = info["geodesic_distance"]
        while True:
            a = pol(obs)
            obs, r, te, tr, info = env.step(a)
            R += r
            n += 1
            for k, v in info["reward_terms"].items():
                terms[k] = terms.get(k, 0) + v
            if te or tr:
                break
        out.append((info["is_success"], info["collision"], n, R, d0, {k: round(v, 2) for k, v in terms.items()}))
    return out


class Straight:
    def __call__(self, obs):
        g = obs["goal"]
        ang = np.arctan2(g[1], g[0])
        return np.array([1.0 if abs(ang) < 0.5 else 0.2, np.clip(2 * ang, -1, 1)], np.float32)


for name, pol in [("reactive", SDFReactive()), ("straight", Straight())]:
    res = run(pol, range(1000, 1020))
    print(
        name,
        "succ",
        np.mean([r[0] for r in res]),
        "coll",
        np.mean([r[1] for r in res]),
        "len",
        np.mean([r[2] for r in res]),
        "ret",
        np.mean([r[3] for r in res]),
    )
    for r in res[:5]:
        print("  ", r)
