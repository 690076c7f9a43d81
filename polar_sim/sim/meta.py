"""``World.meta``: each shipped scene's metadata, a frozen dataclass per scene.

``World(scene).meta`` is the scene's dataclass (``w.meta.goal``, ``w.meta.bounds``): its fields,
their types, shapes and units are declared here, and every value is checked when the scene loads
(a builder that breaks its declaration raises ``TypeError``/``ValueError`` naming the field).
Positions and lengths are metres, angles radians, poses ``(x, y, yaw)`` in the world frame.
Rectangles are ``(x0, x1, y0, y1)``. A world loaded from an MJCF file has a :class:`SceneMeta`
with no fields.

:meth:`SceneMeta.to_dict` gives the fields as a dict (the form the scene builders return) and
:meth:`SceneMeta.from_dict` checks such a dict and builds the dataclass. The values are live
objects (the rover's configuration, the terrain grid, the hand's script): no recording saves
``World.meta`` whole; recordings save the scene, seed and options that rebuild it, plus the few
JSON values they need (a rover route's ``zones`` and ``appearance``).
"""

from __future__ import annotations

import dataclasses
import functools
import typing
from typing import Any, ClassVar

import numpy as np

__all__ = ["SceneMeta", "RoverMeta", "RoverSceneMeta", "Office2DMeta", "Warehouse2DMeta", "NavWorldMeta",
           "TabletopMeta", "ObjectOrbitMeta", "SCENE_META", "check_meta"]

_frozen = dataclasses.dataclass(frozen=True, kw_only=True, eq=False)


@_frozen
class SceneMeta:
    """Metadata common to every scene: none (a world loaded from an MJCF file has this)."""

    #: field -> required shape of its array (None: any length along that axis)
    _SHAPES: ClassVar[dict] = {}

    def __post_init__(self):
        hints = _declared_types(type(self))
        for f in dataclasses.fields(self):
            value, kinds = getattr(self, f.name), hints[f.name]
            if kinds is not None and not isinstance(value, kinds):
                raise TypeError(f"{type(self).__name__}.{f.name}: expected "
                                f"{' | '.join(k.__name__ for k in kinds)}, got {type(value).__name__}")
            shape = self._SHAPES.get(f.name)
            if shape is not None and (np.ndim(value) != len(shape) or any(
                    n is not None and n != m for n, m in zip(shape, np.shape(value)))):
                want = "(" + ", ".join("n" if n is None else str(n) for n in shape) + ("," if len(shape) == 1 else "") + ")"
                raise ValueError(f"{type(self).__name__}.{f.name}: expected shape {want}, got {np.shape(value)}")

    def __getitem__(self, key):
        # World.meta was a dict until issue 34: say how to read it now rather than fail obscurely.
        raise TypeError(f"World.meta is a {type(self).__name__} dataclass, not a dict: read w.meta.{key} "
                        "(or w.meta.to_dict())")

    def __contains__(self, key):
        raise TypeError(f"World.meta is a {type(self).__name__} dataclass, not a dict: test hasattr(w.meta, {key!r}) "
                        "(or key in w.meta.to_dict())")

    def to_dict(self) -> dict:
        """``{field: value}`` of every field (the values themselves, not copies)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls, values: dict):
        """The dataclass from ``{field: value}``: every required field present, no other key, each
        value of its declared type and shape. Raises ``TypeError`` naming the keys otherwise."""
        if not isinstance(values, dict):
            raise TypeError(f"values: expected a dict, got {type(values).__name__}")
        fields = {f.name: f for f in dataclasses.fields(cls)}
        required = {n for n, f in fields.items()
                    if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING}
        missing, extra = sorted(required - set(values)), sorted(set(values) - set(fields))
        if missing or extra:
            raise TypeError(f"{cls.__name__}: keys differ from the declaration: missing {missing}, undeclared {extra}")
        return cls(**values)


@_frozen
class RoverMeta(SceneMeta):
    """What every scene with a rover gives.

    Attributes
    ----------
    rover_config : RoverConfig
        The rover's :class:`~polar_sim.sim.actors.robots.RoverConfig`.
    start_pose2d : ndarray, shape (3,)
        The rover's start (x, y, yaw), m and rad.
    """

    _SHAPES: ClassVar[dict] = {"start_pose2d": (3,)}
    rover_config: Any
    start_pose2d: np.ndarray


@_frozen
class RoverSceneMeta(RoverMeta):
    """``rover_terrain`` and ``rover_flat``.

    Attributes
    ----------
    route : ndarray, shape (n, 2)
        The closed route's waypoints, m.
    zones : list of str
        The ground type or appearance family of each zone, in route order.
    zone_of_route : ndarray, shape (n,)
        int, the zone index of each waypoint.
    terrain : TerrainGrid
        The height grid (:class:`~polar_sim.sim.builders.terrain.TerrainGrid`).
    appearance : dict or None
        The resolved appearance spec; None for the default look.
    """

    _SHAPES: ClassVar[dict] = {**RoverMeta._SHAPES, "route": (None, 2), "zone_of_route": (None,)}
    route: np.ndarray
    zones: list
    zone_of_route: np.ndarray
    terrain: Any
    appearance: dict | None


@_frozen
class Office2DMeta(RoverMeta):
    """``office2d``.

    Attributes
    ----------
    rooms : dict
        Room name -> rectangle (x0, x1, y0, y1), m.
    doors : ndarray, shape (k, 2)
        Door centres, m.
    bounds : tuple
        (x0, x1, y0, y1) of the floor, m.
    tiles : int
        Copies of the floor along each axis (the ``tiles`` option); 1 by default.
    """

    _SHAPES: ClassVar[dict] = {**RoverMeta._SHAPES, "doors": (None, 2), "bounds": (4,)}
    rooms: dict
    doors: np.ndarray
    bounds: tuple
    tiles: int = 1


@_frozen
class Warehouse2DMeta(RoverMeta):
    """``warehouse2d``.

    Attributes
    ----------
    regions : dict
        Region name -> rectangle (x0, x1, y0, y1), m: the aisles, ``main_aisle``, ``partitions``, ``yard``.
    bounds, hall, yard : tuple
        (x0, x1, y0, y1), m: of everything built, of the hall's interior, of the open yard.
    rows_along : str
        ``"x"`` or ``"y"``, the shelf rows' direction.
    corners : ndarray, shape (k, 2)
        The section's corners, m (scored separately by the GPIS experiments).
    layout : dict
        The section's shapes: ``"boxes"`` (k, 5), ``"discs"`` (k, 3), ``"names"``.
    features : dict
        Feature kind -> (k, columns) array or count.
    """

    _SHAPES: ClassVar[dict] = {**RoverMeta._SHAPES, "corners": (None, 2), "bounds": (4,), "hall": (4,), "yard": (4,)}
    regions: dict
    bounds: tuple
    hall: tuple
    yard: tuple
    rows_along: str
    corners: np.ndarray
    layout: dict
    features: dict


@_frozen
class NavWorldMeta(RoverMeta):
    """``navworld`` (the GPISNav and LidarNav worlds).

    Attributes
    ----------
    goal : ndarray, shape (2,)
        The goal, m, reachable from the start.
    bounds : tuple
        (x0, x1, y0, y1) of the rooms, m.
    occupancy : ndarray, shape (nx, ny)
        bool, obstacles inflated by the robot radius; cell (i, j) covers
        ``x0 + i * occupancy_res``, ``y0 + j * occupancy_res``.
    occupancy_res : float
        The occupancy grid's cell size, m.
    robot_radius : float
        The rover's footprint radius, m.
    pooled : bool
        The model has slots for any layout (``World.relayout``); False by default.
    max_round_radius : float
        The pooled model's largest round obstacle, m; 0.0 when not pooled.
    """

    _SHAPES: ClassVar[dict] = {**RoverMeta._SHAPES, "goal": (2,), "bounds": (4,), "occupancy": (None, None)}
    goal: np.ndarray
    bounds: tuple
    occupancy: np.ndarray
    occupancy_res: float
    robot_radius: float
    pooled: bool = False
    max_round_radius: float = 0.0


@_frozen
class _ObjectsMeta(SceneMeta):
    """What the object scenes share (documented in each)."""

    objects: list
    target: str
    control_dt: float
    script: Any
    script_name: str
    colours: dict


@_frozen
class TabletopMeta(_ObjectsMeta):
    """``tabletop``.

    Attributes
    ----------
    objects : list of str
        The objects' names.
    target : str
        The object the hand handles.
    control_dt : float
        Seconds per control step.
    script : HandScript
        The hand's :class:`~polar_sim.sim.actors.hand.HandScript`.
    script_name : str
        Its name.
    colours : dict
        Object name -> its colour name(s).
    table_z : float
        The table top's height, m.
    appearance : dict or None
        The resolved appearance spec (with the ``appearance`` option); None by default.
    """

    table_z: float
    appearance: dict | None = None


@_frozen
class ObjectOrbitMeta(_ObjectsMeta):
    """``object_orbit``.

    Attributes
    ----------
    objects : list of str
        The objects' names (one).
    target : str
        That object.
    control_dt : float
        Seconds per control step.
    script : OrbitScript
        The camera's orbit (:class:`~polar_sim.sim.recorders.orbits.OrbitScript`).
    script_name : str
        Its name.
    colours : dict
        Object name -> its colour name(s).
    centre : list
        (3,) the point the camera circles, m.
    """

    _SHAPES: ClassVar[dict] = {"centre": (3,)}
    centre: list


#: Scene name -> the dataclass its ``World.meta`` is.
SCENE_META = {"rover_terrain": RoverSceneMeta, "rover_flat": RoverSceneMeta, "office2d": Office2DMeta,
              "warehouse2d": Warehouse2DMeta, "navworld": NavWorldMeta, "tabletop": TabletopMeta,
              "object_orbit": ObjectOrbitMeta}


def check_meta(scene: str, meta: dict) -> SceneMeta:
    """The scene's dataclass from a builder's dict (:meth:`SceneMeta.from_dict` of
    ``SCENE_META[scene]``); raises ``TypeError``/``ValueError`` naming the scene's class and the
    field when the builder breaks its declaration (a builder's bug, not a user's input)."""
    return SCENE_META[scene].from_dict(meta)


@functools.cache
def _declared_types(cls):
    """Field -> tuple of classes for ``isinstance`` (None for ``Any``), from a dataclass's hints."""
    out = {}
    for key, kind in typing.get_type_hints(cls).items():
        if typing.get_origin(kind) is ClassVar:
            continue
        if kind is Any:
            out[key] = None
            continue
        args = typing.get_args(kind) if typing.get_origin(kind) is not None and typing.get_origin(kind) is not list \
            else (kind,)
        out[key] = tuple(type(None) if k is None else (typing.get_origin(k) or k) for k in args)
    return out
