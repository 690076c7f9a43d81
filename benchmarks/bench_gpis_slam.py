"""The GPIS share of a GPISNav slam step, replayed: map updates, ICP-G and stencil queries.

The default mode of ``GPISNav-Room-v1`` (``pose_source="slam"``) spends most of each step in
``GPISMap2D.update``, in ICP-G (``localize``, whose cost is GPIS queries) and in the stencil
query. This script records those calls from real episodes once, then replays them through the
map and ICP-G alone, so that two versions of the GPIS code can be timed on exactly the same
work, interleaved in one run:

    python benchmarks/bench_gpis_slam.py record --out /tmp/slam.npz          # dev seeds 0-4
    python benchmarks/bench_gpis_slam.py replay /tmp/slam.npz                # one timing, JSON
    python benchmarks/bench_gpis_slam.py compare /tmp/slam.npz --old DIR     # DIR: a checkout

``compare`` loads the old code (the package ``polar_sim`` of checkout DIR, copied under the name
``polar_sim_old``) beside this checkout's in one process and replays every episode through both,
alternating which goes first, ``--rounds`` times after an untimed warm-up round (numba's
caches). It reports the CPU time (``time.process_time``) per step of each part (median over
rounds), the ratio old / new, and the largest difference of any answer (ICP-G poses, query
distances and variances). Replays use the recorded sensor poses for the map updates, so both
versions' maps see the same scans at the same poses. Alternating within one process keeps both
under the same machine load, which on a shared machine swings by 2-3x within minutes.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


# -- recording ----------------------------------------------------------------------------------
def record(out, seeds, env_id="polar_sim/GPISNav-Room-v1", max_steps=300):
    """Run ``SDFReactive`` episodes in the default slam mode and save every GPIS call."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import gymnasium as gym

    import polar_sim.envs  # noqa: F401  (registers the ids)
    from polar_sim.envs.policies import SDFReactive

    events = []
    env = gym.make(env_id)
    u = env.unwrapped
    src, ps = u._source, u._pose_source
    upd, qry, loc = src.update, src.query, ps._localize

    def rec_update(angles, ranges, pose):
        events.append(("update", np.array(angles), np.array(ranges), np.array(pose, float)))
        return upd(angles, ranges, pose)

    inside = []                                  # queries made by ICP-G are its own work

    def rec_query(points):
        if not inside:
            events.append(("query", np.array(points, float)))
        return qry(points)

    def rec_localize(map, scan, pose, **kw):
        events.append(("localize", np.array(scan[0]), np.array(scan[1]), np.array(pose, float),
                       json.dumps({k: list(v) if isinstance(v, tuple) else v for k, v in kw.items()})))
        inside.append(1)
        try:
            return loc(map, scan, pose, **kw)
        finally:
            inside.pop()

    src.update, src.query, ps._localize = rec_update, rec_query, rec_localize
    pol = SDFReactive()
    steps = 0
    for s in seeds:
        events.append(("reset",))
        obs, _ = env.reset(seed=int(s))
        pol.reset()
        for _ in range(max_steps):
            obs, r, te, tr, _ = env.step(pol(obs))
            steps += 1
            if te or tr:
                break
    env.close()
    arrays = {}
    kinds = []
    for i, e in enumerate(events):
        kinds.append(e[0])
        for j, a in enumerate(e[1:]):
            arrays[f"e{i}_{j}"] = np.frombuffer(a.encode(), np.uint8) if isinstance(a, str) else a
    np.savez_compressed(out, kinds=np.array(kinds), steps=steps, seeds=np.asarray(seeds), **arrays)
    print(f"recorded {steps} steps, {len(events)} calls ({env_id}, seeds {list(seeds)}) -> {out}")


def load_events(path):
    z = np.load(path)
    ev = []
    for i, k in enumerate(z["kinds"]):
        k = str(k)
        n = {"reset": 0, "update": 3, "query": 1, "localize": 4}[k]
        args = [z[f"e{i}_{j}"] for j in range(n)]
        if k == "localize":
            args[3] = json.loads(args[3].tobytes().decode())
        ev.append((k, args))
    return ev, int(z["steps"])


# -- replay -------------------------------------------------------------------------------------
class _Source:
    """The env's GPIS source: before any data, distance 0, no gradient, infinite variance."""

    def __init__(self, map):
        self.map = map

    def query(self, points):
        if getattr(self.map, "n_updates_", 0) == 0:
            n = len(points)
            return np.zeros(n), np.zeros((n, 2)), np.full(n, np.inf)
        return self.map.query(points)

    def _register_native(self, *args):
        """ICP-G in the map's compiled loop, where it has one (as the env's source does)."""
        native = getattr(self.map, "_register_native", None)
        return native(*args) if native is not None else None


def replay(path, passes=2):
    """Replay the recording ``passes`` times in this process; the last pass's CPU seconds per
    part, and the answers (ICP-G poses and statuses, query values) for comparison."""
    from polar_sim.gpis import GPISMap2D
    from polar_sim.gpis.localize import localize

    events, steps = load_events(path)
    for _ in range(passes):
        cpu = {"update": 0.0, "localize": 0.0, "query": 0.0}
        poses, status, qd, qv = [], [], [], []
        src = None
        for kind, a in events:
            if kind == "reset":
                src = _Source(GPISMap2D(sensor_offset=(0.0, 0.0)))
                continue
            c0 = time.process_time()
            if kind == "update":
                src.map.update(*a)
            elif kind == "query":
                d, g, v = src.query(a[0])
            else:
                kw = {k: tuple(v) if isinstance(v, list) else v for k, v in a[3].items()}
                pose, _, info = localize(src, (a[0], a[1]), a[2], **kw)
            cpu[kind] += time.process_time() - c0
            if kind == "query":
                qd.append(d)
                qv.append(np.minimum(v, 1e6))
            elif kind == "localize":
                poses.append(pose)
                status.append(info["status"])
    return cpu, steps, {"poses": np.array(poses), "status": np.array(status),
                        "qd": np.concatenate(qd), "qv": np.concatenate(qv)}


def _renamed_copy(old, dest):
    """A copy of the package ``polar_sim`` of checkout ``old`` as ``polar_sim_old`` (imports
    rewritten), so that both versions load in one process."""
    import re
    import shutil

    src = Path(old).resolve() / "polar_sim"
    dst = Path(dest) / "polar_sim_old"
    shutil.copytree(src, dst, symlinks=False,
                    ignore=shutil.ignore_patterns("__pycache__", "experiments", "scenes"))
    for f in dst.rglob("*.py"):
        f.write_text(re.sub(r"\bpolar_sim(?=[.\s])", "polar_sim_old", f.read_text()))
    return dst


def _episodes(events):
    """The recording split at its resets: one list of events per episode."""
    eps = []
    for kind, a in events:
        if kind == "reset":
            eps.append([])
        else:
            eps[-1].append((kind, a))
    return eps


def _replay_episode(pkg, episode, cpu, answers):
    """Replay one episode through ``pkg``'s GPISMap2D and localize, adding CPU seconds per part."""
    src = _Source(pkg.GPISMap2D(sensor_offset=(0.0, 0.0)))
    for kind, a in episode:
        c0 = time.process_time()
        if kind == "update":
            src.map.update(*a)
        elif kind == "query":
            d, g, v = src.query(a[0])
        else:
            kw = {k: tuple(v) if isinstance(v, list) else v for k, v in a[3].items()}
            pose, _, info = pkg.localize(src, (a[0], a[1]), a[2], **kw)
        cpu[kind] += time.process_time() - c0
        if kind == "query":
            answers.append(d)
            answers.append(np.minimum(v, 1e6))
        elif kind == "localize":
            answers.append(pose)


def compare(path, old, rounds):
    """Alternate the old and the new code episode by episode in one process; print the CPU time
    per step of each part (medians over rounds), the ratio, and the largest answer difference."""
    import importlib
    import tempfile
    from types import SimpleNamespace

    tmp = tempfile.mkdtemp()
    _renamed_copy(old, tmp)
    sys.path.insert(0, tmp)
    pk = {}
    for name, root in (("old", "polar_sim_old"), ("new", "polar_sim")):
        gp = importlib.import_module(f"{root}.gpis")
        loc = importlib.import_module(f"{root}.gpis.localize")
        pk[name] = SimpleNamespace(GPISMap2D=gp.GPISMap2D, localize=loc.localize)
    events, steps = load_events(path)
    eps = _episodes(events)
    res = {n: [] for n in pk}
    ans = {n: [] for n in pk}
    for r in range(rounds + 1):                       # round 0 warms up (numba caches)
        cpu = {n: {"update": 0.0, "localize": 0.0, "query": 0.0} for n in pk}
        for e, ep in enumerate(eps):
            for name in (("old", "new") if (r + e) % 2 == 0 else ("new", "old")):
                out = []
                _replay_episode(pk[name], ep, cpu[name], out)
                if r == 1:
                    ans[name].extend(out)
        if r:
            for n in pk:
                res[n].append(cpu[n])
    print(f"{steps} steps, {rounds} rounds, old and new alternating by episode in one process, "
          f"load average {os.getloadavg()[0]:.2f}")
    for name in res:
        print(f"{name} total ms/step per round:",
              " ".join(f"{1e3 * sum(x.values()) / steps:.2f}" for x in res[name]))
    print("| part | old ms/step | new ms/step | old / new |")
    print("|---|---|---|---|")
    for part in ("update", "localize", "query", "total"):
        med = {}
        for name in res:
            v = [sum(x.values()) if part == "total" else x[part] for x in res[name]]
            med[name] = 1e3 * float(np.median(v)) / steps
        print(f"| {part} | {med['old']:.3f} | {med['new']:.3f} | {med['old'] / med['new']:.2f} |")
    diffs = np.array([float(np.max(np.abs(a - b))) if a.size else 0.0
                      for a, b in zip(ans["old"], ans["new"])])
    print(f"largest difference of any answer (ICP-G pose, SDF, variance): {diffs.max():.3g}; "
          f"answers differing by more than 1e-9: {int((diffs > 1e-9).sum())} of {len(diffs)}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("--out", required=True)
    r.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    p = sub.add_parser("replay")
    p.add_argument("path")
    c = sub.add_parser("compare")
    c.add_argument("path")
    c.add_argument("--old", required=True, help="a checkout of the code to compare against")
    c.add_argument("--rounds", type=int, default=5)
    a = ap.parse_args()
    if a.cmd == "record":
        record(a.out, a.seeds)
    elif a.cmd == "replay":
        cpu, steps, _ = replay(a.path)
        print(json.dumps({"cpu_ms_per_step": {k: 1e3 * v / steps for k, v in cpu.items()},
                          "steps": steps}))
    else:
        compare(a.path, a.old, a.rounds)


if __name__ == "__main__":
    main()
