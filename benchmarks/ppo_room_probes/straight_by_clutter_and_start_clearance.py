import numpy as np
import gymnasium as gym

import polar_sim.envs  # noqa: F401  (registers the environment ids)


class Straight:
    def __call__(self, obs):
        g = obs["goal"]
        ang = np.arctan2(g[1], g[0])
        return np.array([1.0 if abs(ang) < 0.5 else 0.2, np.clip(2 * ang, -1, 1)], np.float32)


for clutter in (0, 3):
    env = gym.make("polar_sim/GPISNav-Room-v2", pose_source="truth", sdf_source="truth", clutter=clutter)
    res = []
    for s in range(1000, 1020):
        obs, info = env.reset(seed=s)
        n = 0
        while True:
            obs, r, te, tr, info = env.step(Straight()(obs))
            n += 1
            if te or tr:
                break
        res.append((info["is_success"], info["collision"], n))
    print("clutter", clutter, np.mean(res, 0))
env = gym.make("polar_sim/GPISNav-Room-v2", pose_source="truth", sdf_source="truth")
cl = []
for s in range(1000, 1050):
    obs, info = env.reset(seed=s)
    cl.append(env.unwrapped.base._world.sdf(info["robot_pose2d"][None, :2])[0] - env.unwrapped.base._robot_radius)
cl = np.array(cl)
print(
    f"start clearance m: min {cl.min():.2f} p10 {np.percentile(cl, 10):.2f} median {np.median(cl):.2f}; "
    f"<0.2: {(cl < 0.2).sum()}/50"
)
