"""``polar-sim demo``: a short headless run of the simulator and the three modules on the
built-in scenes, printing a summary and writing PNGs. Each part is one function; the demo runs
them in order and reports which ran."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

__all__ = ["run_demo"]


def demo_scenes(out: Path):
    """Render the rover scenes' sensors: camera, depth, labels, lidar."""
    from polar_sim.sim import World
    from polar_sim.sim.pictures import render_scene_pictures

    lines = []
    for scene, action in (("rover_terrain", (6.0, 0.08)), ("office2d", (1.0, 0.0))):
        with World(scene, seed=0) as w:
            for _ in range(10):
                w.step(action)
            render_scene_pictures(w, out, width=480, height=360)
            s = w.lidar("lidar")
            t = w.truth()
            lines.append(f"{scene}: robot at ({t['robot_pose2d'][0]:.1f}, {t['robot_pose2d'][1]:.1f}) m, "
                         f"speed {t['robot_twist'][0]:.2f} m/s, lidar {np.isfinite(s.ranges).sum()}/{len(s.ranges)} returns")
    return lines


DEMOS = [("scenes", demo_scenes)]


def run_demo(out: Path, quick=True):
    """Run every demo part; returns the process exit code."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"polar_sim demo: writing pictures to {out}/")
    rc = 0
    for name, fn in DEMOS:
        t0 = time.perf_counter()
        try:
            lines = fn(out)
        except Exception as exc:  # report and carry on with the other parts
            print(f"[{name}] FAILED: {type(exc).__name__}: {exc}")
            rc = 1
            continue
        for line in lines:
            print(f"[{name}] {line}")
        print(f"[{name}] done in {time.perf_counter() - t0:.1f} s")
    pngs = sorted(out.glob("*.png"))
    print(f"wrote {len(pngs)} PNGs to {out}/")
    return rc
