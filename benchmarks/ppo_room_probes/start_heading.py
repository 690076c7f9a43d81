import numpy as np, gymnasium as gym, polar_sim.envs
env = gym.make("polar_sim/GPISNav-Room-v2", pose_source="truth", sdf_source="truth")
b = env.unwrapped.base
out = []
for s in range(1000, 1030):
    obs, info = env.reset(seed=s)
    p = info["robot_pose2d"]; w = b._world
    ahead = [w.sdf(np.array([[p[0] + d*np.cos(p[2]), p[1] + d*np.sin(p[2])]]))[0] - b._robot_radius for d in (0.1, 0.2, 0.3)]
    g = obs["goal"]; out.append((ahead[0], ahead[2], np.degrees(np.arctan2(g[1], g[0]))))
o = np.array(out); print("clearance 0.1 ahead: p10 %.2f med %.2f; 0.3 ahead: p10 %.2f med %.2f; <0 at 0.3: %d/30" % (np.percentile(o[:,0],10), np.median(o[:,0]), np.percentile(o[:,1],10), np.median(o[:,1]), (o[:,1]<0).sum()))
print("goal bearing deg:", np.round(o[:,2]).astype(int))
print("radius", b._robot_radius)
