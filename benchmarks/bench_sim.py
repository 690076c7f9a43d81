"""Simulator speed: lidar throughput against raw mj_multiRay, camera frame rates, physics steps/s.

Usage: python benchmarks/bench_sim.py [--quick]
Prints a markdown table; the figures recorded in benchmarks/RESULTS.md come from this script.
"""

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

from polar_sim.sim import World  # noqa: E402
from polar_sim.sim.sensors import bare_multiray  # noqa: E402


def rate(fn, seconds):
    fn()  # warm-up (renderer creation, caches)
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        n += 1
    return n / (time.perf_counter() - t0)


def paired_rates(fa, fb, seconds, rounds=5):
    """Best-of-``rounds`` CPU rates (calls per CPU second) of ``fa`` and ``fb``, measured in alternating
    windows so that both see the same machine state: on a shared 2-core machine a single wall-clock
    window is dominated by whatever else runs, and ray casting is single-threaded CPU work."""
    best = [0.0, 0.0]
    fa(), fb()
    for _ in range(rounds):
        for i, fn in enumerate((fa, fb)):
            n, t0 = 0, time.process_time()
            while time.process_time() - t0 < seconds / rounds:
                fn()
                n += 1
            best[i] = max(best[i], n / (time.process_time() - t0))
    return best


def raw_multiray(w, name):
    """The bare mj_multiRay call a lidar scan needs, with directions precomputed in world axes."""
    return bare_multiray(w.model, w.data, w.lidar_spec(name))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    T = 0.5 if args.quick else 3.0
    rows = []
    for scene, steps, action in (("office2d", 5, (1.0, 0.0)), ("rover_terrain", 20, (6.0, 0.08))):
        w = World(scene, seed=0)
        for _ in range(steps):
            w.step(action)
        for name in ("lidar", "lidar3d"):
            api, raw = paired_rates(lambda: w.lidar(name), raw_multiray(w, name), T)
            rows.append((f"{scene} {name} ({len(w.lidar_spec(name).directions)} beams)",
                         f"{api:.0f} scans/CPU-s", f"{raw:.0f} scans/CPU-s raw", f"{100 * api / raw:.0f}% of raw"))
        w.close()
    w = World("rover_terrain", seed=0)
    for _ in range(20):
        w.step((6.0, 0.08))
    for (W, H) in ((640, 480), (320, 240)):
        fps = rate(lambda: w.camera("front", width=W, height=H), T)
        rows.append((f"rover_terrain camera {W}x{H} rgb+depth+labels", f"{fps:.1f} frames/s", "", ""))
    # Physics only: World.step without sensors, counted in physics steps (timestep 4 ms).
    n_ctrl = rate(lambda: w.step((6.0, 0.08)), T)
    rows.append(("rover_terrain World.step, physics only", f"{n_ctrl * round(w.dt / w.model.opt.timestep):.0f} physics steps/s",
                 f"{n_ctrl:.0f} World.step/s (dt = {w.dt} s)", f"{n_ctrl * w.dt:.0f}x real time"))
    print(f"load: {os.getloadavg()[0]:.2f}")
    print("| what | measured | reference | ratio |\n|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")


if __name__ == "__main__":
    main()
