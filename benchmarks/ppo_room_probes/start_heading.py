import numpy as np
import gymnasium as gym

import polar_sim.envs  # noqa: F401  (registers the environment ids)

env = gym.make("polar_sim/GPISNav-Room-v2", pose_source="truth", sdf_source="truth")
b = env.unwrapped.base
out = []
for s in range(1000, 1030):
    obs, info = env.reset(seed=s)
    p = info["robot_pose2d"]
    w = b._world
    ahead = [
        w.sdf(np.array([[p[0] + d * np.cos(p[2]), p[1] + d * np.sin(p[2])]]))[0] - b._robot_radius
        for d in (0.1, 0.2, 0.3)
    ]
    g = obs["goal"]
    out.append((ahead[0], ahead[2], np.degrees(np.arctan2(g[1], g[0]))))
o = np.array(out)
c1, c3 = o[:, 0], o[:, 1]
print(
    f"clearance 0.1 ahead: p10 {np.percentile(c1, 10):.2f} med {np.median(c1):.2f}; "
    f"0.3 ahead: p10 {np.percentile(c3, 10):.2f} med {np.median(c3):.2f}; <0 at 0.3: {(c3 < 0).sum()}/30"
)
print("goal bearing deg:", np.round(o[:, 2]).astype(int))
print("radius", b._robot_radius)
