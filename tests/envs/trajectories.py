"""Reference trajectories of the navigation environments: record them, and replay them.

Each case runs one environment through a few seeded episodes of a fixed action sequence and keeps
everything an agent or a scorer reads: the observation, the reward, ``terminated``/``truncated``
and every value of ``info`` (the truth). ``data/nav_trajectories.npz`` holds the cases recorded
with the code before the throughput work of issue 32 (main 969d506); ``test_trajectories.py``
replays the stored actions against today's code and asserts that nothing changed. The three cases
that run GPIS (room_slam, rooms3_truthpose_gpis, v0) were replayed once more, with the same actions,
after the GPIS speed work (branch ``gpis``, issue 35), which changed their info/observation values
at round-off (at most 1.2e-10 m, 9e-13, and 4.4e-5 / 6.6e-6 in v0; benchmarks/RESULTS.md).

The recorded actions come from ``SDFReactive`` on the observation plus seeded noise (the stencil
observation) or from seeded forward-biased random actions (LidarNav, the grid observation), so the episodes drive around clutter for a
few hundred steps; the replay uses the stored actions, never the policy.

Regenerate (only when an episode is meant to change, with a new env version):
``python tests/envs/trajectories.py`` (writes ``data/nav_trajectories.npz``).
"""

from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import polar_sim.envs  # noqa: E402,F401  (registers the ids)

DATA = Path(__file__).parent / "data" / "nav_trajectories.npz"

#: name -> (env id, gym.make kwargs, [(episode seed, max steps), ...]); the episodes of a case
#: run one after another in one environment instance (so a reset after an episode is covered).
CASES = {
    "room_truth_truth": ("polar_sim/GPISNav-Room-v1", {"pose_source": "truth", "sdf_source": "truth"},
                         [(0, 200), (1, 150), (10, 150)]),
    "room_slam": ("polar_sim/GPISNav-Room-v1", {}, [(2, 120)]),
    "rooms2_truth_truth": ("polar_sim/GPISNav-Rooms2-v1", {"pose_source": "truth", "sdf_source": "truth"},
                           [(9, 120)]),
    "rooms2_odometry_grid": ("polar_sim/GPISNav-Rooms2-v1", {"pose_source": "odometry", "obs_mode": "grid",
                                                             "grid_visited": True}, [(3, 40)]),
    "rooms3_truthpose_gpis": ("polar_sim/GPISNav-v1", {"pose_source": "truth"}, [(4, 100)]),
    "rooms3_truth_truth": ("polar_sim/GPISNav-v1", {"pose_source": "truth", "sdf_source": "truth"}, [(5, 150)]),
    "v0": ("polar_sim/GPISNav-v0", {}, [(6, 100)]),
    "lidar_v1": ("polar_sim/LidarNav-v1", {"tier": "room"}, [(7, 100)]),
    "lidar_v0": ("polar_sim/LidarNav-v0", {}, [(8, 60)]),
}


def flatten_info(info):
    """(numeric values (k,) float64, their keys, string values joined by '|') of an info dict,
    keys sorted, nested dicts (``reward_terms``) flattened as ``outer.inner``."""
    keys, vals, strs = [], [], []

    def walk(prefix, d):
        for k in sorted(d):
            v = d[k]
            name = f"{prefix}{k}"
            if isinstance(v, dict):
                walk(name + ".", v)
            elif isinstance(v, str):
                strs.append(f"{name}={v}")
            else:
                a = np.asarray(v, dtype=np.float64).ravel()
                keys.append(f"{name}:{a.size}")
                vals.append(a)

    walk("", info)
    return np.concatenate(vals) if vals else np.zeros(0), "|".join(keys), "|".join(strs)


def flatten_obs(obs):
    """(values float32, keys) of an observation dict, keys sorted."""
    keys = sorted(obs)
    return np.concatenate([np.asarray(obs[k], np.float32).ravel() for k in keys]), "|".join(
        f"{k}:{np.asarray(obs[k]).size}" for k in keys)


class _Recorder:
    def __init__(self):
        self.obs, self.info, self.rtt, self.strs, self.obs_keys, self.info_keys = [], [], [], [], [], []

    def add(self, obs, info, reward=np.nan, terminated=False, truncated=False):
        o, ok = flatten_obs(obs)
        i, ik, s = flatten_info(info)
        self.obs.append(o)
        self.info.append(i)
        self.rtt.append([reward, float(terminated), float(truncated)])
        self.obs_keys.append(ok)
        self.info_keys.append(ik)
        self.strs.append(s)

    def arrays(self, name):
        pad = max(len(i) for i in self.info)  # the reset row lacks reward_terms
        info = np.full((len(self.info), pad), np.nan)
        for r, i in enumerate(self.info):
            info[r, : len(i)] = i
        out = {f"{name}/obs": np.stack(self.obs), f"{name}/info": info, f"{name}/rtt": np.array(self.rtt),
               f"{name}/strings": np.array(self.strs)}
        for what, keys in (("obs_keys", self.obs_keys), ("info_keys", self.info_keys)):
            uniq, index = np.unique(np.array(keys), return_inverse=True)
            out[f"{name}/{what}"], out[f"{name}/{what}_index"] = uniq, index
        return out


def _actions(obs, policy, rng):
    """The recording's action: ``SDFReactive`` on the stencil; on ranges or the grid image, steer to
    the more open side and slow before what is ahead; plus seeded noise."""
    if "sdf" in obs:
        a = policy(obs)
    else:
        if "ranges" in obs:  # 270 deg, beam 0 at -135 deg (right), counter-clockwise
            r = np.asarray(obs["ranges"], float)
            n = len(r)
            ahead = r[int(0.43 * n): int(0.57 * n)].min()
            left, right = r[int(0.57 * n): int(0.83 * n)].mean(), r[int(0.17 * n): int(0.43 * n)].mean()
            ahead -= 0.3
        else:  # the grid image: row 0 ahead, column 0 to the left, the robot at the centre
            d = np.asarray(obs["sdf_grid"][0], float)
            c = d.shape[0] // 2
            ahead = d[c - 4 : c, c - 2 : c + 2].min()
            left, right = d[: c, : c].mean(), d[: c, c:].mean()
        a = np.array([0.7 * np.clip((ahead - 0.3) / 0.7, 0.0, 1.0), np.clip(left - right, -1.0, 1.0)])
    return np.clip(a + rng.normal(0.0, 0.15, 2), -1.0, 1.0).astype(np.float32)


def run_case(name, actions=None):
    """Run case ``name``: with ``actions`` None, generate and return them with the recording;
    otherwise replay them. Returns ({array name: array}, actions (T, 2) float32, episode
    lengths)."""
    from polar_sim.envs.policies import SDFReactive

    env_id, kwargs, episodes = CASES[name]
    env = gym.make(env_id, **kwargs)
    rec = _Recorder()
    out_actions, lengths, t = [], [], 0
    try:
        for seed, n in episodes:
            rng = np.random.default_rng(1000 + seed)
            policy = SDFReactive()
            obs, info = env.reset(seed=seed)
            rec.add(obs, info)
            k = 0
            for k in range(n):
                if actions is None:
                    a = _actions(obs, policy, rng)
                else:
                    if t >= len(actions):
                        break
                    a = actions[t]
                out_actions.append(a)
                t += 1
                obs, reward, term, trunc, info = env.step(a)
                rec.add(obs, info, reward, term, trunc)
                if term or trunc:
                    break
            lengths.append(k + 1)
    finally:
        env.close()
    return rec.arrays(name), np.array(out_actions, np.float32).reshape(-1, 2), lengths


def record(path=DATA):
    """Record every case to ``path`` (.npz, compressed, no pickle)."""
    out = {}
    for name in CASES:
        arrays, actions, lengths = run_case(name)
        out.update(arrays)
        out[f"{name}/actions"] = actions
        out[f"{name}/lengths"] = np.array(lengths)
        print(f"{name}: episodes of {lengths} steps")
    import subprocess

    commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__file__).parent).stdout.strip()
    out["format_version"] = np.array(1)
    out["commit"] = np.array(commit)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **out)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB) at {commit}")


if __name__ == "__main__":
    record()
