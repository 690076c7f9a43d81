"""The manipulation scenes: ``tabletop`` (objects on a table, a scripted mocap hand, a static
RGB-D camera) and ``object_orbit`` (an RGB-D camera circling one object).

Both builders add the seeded parts to their base MJCF (``scenes/tabletop.xml``,
``scenes/object_orbit.xml``): object choice, placement and colours, procedural textures, the
hand and the script. Objects come from :mod:`polar_sim.sim.builders.objects`; each is a textured visual
mesh (no collisions) plus hidden collision primitives. The tracked object's visible geom is in
the ``target`` geom group, so :meth:`World.amodal_mask` renders its full silhouette.

Scripts of ``tabletop`` (option ``script``):

========  =====================================================================================
touch     the palm rests on the target's top, fingers over its front; twice (Mode B, contact)
push      the fingers push the target 10 cm along +x, then 8 cm back (Mode B, physics)
lift      grasp, lift 15 cm, tilt toward the camera, turn, put back (Mode A, kinematic)
turn      grasp, lift 3 cm, turn 70-100 deg about the vertical, roll, put down; twice
fast      grasp and shake: +-7 cm, +-25 deg moves of 0.5 s (peaks ~0.7 m/s, ~190 deg/s)
light     the key light dims to 30 % and brightens to 130 % while the hand touches and turns
pass      the hand sweeps across in front of the target without touching it, twice
demo      touch, pass, lift, turn, push, and again (cycles for ever)
reach     the hand is driven from outside (``World.meta.script.command(velocity, yaw_rate)``) and a
          scripted disturbance slides the target about the front of the table
          (:class:`polar_sim.sim.actors.hand.ReachScript`; used by the ``ObjectTrack-v0`` environment)
========  =====================================================================================
"""

from __future__ import annotations

import logging

import mujoco
import numpy as np

from polar_sim.sim.builders import objects as _objects
from polar_sim.sim.actors.hand import (COLLIDE_OBJECT, COLLIDE_STATIC, HandScript, ReachScript, add_hand,
                                look_at_quat, matrix_to_quat)
from polar_sim.sim.actors.robots import GROUP
from polar_sim.sim.builders.tabletop_textures import COLOURS, _wall_texture, _wood_texture, object_texture
from polar_sim.sim.builders.tabletop_appearance import (HAND_COLOURS, SLEEVE_COLOURS, appearance_rng, flat_texture,
                                               resolve_appearance, table_texture)

__all__ = ["build_tabletop", "build_object_orbit", "SCRIPTS", "AGENT_SCRIPTS", "COLOURS", "OrbitScript",
           "object_texture"]

logger = logging.getLogger(__name__)

TABLE_Z = 0.75
CONTROL_DT = 1.0 / 30.0
TIMESTEP = CONTROL_DT / 20  # 20 physics substeps per camera frame

#: Scripts: (actions, options) — actions as in :mod:`polar_sim.sim.actors.hand`.
SCRIPTS = {
    "touch": [("touch", {"yaw": 0.0}), ("touch", {"yaw": 0.5, "hold": 2.2})],
    "push": [("push", {"dir": 1.0, "dist": 0.10}), ("push", {"dir": -1.0, "dist": 0.08})],
    "lift": [("lift", {})],
    "turn": [("turn", {}), ("turn", {})],
    "fast": [("fast", {})],
    "light": [("touch", {"hold": 2.0}), ("turn", {})],
    "pass": [("pass", {"dir": 1.0, "height": 0.0, "duration": 3.6}),
             ("pass", {"dir": -1.0, "height": -0.045, "duration": 3.6})],
    "demo": ["touch", "pass", "lift", "turn", "push"],
}
CAMERA_MOTIONS = ("static", "sway")
#: Scripts where the hand is driven from outside (not by a list of actions).
AGENT_SCRIPTS = ("reach",)
#: ``reach``: the box the palm centre stays in (x0, x1, y0, y1, z0, z1), m; z0 keeps the
#: fingertips above the table top.
REACH_WORKSPACE = (-0.55, 0.55, -0.45, 0.55, 0.83, 1.45)


def _check(value, choices, name):
    if value not in choices:
        raise ValueError(f"{name}: unknown value {value!r}; expected one of {', '.join(map(repr, choices))}")
    return value


# -- textures --------------------------------------------------------------------------------

def _add_texture(spec, name, img):
    tex = spec.add_texture(name=name, type=mujoco.mjtTexture.mjTEXTURE_2D,
                           width=img.shape[1], height=img.shape[0], nchannel=3)
    tex.data = np.ascontiguousarray(img).tobytes()
    mat = spec.add_material(name=name, specular=0.15, shininess=0.2)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = name
    return mat


# -- objects ---------------------------------------------------------------------------------

def _add_mesh(spec, name):
    """Add object ``name``'s shipped OBJ mesh (vertices, faces and texture coordinates)."""
    V, T, F, FT = [], [], [], []
    for line in _objects.asset_path(name).read_text().splitlines():
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "v":
            V.extend(float(a) for a in tok[1:4])
        elif tok[0] == "vt":
            T.extend(float(a) for a in tok[1:3])
        elif tok[0] == "f":
            for c in tok[1:4]:
                v, t = c.split("/")[:2]
                F.append(int(v) - 1)
                FT.append(int(t) - 1)
    mesh = spec.add_mesh(name=f"mesh_{name}")
    mesh.uservert = V
    mesh.userface = F
    mesh.usertexcoord = T
    mesh.userfacetexcoord = FT
    return mesh


def _add_object(spec, name, pos, yaw, material, *, target, free=True):
    info = _objects.object_info(name)
    _add_mesh(spec, name)
    body = spec.worldbody.add_body(name=name, pos=list(pos), quat=[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)])
    if free:
        body.add_freejoint(name=f"{name}_free")
    body.add_geom(name=f"{name}_visual", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"mesh_{name}",
                  material=material, contype=0, conaffinity=0, density=0.0,
                  group=GROUP["target"] if target else GROUP["dynamic"])
    if not free:
        return body
    vols = []
    for c in info.collision:
        s = c["size"]
        vols.append(8 * s[0] * s[1] * s[2] if c["type"] == "box" else 2 * np.pi * s[0] ** 2 * s[1])
    fracs = [c.get("mass_frac", v / sum(vols)) for c, v in zip(info.collision, vols)]
    bits = COLLIDE_OBJECT if target else COLLIDE_STATIC  # the hand touches the target only
    for k, (c, frac) in enumerate(zip(info.collision, fracs)):
        kw = dict(name=f"{name}_collision{k}", size=list(c["size"]) + [0] * (3 - len(c["size"])),
                  pos=list(c["pos"]), group=GROUP["collision"], rgba=[0, 0, 0, 0],
                  contype=bits, conaffinity=bits, mass=info.mass * frac,
                  friction=[0.5, 0.005, 0.0001], condim=4)
        if c["type"] == "box":
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, **kw)
        else:
            if c.get("axis", "z") == "x":
                kw["quat"] = [np.sqrt(0.5), 0, np.sqrt(0.5), 0]
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, **kw)
    return body


def _disc(mesh, x, y, yaw):
    """Footprint of a mesh standing at (x, y) with ``yaw``: centre (2,) and radius of the
    smallest disc about its bounding-box centre that holds it."""
    c = 0.5 * (mesh.bounds[0, :2] + mesh.bounds[1, :2])
    r = float(np.linalg.norm(mesh.vertices[:, :2] - c, axis=1).max())
    cs, sn = np.cos(yaw), np.sin(yaw)
    return np.array([x + cs * c[0] - sn * c[1], y + sn * c[0] + cs * c[1]]), r


#: The camera's pose in scenes/tabletop.xml (eye and look-at point, m) and vertical fov (deg).
CAMERA_EYE, CAMERA_LOOK, CAMERA_FOVY = (0.0, -0.6106, 1.2015), (0.0, 0.0, 0.82), 44.62


def _in_view(c, r, mesh, margin=0.04):
    """Whether a footprint disc (centre c, radius r) and the object's height above it are inside
    the camera's image, ``margin`` (fraction of the width) from its borders."""
    eye, look = np.asarray(CAMERA_EYE), np.asarray(CAMERA_LOOK)
    f = (look - eye) / np.linalg.norm(look - eye)
    right = np.cross(f, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(f, right)
    t = np.tan(np.radians(CAMERA_FOVY) / 2)
    h = mesh.bounds[1, 2]
    for dx in (-r, r):
        for dz in (0.0, h):
            p = np.array([c[0] + dx, c[1], TABLE_Z + dz]) - eye
            x, y = (p @ right) / (p @ f), (p @ down) / (p @ f)
            if abs(x) > t * 4 / 3 * (1 - 2 * margin) or abs(y) > t * (1 - 2 * margin):
                return False
    return True


def _place(rng, target, others, meshes):
    """Seeded positions (x, y) and yaws. The target stands in the front half of the table; the
    others stand behind it, so the strips beside it (pushing) and in front of it (the pass, the
    camera's view) stay clear. A layout that does not fit is drawn again."""
    for _ in range(50):
        out = _try_place(rng, target, others, meshes)
        if out is not None:
            return out
    raise ValueError(f"n_objects: cannot place {len(others) + 1} objects on the table")


def _try_place(rng, target, others, meshes):
    xt, yt, at = rng.uniform(-0.10, 0.0), rng.uniform(-0.10, -0.04), rng.uniform(-np.pi, np.pi)
    out = {target: (xt, yt, at)}
    ct, rt = _disc(meshes[target], xt, yt, at)
    placed = [(ct, rt)]
    for o in others:
        for _ in range(1000):
            x, y, a = rng.uniform(-0.45, 0.45), rng.uniform(-0.05, 0.36), rng.uniform(-np.pi, np.pi)
            c, r = _disc(meshes[o], x, y, a)
            if not (c[1] + r < 0.38 and c[1] - r > ct[1] + rt + 0.04 and _in_view(c, r, meshes[o])):
                continue
            if all(np.linalg.norm(c - c2) > r + r2 + 0.02 for c2, r2 in placed):
                break
        else:
            return None
        out[o] = (x, y, a)
        placed.append((c, r))
    return out


def _surface_samples(mesh, n=4000):
    import trimesh

    pts, _ = trimesh.sample.sample_surface_even(mesh, n, seed=0)
    return np.vstack([np.asarray(pts), mesh.vertices])


def _light_ramp(t):
    """Key-light scale over time: 1 until 1.5 s, down to 0.3 at 4.5 s, held, up to 1.3 at
    9.5 s, held."""
    from polar_sim.sim.actors.hand import min_jerk

    if t < 1.5:
        return 1.0
    if t < 4.5:
        return 1.0 - 0.7 * min_jerk((t - 1.5) / 3.0)
    if t < 6.5:
        return 0.3
    return 0.3 + 1.0 * min_jerk((t - 6.5) / 3.0)


def _camera_sway(p0, look):
    p0 = np.asarray(p0, float)

    def pose(t):
        p = p0 + np.array([0.10 * np.sin(2 * np.pi * t / 9.0), 0.03 * np.sin(2 * np.pi * t / 6.0),
                           0.05 * np.sin(2 * np.pi * t / 7.0)])
        return p, look_at_quat(p, look)
    return pose


def build_tabletop(spec: mujoco.MjSpec, seed: int, *, script="demo", target=None, n_objects=4,
                   target_colour=None, distractor_like_target=False, camera_motion="static", appearance=None):
    """``tabletop``: 4-6 objects on a table, a scripted mocap hand, a static RGB-D camera.

    Options: ``script`` (one of :data:`SCRIPTS` or :data:`AGENT_SCRIPTS`), ``target`` (an object name from
    :func:`polar_sim.sim.builders.objects.object_names`, default chosen from the seed), ``n_objects``
    (4-6), ``target_colour`` (a name of :data:`COLOURS`, e.g. ``"skin"`` for an object the colour
    of the hand; default seeded), ``distractor_like_target`` (give one other object the
    target's colours), ``camera_motion`` ("static" or "sway": the camera drifts slowly, always
    looking at the table), ``appearance`` (None: the scene as it has always been rendered; a
    family name, ``"random"`` or a dict spec: see :mod:`polar_sim.sim.builders.tabletop_appearance`).
    A target named explicitly may also be ``"blocks"``; without ``target`` the seed chooses among
    :data:`polar_sim.sim.builders.objects.DEFAULT_OBJECTS`.

    Returns the metadata: ``objects``, ``target``, ``control_dt``, ``script`` (a
    :class:`polar_sim.sim.actors.hand.HandScript`), ``script_name``, ``colours``, ``table_z``, and
    ``appearance`` (the resolved spec as a dict) when one was given.
    """
    _check(script, tuple(SCRIPTS) + AGENT_SCRIPTS, "script")
    names = list(_objects.DEFAULT_OBJECTS)
    if target is not None:
        _check(target, tuple(_objects.object_names()), "target")
    if isinstance(n_objects, bool) or not isinstance(n_objects, (int, np.integer)) or not 4 <= n_objects <= 6:
        raise ValueError(f"n_objects: expected an integer in 4..6, got {n_objects!r}")
    if target_colour is not None:
        _check(target_colour, tuple(COLOURS), "target_colour")
    _check(camera_motion, CAMERA_MOTIONS, "camera_motion")
    context = f"{script}/{target}"
    app = resolve_appearance(appearance, seed, context)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7101]))
    # the appearance draws from its own stream: the layout's draws below stay those of the default
    arng = appearance_rng(seed, context) if app is not None else None
    spec.option.timestep = TIMESTEP
    table = _wood_texture(rng)
    # "wood" is the scene's own wood (the default's, from the layout stream)
    _add_texture(spec, "table_wood", table if app is None or app.table == "wood" else table_texture(app.table, arng))
    _add_texture(spec, "wall", _wall_texture(rng))

    if target is None:
        target = str(rng.choice(names))
    others = [str(o) for o in rng.permutation([n for n in names if n != target])[: n_objects - 1]]
    meshes = {o: _objects.load_mesh(o) for o in [target] + others}
    layout = _place(rng, target, others, meshes)
    palette = [c for c in COLOURS if c != "skin"]
    order = [str(c) for c in rng.permutation(palette)]
    colours = {}
    for k, o in enumerate([target] + others):
        colours[o] = (order[k % len(order)], order[(k + 3) % len(order)])
    if target_colour is not None:
        colours[target] = (target_colour, colours[target][1])
    if distractor_like_target:
        colours[others[0]] = colours[target]
    for o in [target] + others:
        base, accent = colours[o]
        tex = object_texture(COLOURS[base], COLOURS[accent], rng)
        if app is not None:
            tex, colours[o] = _styled_texture(app, o, tex, colours[o], arng)
        _add_texture(spec, f"tex_{o}", tex)
        x, y, yaw = layout[o]
        _add_object(spec, o, (x, y, TABLE_Z), yaw, f"tex_{o}", target=(o == target))

    home = (np.array([0.32, 0.42, 1.32]), matrix_to_quat(np.diag([-1.0, -1.0, 1.0])))
    if app is None:
        add_hand(spec, *home)
    else:
        add_hand(spec, *home, skin=HAND_COLOURS[app.hand], sleeve=SLEEVE_COLOURS[app.sleeve])
        _apply_light(spec, app.light)
    extra = {} if app is None else {"appearance": app.as_dict()}
    cam_body = spec.body("camera_rig")
    cam_pos = np.array(cam_body.pos, float)
    if script in AGENT_SCRIPTS:
        if camera_motion != "static":
            raise ValueError(f"camera_motion: {camera_motion!r} is not available with script={script!r}; use 'static'")
        x0, y0 = layout[target][:2]
        region = (max(x0 - 0.12, -0.25), min(x0 + 0.12, 0.2), y0 - 0.08, y0 + 0.01)
        hs = ReachScript(target, [target] + others, home, TABLE_Z, int(rng.integers(2 ** 31)),
                         region=region, workspace=REACH_WORKSPACE)
        return {"objects": [target] + others, "target": target, "control_dt": CONTROL_DT, "script": hs,
                "script_name": script, "colours": {o: list(c) for o, c in colours.items()},
                "table_z": TABLE_Z, **extra}
    actions = SCRIPTS[script]
    light = None
    if script == "light":
        light = _light_ramp
    camera = _camera_sway(cam_pos, (0.0, 0.05, TABLE_Z + 0.05)) if camera_motion == "sway" else None
    samples = {target: _surface_samples(meshes[target])}
    hs = HandScript(actions, target, [target] + others, samples, cam_pos, home, TABLE_Z,
                    int(rng.integers(2 ** 31)), cycle=(script == "demo"), light=light, camera=camera)
    return {
        "objects": [target] + others,
        "target": target,
        "control_dt": CONTROL_DT,
        "script": hs,
        "script_name": script,
        "colours": {o: list(c) for o, c in colours.items()},
        "table_z": TABLE_Z,
        **extra,
    }


def _styled_texture(app, name, textured, colours, arng):
    """The atlas of object ``name`` under appearance ``app``: the printed one, or a flat one whose
    tiles are the object's colours (body, accent, and a third drawn from the palette unless the
    spec names it). Returns the texture and the object's colour names."""
    flat = app.objects == "flat" or (app.objects == "mixed" and arng.random() < 0.5)
    palette = [c for c in COLOURS if c != "skin"]
    third = [c for c in palette if c not in colours]
    names = list(colours) + [str(third[int(arng.integers(len(third)))])]
    given = app.colours.get(name, [])
    names[: len(given)] = given
    if not flat:
        if given:  # the printed atlas in the named body and accent colours
            return object_texture(COLOURS[names[0]], COLOURS[names[1]], arng), names
        return textured, names
    return flat_texture([COLOURS[c] for c in names]), names


def _apply_light(spec, light):
    """Key light turned about the vertical through the table centre, scaled and tinted; fill and
    ambient scaled (the base values are those of scenes/tabletop.xml)."""
    key, fill = spec.light("key"), spec.light("fill")
    a = np.radians(light["azimuth_deg"])
    Rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    key.pos = list(Rz @ np.asarray(key.pos, float))
    key.dir = list(Rz @ np.asarray(key.dir, float))
    key.diffuse = list(np.asarray(key.diffuse, float) * light["intensity"] * np.asarray(light["tint"]))
    fill.diffuse = list(np.asarray(fill.diffuse, float) * light["fill"])
    spec.visual.headlight.ambient = [light["ambient"]] * 3


class OrbitScript:
    """Moves the camera rig of ``object_orbit`` on a circle around the object, looking at it.

    The camera circles once every ``period`` seconds at ``radius`` metres (horizontal), its
    height swinging between ``elevation_deg`` +- 12 deg twice per turn.
    """

    def __init__(self, centre, radius, elevation_deg, period, phase0):
        self.centre = np.asarray(centre, float)
        self.radius, self.period, self.phase0 = float(radius), float(period), float(phase0)
        self.elevation = np.radians(elevation_deg)

    def pose(self, t):
        th = self.phase0 + 2 * np.pi * t / self.period
        el = self.elevation + np.radians(12.0) * np.sin(2 * th)
        d = self.radius / np.cos(el)  # slant distance
        p = self.centre + d * np.array([np.cos(el) * np.cos(th), np.cos(el) * np.sin(th), np.sin(el)])
        return p, look_at_quat(p, self.centre)

    def _set(self, model, data):
        m = model.body_mocapid[model.body("camera_rig").id]
        p, q = self.pose(float(data.time))
        data.mocap_pos[m] = p
        data.mocap_quat[m] = q

    def reset(self, model, data):
        self._set(model, data)

    def apply(self, model, data):
        self._set(model, data)

    def after_step(self, model, data):
        self._set(model, data)
        mujoco.mj_kinematics(model, data)
        mujoco.mj_camlight(model, data)

    def truth(self, model, data):
        return {"in_contact": False, "grasped": False, "held": None, "phase": "orbit", "light_scale": 1.0}


STAND_Z = 0.5


def build_object_orbit(spec: mujoco.MjSpec, seed: int, *, object=None, radius=0.8, elevation_deg=30.0,
                       period=10.0):
    """``object_orbit``: one object on a stand, the RGB-D camera circling it.

    Options: ``object`` (a name from :func:`polar_sim.sim.builders.objects.object_names`, default from the
    seed), ``radius`` (horizontal distance of the camera from the object, 0.5-1.5 m),
    ``elevation_deg`` (mean camera elevation, 5-60 deg), ``period`` (seconds per turn, > 0).
    The object is welded to the stand (no joint): it belongs to the static scene, so
    ``World.sdf`` includes it exactly.
    """
    names = _objects.object_names()
    if object is not None:
        _check(object, tuple(names), "object")
    for val, lo, hi, nm in ((radius, 0.5, 1.5, "radius"), (elevation_deg, 5.0, 60.0, "elevation_deg"),
                            (period, 1e-3, 1e6, "period")):
        if isinstance(val, bool) or not isinstance(val, (int, float, np.number)) or not lo <= val <= hi:
            raise ValueError(f"{nm}: expected a number in [{lo}, {hi}], got {val!r}")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7102]))
    if object is None:
        object = str(rng.choice(names))
    palette = [c for c in COLOURS if c != "skin"]
    base, accent = (str(c) for c in rng.choice(palette, 2, replace=False))
    _add_texture(spec, f"tex_{object}", object_texture(COLOURS[base], COLOURS[accent], rng))
    _add_object(spec, object, (0.0, 0.0, STAND_Z), rng.uniform(-np.pi, np.pi), f"tex_{object}",
                target=True, free=False)
    top = float(_objects.load_mesh(object).vertices[:, 2].max())
    centre = (0.0, 0.0, STAND_Z + 0.5 * top)
    script = OrbitScript(centre, radius, elevation_deg, period, rng.uniform(0, 2 * np.pi))
    return {"objects": [object], "target": object, "control_dt": CONTROL_DT, "script": script,
            "script_name": "orbit", "colours": {object: [base, accent]}, "centre": list(centre)}
