"""GroundVO-v0 and ObjectTrack-v0: throughput against the renderer, and the scripted baselines.

Usage: python benchmarks/bench_envs_ground_track.py [--quick] [--write benchmarks/results/envs_ground_track.md]
       python benchmarks/bench_envs_ground_track.py --pictures   (docs/img/env_groundvo.png, env_objecttrack.png)

Throughput: steps/s (wall) and CPU ms per step (process time, all threads, so the figure an idle
core would give) of one environment in one process, with the part each stage takes (physics,
render, module) measured separately on the same states. The load average is recorded beside
every figure: the 2-core machine is shared. Baselines: ``PurePursuitVO`` drives whole routes on
``GroundVO-v0`` (final drift against the route length) and ``VisualServoReach`` reaches on
``ObjectTrack-v0`` (success, steps, tracking error).
"""

import argparse
import os
import platform
import sys
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import polar_sim.envs  # noqa: E402, F401  (registers the ids)
from polar_sim.envs.policies import PurePursuitVO, VisualServoReach  # noqa: E402


def load():
    return "/".join(f"{v:.1f}" for v in os.getloadavg())


class Timer:
    """Wall and process (CPU) time of a block."""

    def __enter__(self):
        self.w, self.c = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall, self.cpu = time.perf_counter() - self.w, time.process_time() - self.c


def instrument(obj, name, acc):
    """Replace ``obj.name`` by a version that adds its wall and CPU time to ``acc[name]``."""
    fn = getattr(obj, name)
    acc[name] = [0.0, 0.0, 0]

    def timed(*a, **k):
        with Timer() as t:
            r = fn(*a, **k)
        acc[name][0] += t.wall
        acc[name][1] += t.cpu
        acc[name][2] += 1
        return r
    setattr(obj, name, timed)


class _World:
    """Proxy of a World whose ``step`` is timed (the env calls ``self._world.step``)."""

    def __init__(self, world, acc):
        self._w = world
        self._acc = acc
        acc.setdefault("physics", [0.0, 0.0, 0])

    def step(self, *a):
        with Timer() as t:
            self._w.step(*a)
        self._acc["physics"][0] += t.wall
        self._acc["physics"][1] += t.cpu
        self._acc["physics"][2] += 1

    def __getattr__(self, k):
        return getattr(self._w, k)


def throughput(make, policy, n, seed, stages):
    """Steps/s and CPU per step of ``make()`` over ``n`` steps, and the per-stage times of the
    instrumented methods ``stages`` = {label: (attribute path on the unwrapped env, method)}."""
    env = make()
    obs, _ = env.reset(seed=seed)
    policy.reset()
    u = env.unwrapped
    acc = {}
    u._world = _World(u._world, acc)
    for label, (path, meth) in stages.items():
        instrument(getattr(u, path) if path else u, meth, acc)
    wall = cpu = 0.0
    la = load()
    for _ in range(n):
        a = policy(obs)
        with Timer() as t:
            obs, _, term, trunc, _ = env.step(a)
        wall, cpu = wall + t.wall, cpu + t.cpu
        if term or trunc:
            break
    steps = acc["physics"][2]
    env.close()
    per = {"physics": acc["physics"]}
    per.update({label: acc[meth] for label, (_, meth) in stages.items()})
    return steps, wall, cpu, la, {k: (v[0] / max(v[2], 1), v[1] / max(v[2], 1)) for k, v in per.items()}


class _Const:
    def __init__(self, a):
        self.a = np.asarray(a, np.float32)

    def reset(self):
        pass

    def __call__(self, obs):
        return self.a


def groundvo_throughput(n, rows):
    lines = []
    first = None
    for label, kw in (("GroundVO-v0 (default, no image obs)", {}), ("GroundVO-v0, image_obs=True", {"image_obs": True}),
                      ("GroundVO-v0, supersample=False", {"supersample": False}), ("RoverDrive-v0 (raw)", None)):
        if kw is None:
            make, pol, stages = (lambda: gym.make("polar_sim/RoverDrive-v0")), _Const([0.6, 0.0]), \
                {"render RGB": ("", "_render_camera")}
        else:
            make, pol = (lambda kw=kw: gym.make("polar_sim/GroundVO-v0", **kw)), PurePursuitVO()
            stages = {"render RGB": ("", "_render_camera"), "VO + observation": ("_odometry", "update")}
        steps, wall, cpu, la, per = throughput(make, pol, n, 0, stages)
        rows.append((label, f"{steps / wall:.1f}", f"{1000 * cpu / steps:.1f}", f"{steps / cpu:.0f}", la))
        lines.append(f"| {label} | " + "; ".join(f"{k} {1000 * w:.1f} / {1000 * c:.1f}" for k, (w, c) in per.items())
                     + f" | {la} |")
        if first is None:
            first = per
    return lines, first


def objecttrack_throughput(n, rows):
    lines = []
    for label, kw in (("ObjectTrack-v0 (default, 320x240, depth noise)", {}),
                      ("ObjectTrack-v0, image_obs=True", {"image_obs": True}),
                      ("ObjectTrack-v0, depth_noise=False", {"depth_noise": False}),
                      ("ObjectTrack-v0, camera_size=(640, 480)", {"camera_size": (640, 480)}),
                      ("TabletopReach-v0 (raw)", None)):
        if kw is None:
            make, pol, stages = (lambda: gym.make("polar_sim/TabletopReach-v0")), _Const([-0.3, -0.3, -0.2, 0.0]), \
                {"camera": ("", "_frame")}
        else:
            make, pol = (lambda kw=kw: gym.make("polar_sim/ObjectTrack-v0", **kw)), VisualServoReach()
            stages = {"camera": ("", "_frame"), "tracker + observation": ("_tracking", "update")}
        steps, wall, cpu, la, per = throughput(make, pol, n, 0, stages)
        rows.append((label, f"{steps / wall:.1f}", f"{1000 * cpu / steps:.1f}", f"{steps / cpu:.0f}", la))
        lines.append(f"| {label} | " + "; ".join(f"{k} {1000 * w:.1f} / {1000 * c:.1f}" for k, (w, c) in per.items())
                     + f" | {la} |")
    return lines


def groundvo_baseline(seeds, route_length, kw):
    env = gym.make("polar_sim/GroundVO-v0", route_length=route_length, **kw)
    pol = PurePursuitVO()
    out = []
    for s in seeds:
        obs, info = env.reset(seed=s)
        pol.reset()
        n, max_cte, max_drift = 0, 0.0, 0.0
        while True:
            obs, r, term, trunc, info = env.step(pol(obs))
            n += 1
            max_cte, max_drift = max(max_cte, info["cross_track_error"]), max(max_drift, info["drift"])
            if term or trunc:
                break
        end = "end" if info["is_success"] else ("collision" if info["collision"] else ("off route" if term else "time"))
        out.append(dict(seed=s, steps=n, end=end, drift=info["drift"], drift_pct=100 * info["drift"] / route_length,
                        progress=info["progress"], heading=np.degrees(info["heading_error"]), max_cte=max_cte,
                        max_drift=max_drift, success=info["is_success"]))
        print(f"  GroundVO {kw} seed {s}: {end} after {n} steps, final drift {info['drift']:.2f} m "
              f"({out[-1]['drift_pct']:.2f} % of {route_length:.0f} m), max cte {max_cte:.2f} m",
              file=sys.stderr, flush=True)
    env.close()
    return out


def objecttrack_baseline(seeds):
    env = gym.make("polar_sim/ObjectTrack-v0")
    pol = VisualServoReach()
    out = []
    for s in seeds:
        obs, info = env.reset(seed=s)
        pol.reset()
        n, errs, lost = 0, [], 0
        while True:
            obs, r, term, trunc, info = env.step(pol(obs))
            n += 1
            errs.append(info["tracking_error"])
            lost += info["tracker_lost"]
            if term or trunc:
                break
        out.append(dict(seed=s, target=info["target"], steps=n, success=info["is_success"],
                        final_error=info["position_error"], mean_track=float(np.mean(errs)),
                        max_track=float(np.max(errs)), lost=lost))
        print(f"  ObjectTrack seed {s} ({info['target']}): success={info['is_success']} after {n} steps, "
              f"tracking error mean {1000 * np.mean(errs):.1f} mm max {1000 * np.max(errs):.1f} mm", file=sys.stderr,
              flush=True)
    env.close()
    return out


def pictures(vo_steps=220, track_steps=62):
    """The README pictures: docs/img/env_groundvo.png and docs/img/env_objecttrack.png."""
    import cv2

    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "docs", "img")
    for env_id, pol, steps, name in (
            ("polar_sim/GroundVO-v0", PurePursuitVO(), vo_steps, "env_groundvo.png"),
            ("polar_sim/ObjectTrack-v0", VisualServoReach(), track_steps, "env_objecttrack.png")):
        env = gym.make(env_id, render_mode="rgb_array")
        obs, _ = env.reset(seed=0)
        pol.reset()
        for _ in range(steps):
            obs, *_ = env.step(pol(obs))
        frame = env.render()
        env.close()
        path = os.path.normpath(os.path.join(root, name))
        cv2.imwrite(path, frame[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9])
        print(f"wrote {path} {frame.shape}", file=sys.stderr)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="CI size: fewer steps and episodes")
    ap.add_argument("--steps", type=int, default=None, help="timed steps per throughput row")
    ap.add_argument("--vo-episodes", type=int, default=None)
    ap.add_argument("--track-episodes", type=int, default=None)
    ap.add_argument("--route-length", type=float, default=300.0)
    ap.add_argument("--write", default=None, help="write the markdown report here")
    ap.add_argument("--pictures", action="store_true", help="only write the README pictures (docs/img/env_*.png)")
    args = ap.parse_args()
    if args.pictures:
        pictures()
        return
    n = args.steps or (40 if args.quick else 300)
    n_vo = args.vo_episodes if args.vo_episodes is not None else (1 if args.quick else 12)
    n_tr = args.track_episodes if args.track_episodes is not None else (2 if args.quick else 20)
    cmd = "python " + " ".join(sys.argv)
    out = ["# GroundVO-v0 and ObjectTrack-v0: throughput and scripted baselines", "",
           f"Command: `{cmd}`  ",
           f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores shared with other jobs; "
           f"Python {platform.python_version()}; MUJOCO_GL={os.environ.get('MUJOCO_GL')}; default thread settings.  ",
           f"Load average (1/5/15 min) at the start: {load()}.", ""]
    print("throughput ...", file=sys.stderr, flush=True)
    rows = []
    vo_lines, per = groundvo_throughput(n, rows)
    tr_lines = objecttrack_throughput(n, rows)
    out += ["## Throughput (one environment, one process)", "",
            f"Up to {n} timed steps per row from seed 0 (the scripted baseline acting; the reset is not timed; an "
            "ObjectTrack episode ends at success, so those rows have fewer steps). CPU ms is the process time of "
            "all its threads per step; steps/s on CPU = 1000 / CPU ms, about what an idle core would give.", "",
            "| environment | steps/s (wall) | CPU ms/step | steps/s on CPU | load 1/5/15 |", "|---|---|---|---|---|"]
    out += [f"| {' | '.join(r)} |" for r in rows]
    out += ["", "Stages, measured inside the same runs (mean ms per step, wall / CPU):", "",
            "| environment | stages | load |", "|---|---|---|"]
    out += vo_lines + tr_lines
    rw, rc = per["render RGB"]
    pw, pc = per["physics"]
    out += ["", f"GroundVO-v0 against the renderer: the camera render alone would run at {1 / rc:.0f} frames/s on "
            f"CPU ({1 / rw:.0f} wall at this load); render + physics at {1 / (rc + pc):.0f}/s on CPU; the full step "
            f"(+ VO) at {float(rows[0][3]):.0f}/s on CPU = {100 * float(rows[0][3]) * rc:.0f} % of the render "
            "rate.", ""]
    print("baselines ...", file=sys.stderr, flush=True)
    vo_sets = [("default", {})] + ([] if args.quick else [("supersample=False", {"supersample": False})])
    results = []
    for label, kw in vo_sets:
        la0 = load()
        results.append((label, la0, groundvo_baseline(range(n_vo), args.route_length, kw)))
    tr = objecttrack_baseline(range(n_tr))
    for label, la0, vo in results:
        if vo:
            out += [f"## PurePursuitVO on GroundVO-v0, {label} ({n_vo} seeds, {args.route_length:.0f} m routes; "
                    f"load {la0})", "",
                    "Final drift = distance between the estimated and the true position when the episode ends, "
                    "as % of the route length (target: within 3 %).", "",
                    "| seed | end | steps | true progress (m) | final drift (m) | final drift (% of route) "
                    "| heading error (deg) | max drift (m) | max cross-track (m) |",
                    "|---|---|---|---|---|---|---|---|---|"]
            for r in vo:
                out.append(f"| {r['seed']} | {r['end']} | {r['steps']} | {r['progress']:.0f} | {r['drift']:.2f} "
                           f"| {r['drift_pct']:.2f} | {r['heading']:+.2f} | {r['max_drift']:.2f} "
                           f"| {r['max_cte']:.2f} |")
            d = np.array([r["drift_pct"] for r in vo])
            ok = [r for r in vo if r["success"]]
            line = (f"Reached the end: {len(ok)}/{len(vo)}. Final drift: mean {d.mean():.2f} %, max {d.max():.2f} %, "
                    f"{int((d <= 3).sum())}/{len(vo)} within 3 % of the route length")
            if ok:
                good = [r["drift_pct"] for r in ok]
                line += (f"; over the episodes that reached the end: mean {np.mean(good):.2f} %, "
                         f"max {np.max(good):.2f} %")
            out += ["", line + ".", ""]
    if tr:
        out += [f"## VisualServoReach on ObjectTrack-v0 ({n_tr} seeds)", "",
                "| seed | object | success | steps | final position error (mm) | tracking error mean (mm) "
                "| max (mm) | lost frames |",
                "|---|---|---|---|---|---|---|---|"]
        for r in tr:
            out.append(f"| {r['seed']} | {r['target']} | {r['success']} | {r['steps']} "
                       f"| {1000 * r['final_error']:.1f} | {1000 * r['mean_track']:.2f} | {1000 * r['max_track']:.2f} "
                       f"| {r['lost']} |")
        ok = [r for r in tr if r["success"]]
        line = f"Success {len(ok)}/{len(tr)}"
        if ok:
            med = float(np.median([r["steps"] for r in ok]))
            line += f"; median steps to success {med:.0f} ({med / 30:.1f} s)"
        out += ["", line + ".", ""]
    out += [f"Load average at the end: {load()}."]
    text = "\n".join(out) + "\n"
    print(text)
    if args.write:
        with open(args.write, "w") as f:
            f.write(text)


if __name__ == "__main__":
    main()
