"""Scene registry: names map to a base MJCF in ``scenes/`` plus a seeded procedural builder.

``load_scene(name_or_path, seed, **options)`` returns an ``mujoco.MjSpec`` ready to compile and
the scene's metadata (route, terrain, target, script, ...). A path to any MJCF file loads that
file as it is, with no procedural part.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
from importlib import resources
from pathlib import Path
from typing import Callable

import mujoco

__all__ = ["list_scenes", "scene_dir", "load_scene", "scene_options", "SceneEntry", "SCENES", "describe_scene"]


def scene_dir() -> Path:
    """The folder of the shipped MJCF scenes and assets."""
    try:
        p = Path(str(resources.files("polar_sim.scenes")))
        if (p / "rover_flat.xml").is_file():
            return p
    except ModuleNotFoundError:
        pass
    # Running from a source checkout without installing: scenes/ sits beside polar_sim/.
    return Path(__file__).resolve().parents[2] / "scenes"


@dataclasses.dataclass(frozen=True)
class SceneEntry:
    """A shipped scene: its base MJCF file, its builder ``"module:function"`` and a description.

    The builder has the signature ``(spec, seed, *, option=default, ...) -> metadata`` and adds
    the seeded procedural part to the base spec; its keyword-only parameters are the scene's
    options.
    """

    file: str
    builder: str
    description: str

    def load_builder(self) -> Callable:
        module, func = self.builder.split(":")
        return getattr(importlib.import_module(module), func)


SCENES = {
    "rover_terrain": SceneEntry("rover_terrain.xml", "polar_sim.sim.terrain:build_rover_terrain",
                                "car-sized rover on a closed route over hills, 4 ground zones, obstacles"),
    "rover_flat": SceneEntry("rover_flat.xml", "polar_sim.sim.terrain:build_rover_flat",
                             "the rover_terrain route and obstacles on flat ground"),
    "office2d": SceneEntry("office2d.xml", "polar_sim.sim.office:build_office",
                           "30 x 30 m lab floor: rooms, doors, furniture; indoor rover with a 2D lidar"),
    "warehouse2d": SceneEntry("warehouse2d.xml", "polar_sim.sim.worlds2d:build_warehouse",
                              "randomised warehouse: shelf rows and racks, thin and curved walls, pillars, "
                              "crates, clutter, an open yard; indoor rover with a 2D lidar"),
    "navworld": SceneEntry("navworld.xml", "polar_sim.sim.navworld:build_navworld",
                           "seeded rooms, doors and clutter with a start and a reachable goal (GPISNav)"),
    "tabletop": SceneEntry("tabletop.xml", "polar_sim.sim.tabletop:build_tabletop",
                           "table, 4 objects, a scripted mocap hand, static RGB-D camera"),
    "object_orbit": SceneEntry("object_orbit.xml", "polar_sim.sim.tabletop:build_object_orbit",
                               "an RGB-D camera circling one object, like a turntable capture"),
}


def list_scenes():
    """Names of the shipped scenes, sorted."""
    return sorted(SCENES)


def describe_scene(name):
    """One-line description of a shipped scene."""
    return SCENES[name].description


def scene_options(name):
    """Names and defaults of the options a shipped scene accepts, as a dict."""
    sig = inspect.signature(SCENES[name].load_builder())
    return {p.name: p.default for p in sig.parameters.values() if p.kind == p.KEYWORD_ONLY}


def load_scene(scene, seed=0, **options):
    """Build the ``MjSpec`` of a scene name or MJCF path; returns ``(spec, metadata)``.

    Raises ``ValueError`` for an unknown name, an unknown option or malformed MJCF, and
    ``FileNotFoundError`` for a missing file.
    """
    if isinstance(scene, Path) or (isinstance(scene, str) and scene.endswith(".xml")):
        path = Path(scene)
        if not path.is_file():
            raise FileNotFoundError(f"scene: MJCF file {str(path)!r} does not exist")
        if options:
            raise ValueError(f"scene options {sorted(options)} apply to named scenes only, not to an MJCF path")
        try:
            spec = mujoco.MjSpec.from_file(str(path))
        except Exception as exc:  # mujoco raises its own error types for XML problems
            raise ValueError(f"scene: malformed MJCF in {str(path)!r}: {exc}") from exc
        return spec, {}
    if not isinstance(scene, str):
        raise TypeError(f"scene: expected a scene name or a path to an MJCF file, got {type(scene).__name__}")
    if scene not in SCENES:
        raise ValueError(f"scene: unknown scene {scene!r}; expected one of {', '.join(list_scenes())} "
                         "or a path to an MJCF file")
    valid = scene_options(scene)
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise ValueError(f"{scene}: unknown scene option(s) {unknown}; valid: {sorted(valid)}")
    spec = mujoco.MjSpec.from_file(str(scene_dir() / SCENES[scene].file))
    meta = SCENES[scene].load_builder()(spec, seed, **options)
    return spec, meta
