"""The simulator layer: everything that imports MuJoCo lives here and nowhere else.

>>> from polar_sim.sim import World, list_scenes
>>> w = World("rover_flat", seed=0)
>>> w.step((5.0, 0.1)); f = w.camera("front"); s = w.lidar("lidar")

Names are imported on first use, so ``polar_sim.sim.recorders.recording`` (replaying recorded data) does
not load MuJoCo.
"""

import importlib
import os

# Headless by default: CPU EGL through Mesa. Set before mujoco creates a GL context.
os.environ.setdefault("MUJOCO_GL", "egl")

_EXPORTS = {
    "World": "polar_sim.sim.world",
    "list_scenes": "polar_sim.sim.scenes",
    "scene_options": "polar_sim.sim.scenes",
    "CameraFrame": "polar_sim.sim.sensors",
    "LidarScan": "polar_sim.sim.sensors",
    "LidarScan3D": "polar_sim.sim.sensors",
    "RangeNoise": "polar_sim.sim.sensors",
    "DepthNoise": "polar_sim.sim.sensors",
    "LABELS": "polar_sim.sim.truth",
    "Recording": "polar_sim.sim.recorders.recording",
}
__all__ = list(_EXPORTS)


def __getattr__(name):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'polar_sim.sim' has no attribute {name!r}")


def __dir__():
    return __all__
