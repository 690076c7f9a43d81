import numpy as np
import gymnasium as gym

import polar_sim.envs  # noqa: F401  (registers the environment ids)
from polar_sim.envs.evaluate import load_policy
from polar_sim.envs.far_mask import feature_vector

env = gym.make("polar_sim/GPISNav-Room-v2", pose_source="truth", sdf_source="truth")
pol = load_policy("polar_sim_out/ppo2_dev/base/seed0/policy.npz", env)
nm = pol.normaliser
f = pol.features
big, norms, rawmax = [], [], []


class Straight:
    def __call__(self, obs):
        g = obs["goal"]
        ang = np.arctan2(g[1], g[0])
        return np.array([1.0 if abs(ang) < 0.5 else 0.2, np.clip(2 * ang, -1, 1)], np.float32)


for s in range(1000, 1010):
    obs, _ = env.reset(seed=s)
    for t in range(60):
        x = feature_vector(obs, **f)
        z = nm(x)
        big.append((np.abs(z) > 3).mean())
        norms.append(np.linalg.norm(z))
        rawmax.append(np.abs(x).max())
        obs, r, te, tr, _ = env.step(Straight()(obs))
        if te or tr:
            break
print(
    f"frac |z|>3: {np.mean(big):.3f}  ||z|| mean {np.mean(norms):.1f} (sqrt(260)=16.1)  raw |x| max mean {np.mean(rawmax):.1f}"
)
sd = np.sqrt(nm.var[""])
print(f"std min {sd.min():.4f}, #std<0.1: {(sd < 0.1).sum()} of {len(sd)}; goal std", sd[:2], "twist std", sd[-2:])
