"""Scene registry: names map to a base MJCF in ``scenes/`` plus a seeded procedural builder.

``load_scene(name_or_path, seed, **options)`` returns an ``mujoco.MjSpec`` ready to compile and
the scene's metadata (route, terrain, target, script, ...). A path to any MJCF file loads that
file as it is, with no procedural part.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import inspect
import os
import xml.etree.ElementTree as ET
from importlib import resources
from pathlib import Path
from collections.abc import Callable

import mujoco

from polar_sim.sim.meta import SceneMeta, check_meta
from polar_sim._validation import as_float, as_int, check_choice
from polar_sim.fileio import check_source

__all__ = ["list_scenes", "scene_dir", "load_scene", "scene_options", "SceneEntry", "SCENES", "describe_scene",
           "MAX_ASSET_BYTES", "MAX_MESH_FACES"]

#: Largest asset file (mesh, texture, heightfield) a user MJCF may reference, bytes.
MAX_ASSET_BYTES = 256 * 2**20
#: Most mesh faces a compiled scene may hold (all meshes together).
MAX_MESH_FACES = 5_000_000


def scene_dir() -> Path:
    """The folder of the shipped MJCF scenes and assets (``scenes/``, packaged as ``polar_sim.scenes``)."""
    # polar_sim/scenes is a link to scenes/ in a source checkout, and the packaged folder in a wheel.
    return Path(str(resources.files("polar_sim.scenes")))


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
    #: "module:function" ``(model, seed, **options) -> metadata`` that writes the layout of another
    #: seed into a model built with ``pooled=True`` (``World.relayout``); "" if the scene has none.
    relayout: str = ""

    def load_builder(self) -> Callable:
        module, func = self.builder.split(":")
        return getattr(importlib.import_module(module), func)

    def load_relayout(self) -> Callable:
        module, func = self.relayout.split(":")
        return getattr(importlib.import_module(module), func)


SCENES = {
    "rover_terrain": SceneEntry("rover_terrain.xml", "polar_sim.sim.builders.terrain:build_rover_terrain",
                                "car-sized rover on a closed route over hills, 4 ground zones, obstacles"),
    "rover_flat": SceneEntry("rover_flat.xml", "polar_sim.sim.builders.terrain:build_rover_flat",
                             "the rover_terrain route and obstacles on flat ground"),
    "office2d": SceneEntry("office2d.xml", "polar_sim.sim.builders.office:build_office",
                           "30 x 30 m lab floor: rooms, doors, furniture; indoor rover with a 2D lidar"),
    "warehouse2d": SceneEntry("warehouse2d.xml", "polar_sim.sim.builders.worlds2d:build_warehouse",
                              "randomised warehouse: shelf rows and racks, thin and curved walls, pillars, "
                              "crates, clutter, an open yard; indoor rover with a 2D lidar"),
    "navworld": SceneEntry("navworld.xml", "polar_sim.sim.builders.navworld:build_navworld",
                           "seeded rooms, doors and clutter with a start and a reachable goal (GPISNav)",
                           "polar_sim.sim.builders.navworld:relayout_navworld"),
    "tabletop": SceneEntry("tabletop.xml", "polar_sim.sim.builders.tabletop:build_tabletop",
                           "table, 4 objects, a scripted mocap hand, static RGB-D camera"),
    "object_orbit": SceneEntry("object_orbit.xml", "polar_sim.sim.builders.tabletop:build_object_orbit",
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
    return dict(_scene_options(name))


@functools.cache
def _scene_options(name):
    sig = inspect.signature(SCENES[name].load_builder())
    return {p.name: p.default for p in sig.parameters.values() if p.kind == p.KEYWORD_ONLY}


@functools.cache
def _base_spec(file):
    """The parsed base MJCF of a shipped scene, parsed once (procedural scenes are rebuilt every
    episode); callers get a copy (``MjSpec.copy``, ~20x cheaper than parsing the file)."""
    return mujoco.MjSpec.from_file(str(scene_dir() / file))


def _check_generic_options(options):
    """Validate the options several scene builders share (rover and sensor options), by name."""
    from polar_sim.sim.actors.robots import ROVER_PRESETS

    out = dict(options)
    checks = {
        "camera_height": lambda v: as_float(v, "camera_height", minimum=0.0, exclusive_minimum=True, maximum=100.0),
        "camera_fovy": lambda v: as_float(v, "camera_fovy", minimum=0.0, exclusive_minimum=True, maximum=179.0),
        "lidar_beams": lambda v: as_int(v, "lidar_beams", minimum=1, maximum=100_000),
        "lidar_range": lambda v: as_float(v, "lidar_range", minimum=0.0, exclusive_minimum=True, maximum=1000.0),
        "rover": lambda v: _check_rover(v, ROVER_PRESETS),
    }
    for k, fn in checks.items():
        if k in out and out[k] is not None:
            out[k] = fn(out[k])
    return out


def _check_rover(v, presets):
    if not isinstance(v, str):
        raise TypeError(f"rover: expected a preset name (str), got {type(v).__name__}")
    return check_choice(v, tuple(presets), "rover")


_ASSET_TAGS = {"mesh": "meshdir", "texture": "texturedir", "hfield": "assetdir", "skin": "assetdir",
               "include": None, "model": None}


def _check_mjcf_files(path: Path):
    """Refuse MJCF whose files (includes, meshes, textures, heightfields) lie outside the scene's
    folder, are missing, or are larger than :data:`MAX_ASSET_BYTES`, before MuJoCo reads them."""
    root = path.resolve().parent
    seen = set()

    def scan(xml_path):
        if xml_path in seen:
            return
        seen.add(xml_path)
        try:
            tree = ET.parse(xml_path)
        except ET.ParseError as exc:
            raise ValueError(f"scene: malformed MJCF in {str(xml_path)!r}: {exc}") from None
        dirs = {"meshdir": "", "texturedir": "", "assetdir": ""}
        for comp in tree.iter("compiler"):
            for k in dirs:
                if comp.get(k) is not None:
                    dirs[k] = comp.get(k)
        if dirs["assetdir"]:
            dirs["meshdir"] = dirs["meshdir"] or dirs["assetdir"]
            dirs["texturedir"] = dirs["texturedir"] or dirs["assetdir"]
        for tag, dkey in _ASSET_TAGS.items():
            for el in tree.iter(tag):
                f = el.get("file")
                if f is None:
                    continue
                base = root / (dirs.get(dkey, "") if dkey else "")
                target = (base / f).resolve()
                if not target.is_relative_to(root):
                    raise ValueError(f"scene: <{tag} file={f!r}> in {xml_path.name!r} points outside the scene "
                                     f"folder {str(root)!r}")
                try:
                    size = target.stat().st_size
                except OSError:
                    raise FileNotFoundError(f"scene: <{tag} file={f!r}> in {xml_path.name!r}: "
                                            f"{str(target)!r} does not exist") from None
                if size > MAX_ASSET_BYTES:
                    raise ValueError(f"scene: <{tag} file={f!r}> is {size / 2**20:.0f} MiB; the limit is "
                                     f"{MAX_ASSET_BYTES // 2**20} MiB (MAX_ASSET_BYTES)")
                if tag == "include":
                    scan(target)

    scan(path.resolve())


def load_scene(scene, seed=0, **options):
    """Build the ``MjSpec`` of a scene name or MJCF path; returns ``(spec, metadata)``.

    Raises ``ValueError`` for an unknown name, an unknown or invalid option, malformed MJCF, an
    MJCF whose files lie outside its folder or exceed :data:`MAX_ASSET_BYTES`, and
    ``FileNotFoundError`` for a missing file (the MJCF or an asset it names).
    """
    seed = as_int(seed, "seed", minimum=0)
    if isinstance(scene, os.PathLike) or (isinstance(scene, str) and scene.endswith(".xml")):
        path = check_source(scene, "scene")
        if options:
            raise ValueError(f"scene options {sorted(options)} apply to named scenes only, not to an MJCF path")
        _check_mjcf_files(path)
        try:
            spec = mujoco.MjSpec.from_file(str(path))
        except Exception as exc:  # mujoco raises its own error types for XML problems
            raise ValueError(f"scene: malformed MJCF in {str(path)!r}: {exc}") from exc
        return spec, SceneMeta()
    if not isinstance(scene, str):
        raise TypeError(f"scene: expected a scene name or a path to an MJCF file, got {type(scene).__name__}")
    if scene not in SCENES:
        raise ValueError(f"scene: unknown scene {scene[:200]!r}; expected one of {', '.join(list_scenes())} "
                         "or a path to an MJCF file")
    valid = scene_options(scene)
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise ValueError(f"{scene}: unknown scene option(s) {unknown}; valid: {sorted(valid)}")
    options = _check_generic_options(options)
    spec = _base_spec(SCENES[scene].file).copy()
    meta = check_meta(scene, SCENES[scene].load_builder()(spec, seed, **options))
    return spec, meta
