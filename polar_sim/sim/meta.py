"""The declared contract of ``World.meta``: what each shipped scene's builder returns.

``World(scene).meta`` is a plain dict (``w.meta["goal"]``), typed here per scene as a
``TypedDict`` so that a reader (and a type checker) knows every key, its type and its unit, and
:func:`check_meta` holds every builder to its declaration when a scene is loaded. Positions and
lengths are metres, angles radians, poses ``(x, y, yaw)`` in the world frame.
"""


import functools
import typing
from typing import Any, NotRequired, TypedDict

import numpy as np

__all__ = ["RoverMeta", "RoverSceneMeta", "Office2DMeta", "Warehouse2DMeta", "NavWorldMeta", "TabletopMeta",
           "ObjectOrbitMeta", "SCENE_META", "check_meta"]


class RoverMeta(TypedDict):
    """What every scene with a rover gives."""

    rover_config: Any          #: the rover's :class:`~polar_sim.sim.actors.robots.RoverConfig`
    start_pose2d: np.ndarray   #: (3,) the rover's start (x, y, yaw)


class RoverSceneMeta(RoverMeta):
    """``rover_terrain`` and ``rover_flat``."""

    route: np.ndarray          #: (n, 2) the closed route's waypoints
    zones: list                #: the ground type or appearance family of each zone, in route order
    zone_of_route: np.ndarray  #: (n,) int, the zone index of each waypoint
    terrain: Any               #: the height grid, :class:`~polar_sim.sim.builders.terrain.TerrainGrid`
    appearance: dict | None    #: the resolved appearance spec, None for the default look


class Office2DMeta(RoverMeta):
    """``office2d``."""

    rooms: dict                #: room name -> (x0, x1, y0, y1)
    doors: np.ndarray          #: (k, 2) door centres
    bounds: tuple              #: (x0, x1, y0, y1) of the floor
    tiles: NotRequired[int]    #: copies of the floor along each axis (with the ``tiles`` option > 1)


class Warehouse2DMeta(RoverMeta):
    """``warehouse2d``."""

    regions: dict              #: region name -> (x0, x1, y0, y1): aisles, main aisle, partitions, yard
    bounds: tuple              #: (x0, x1, y0, y1) of everything built
    hall: tuple                #: (x0, x1, y0, y1) of the hall's interior
    yard: tuple                #: (x0, x1, y0, y1) of the open yard
    rows_along: str            #: "x" or "y", the shelf rows' direction
    corners: np.ndarray        #: (k, 2) the section's corners (scored separately by the GPIS experiments)
    layout: dict               #: "boxes" (k, 5), "discs" (k, 3), "names": the section's shapes
    features: dict             #: feature kind -> (k, columns) array or count


class NavWorldMeta(RoverMeta):
    """``navworld`` (the GPISNav and LidarNav worlds)."""

    goal: np.ndarray           #: (2,) the goal, reachable from the start
    bounds: tuple              #: (x0, x1, y0, y1) of the rooms
    occupancy: np.ndarray      #: (nx, ny) bool, obstacles inflated by the robot radius
    occupancy_res: float       #: the occupancy grid's cell size
    robot_radius: float        #: the rover's footprint radius
    pooled: NotRequired[bool]  #: the model has slots for any layout (``World.relayout``)
    max_round_radius: NotRequired[float]  #: the pooled model's largest round obstacle


class TabletopMeta(TypedDict):
    """``tabletop``."""

    objects: list              #: the objects' names
    target: str                #: the object the hand handles
    control_dt: float          #: seconds per control step
    script: Any                #: the hand's :class:`~polar_sim.sim.actors.hand.HandScript`
    script_name: str           #: its name
    colours: dict              #: object name -> its colour name
    table_z: float             #: the table top's height
    appearance: NotRequired[dict]  #: the resolved appearance spec (with the ``appearance`` option)


class ObjectOrbitMeta(TypedDict):
    """``object_orbit``."""

    objects: list              #: the objects' names (one)
    target: str                #: that object
    control_dt: float          #: seconds per control step
    script: Any                #: the camera's orbit (:class:`~polar_sim.sim.recorders.orbits.OrbitScript`)
    script_name: str           #: its name
    colours: dict              #: object name -> its colour name
    centre: list               #: (3,) the point the camera circles


#: Scene name -> the TypedDict its ``World.meta`` follows.
SCENE_META = {"rover_terrain": RoverSceneMeta, "rover_flat": RoverSceneMeta, "office2d": Office2DMeta,
              "warehouse2d": Warehouse2DMeta, "navworld": NavWorldMeta, "tabletop": TabletopMeta,
              "object_orbit": ObjectOrbitMeta}


def check_meta(scene: str, meta: dict) -> dict:
    """Hold a builder's metadata to its scene's declaration: every required key present, no
    undeclared key, and each value of its declared type. Returns ``meta``; raises ``TypeError``
    naming the scene and the key otherwise (a builder's bug, not a user's input)."""
    decl = SCENE_META[scene]
    hints = _declared_types(decl)
    missing = sorted(decl.__required_keys__ - set(meta))
    extra = sorted(set(meta) - set(hints))
    if missing or extra:
        raise TypeError(f"{scene}: World.meta keys differ from {decl.__name__}: missing {missing}, undeclared {extra}")
    for key, value in meta.items():
        if hints[key] is not None and not isinstance(value, hints[key]):
            raise TypeError(f"{scene}: World.meta[{key!r}] is a {type(value).__name__}, declared "
                            f"{' | '.join(k.__name__ for k in hints[key])}")
    return meta


@functools.cache
def _declared_types(decl):
    """Key -> tuple of classes for ``isinstance`` (None for ``Any``), from a TypedDict."""
    out = {}
    for key, kind in typing.get_type_hints(decl).items():
        if kind is Any:
            out[key] = None
            continue
        args = typing.get_args(kind) if typing.get_origin(kind) is not None and typing.get_origin(kind) is not list \
            else (kind,)
        out[key] = tuple(type(None) if k is None else (typing.get_origin(k) or k) for k in args)
    return out
