"""The manipulated objects of the tabletop scenes: watertight meshes made with trimesh.

Each object is one closed, outward-oriented triangle mesh in metres. **Object frame: z up, the
origin on the plane the object stands on (its lowest point is at z = 0), under the centre of
its main body** (the axis of the revolved mug, can and bottle; the centre of the box and the
cube; the centre of the drill's battery; the middle of the bracket's foot), so an object
standing upright on a table at height ``h`` has its body at ``z = h``. The meshes ship as OBJ files in ``scenes/assets/objects/`` (with texture coordinates
into a 2x2 texture atlas, see :data:`ATLAS_TILES`); regenerate them with

    python -m polar_sim.sim.builders.objects

(generation needs ``manifold3d`` for the boolean unions; loading does not). MuJoCo renders and
ray-casts the true mesh, but collides a mesh through its convex hull, so every object also lists
**collision primitives** (boxes and cylinders, :attr:`ObjectInfo.collision`) that the scenes add
as hidden geoms; the visual mesh itself has ``contype = conaffinity = 0``.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import numpy as np
import trimesh

from polar_sim import geometry

__all__ = ["OBJECTS", "DEFAULT_OBJECTS", "PARTS", "ObjectInfo", "object_names", "object_info", "load_mesh", "make_mesh",
           "write_assets", "asset_dir", "asset_path", "diameter", "ATLAS_TILES"]

logger = logging.getLogger(__name__)

#: Texture atlas tiles (2x2 in UV space): which part of an object samples which tile. The scene
#: builder paints each tile (tabletop.object_texture); the OBJ texture coordinates select them.
ATLAS_TILES = {"body": 0, "accent": 1, "label": 2, "dark": 3}
_MARGIN = 0.03  # UV inset of each tile, so that bilinear filtering never bleeds across tiles


@dataclasses.dataclass(frozen=True)
class ObjectInfo:
    """A catalogue entry.

    Attributes
    ----------
    name : str
    description : str
    collision : tuple of dict
        Primitives in the object frame: ``{"type": "box", "size": half sizes (3,), "pos": (3,)}``
        or ``{"type": "cylinder", "size": (radius, half_height), "pos": (3,), "axis": "z"|"x"}``;
        an optional ``"mass_frac"`` sets a primitive's share of the mass (default: by volume; the
        drill's battery is heavy, as on a real one).
    mass : float
        kg.
    grasp_halfwidth : float
        Half the object's width (m) along the hand's grasp direction at the fingers' height, for
        a top grasp with the fingers on the object's -y side (object frame).
    symmetry : str
        ``"none"`` or ``"z-continuous"`` (rotationally symmetric about z: score with ADD-S).
    """

    name: str
    description: str
    collision: tuple
    mass: float
    grasp_halfwidth: float
    symmetry: str = "none"


# -- mesh helpers ----------------------------------------------------------------------------

def _revolve(profile, sections=48):
    """Closed surface of revolution about z from a profile ``[(r, z), ...]`` that starts and ends
    on the axis (r = 0), listed from the bottom of the outside up. Returns a trimesh."""
    prof = np.asarray(profile, dtype=np.float64)
    ang = np.linspace(0, 2 * np.pi, sections, endpoint=False)
    verts, rings = [], []
    for r, z in prof:
        if r <= 1e-12:
            rings.append([len(verts)])
            verts.append([0.0, 0.0, z])
        else:
            idx = list(range(len(verts), len(verts) + sections))
            verts.extend(np.stack([r * np.cos(ang), r * np.sin(ang), np.full(sections, z)], 1))
            rings.append(idx)
    faces = []
    for a, b in zip(rings[:-1], rings[1:]):
        for k in range(sections):
            k1 = (k + 1) % sections
            if len(a) == 1:
                faces.append([a[0], b[k], b[k1]])
            elif len(b) == 1:
                faces.append([a[k], b[0], a[k1]])
            else:
                faces.append([a[k], b[k], b[k1]])
                faces.append([a[k], b[k1], a[k1]])
    return _outward(trimesh.Trimesh(np.array(verts), np.array(faces), process=True))


def _tube(path, radius, sides=16):
    """Closed tube of ``radius`` along a polyline ``path`` (k, 3) lying in the xz-plane, capped."""
    path = np.asarray(path, dtype=np.float64)
    tang = np.gradient(path, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    y = np.array([0.0, 1.0, 0.0])
    nrm = np.cross(tang, y)
    ang = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    verts = []
    for p, n in zip(path, nrm):
        verts.extend(p + radius * (np.cos(ang)[:, None] * n + np.sin(ang)[:, None] * y))
    k = len(path)
    faces = []
    for i in range(k - 1):
        for j in range(sides):
            a, b = i * sides + j, i * sides + (j + 1) % sides
            faces += [[a, b, b + sides], [a, b + sides, a + sides]]
    c0, c1 = len(verts), len(verts) + 1
    verts += [path[0], path[-1]]
    for j in range(sides):
        faces.append([c0, (j + 1) % sides, j])
        faces.append([c1, (k - 1) * sides + j, (k - 1) * sides + (j + 1) % sides])
    return _outward(trimesh.Trimesh(np.array(verts), np.array(faces), process=True))


def _outward(mesh):
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def _box(extents, centre, rot=None):
    m = trimesh.creation.box(extents=extents)
    if rot is not None:
        m.apply_transform(rot)
    m.apply_translation(centre)
    return m


def _cyl_x(radius, x0, x1, z, sections=40):
    m = trimesh.creation.cylinder(radius=radius, height=x1 - x0, sections=sections)
    m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    m.apply_translation([(x0 + x1) / 2, 0.0, z])
    return m


def _union(parts):
    out = trimesh.boolean.union(parts, engine="manifold")
    out.merge_vertices()
    return _outward(out)


def _smooth_profile(points, n=6):
    """Insert ``n`` Catmull-Rom points between consecutive profile points (r, z)."""
    p = np.asarray(points, dtype=np.float64)
    out = []
    for i in range(len(p) - 1):
        p0, p1, p2, p3 = p[max(i - 1, 0)], p[i], p[i + 1], p[min(i + 2, len(p) - 1)]
        for t in np.linspace(0, 1, n, endpoint=False):
            out.append(0.5 * ((2 * p1) + (-p0 + p2) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t ** 2
                              + (-p0 + 3 * p1 - 3 * p2 + p3) * t ** 3))
    out.append(p[-1])
    return np.array(out)


# -- the catalogue ---------------------------------------------------------------------------

_MUG_R, _MUG_H, _MUG_WALL, _MUG_BOTTOM = 0.040, 0.095, 0.0045, 0.008


def _mug():
    R, H, w, b = _MUG_R, _MUG_H, _MUG_WALL, _MUG_BOTTOM
    body = _revolve([(0, 0), (R - 0.003, 0), (R, 0.003), (R, H), (R - w, H), (R - w, b), (0, b)], 64)
    phi = np.linspace(0, np.pi, 28)
    x_end = R - w / 2  # the handle's ends sit inside the wall, never in the cavity
    path = np.stack([x_end + 0.030 * np.sin(phi), np.zeros_like(phi), 0.050 - 0.028 * np.cos(phi)], 1)
    handle = _tube(path, 0.0065, 16)
    return _union([body, handle])


def _box_obj():
    return _box([0.10, 0.055, 0.16], [0, 0, 0.08])


def _can():
    return _revolve([(0, 0), (0.029, 0), (0.033, 0.005), (0.033, 0.113), (0.030, 0.120),
                     (0.027, 0.120), (0.027, 0.117), (0, 0.117)], 56)


def _bottle():
    shoulder = _smooth_profile([(0.036, 0.120), (0.034, 0.140), (0.026, 0.160), (0.016, 0.176),
                                (0.013, 0.186), (0.013, 0.198)], 3)
    prof = np.vstack([[(0, 0), (0.034, 0.0), (0.036, 0.004)], shoulder,
                      [(0.016, 0.198), (0.016, 0.222), (0.0, 0.222)]])
    return _revolve(prof, 40)


def _drill():
    tilt = trimesh.transformations.rotation_matrix(np.radians(-12), [0, 1, 0])
    parts = [
        _box([0.075, 0.062, 0.030], [0.0, 0.0, 0.015]),                 # battery
        _box([0.038, 0.034, 0.125], [0.006, 0.0, 0.090], tilt),        # grip
        _cyl_x(0.029, -0.060, 0.095, 0.165),                           # motor housing
        _cyl_x(0.016, 0.094, 0.128, 0.165, 32),                        # chuck
        _cyl_x(0.004, 0.127, 0.165, 0.165, 16),                        # bit
    ]
    return _union(parts)


def _bracket():
    parts = [
        _box([0.12, 0.05, 0.010], [0.0, 0.0, 0.005]),                  # foot plate
        _box([0.012, 0.05, 0.10], [-0.054, 0.0, 0.050]),               # upright plate
        _box([0.03, 0.008, 0.03], [-0.036, 0.0, 0.018],
             trimesh.transformations.rotation_matrix(np.radians(45), [0, 1, 0])),  # gusset
    ]
    below = _box([1.0, 1.0, 1.0], [0.0, 0.0, -0.5])  # cut the gusset's corner off below z = 0
    m = trimesh.boolean.difference([_union(parts), below], engine="manifold")
    m.merge_vertices()
    return _outward(m)


def _cube():
    return _box([0.045, 0.045, 0.045], [0, 0, 0.0225])


# blocks: a box body, a round post standing on it and a small block on its other end
_BLK_BODY = (0.14, 0.075, 0.06)            # extents x, y, z of the body (m)
_BLK_POST = (0.014, 0.085, 0.035)          # radius, height, x of the post's axis
_BLK_CUBE = (0.04, -0.04)                  # edge and x of the small block's centre


def _blocks():
    bx, by, bz = _BLK_BODY
    r, h, xp = _BLK_POST
    e, xc = _BLK_CUBE
    post = trimesh.creation.cylinder(radius=r, height=h + 0.004, sections=40)
    post.apply_translation([xp, 0.0, bz + h / 2 - 0.002])  # sunk 4 mm into the body: one solid
    return _union([_box([bx, by, bz], [0, 0, bz / 2]), post, _box([e, e, e], [xc, 0.0, bz + e / 2 - 0.002])])


def _cyl(r, h, z0=0.0):
    return {"type": "cylinder", "size": (r, h / 2), "pos": (0.0, 0.0, z0 + h / 2), "axis": "z"}


def _bx(half, pos):
    return {"type": "box", "size": tuple(half), "pos": tuple(pos)}


OBJECTS = {
    "mug": ObjectInfo("mug", "mug with a handle (non-convex, hollow)",
                      (_cyl(_MUG_R, _MUG_H), _bx((0.0135, 0.0065, 0.034), (_MUG_R + 0.016, 0, 0.050))),
                      0.30, _MUG_R),
    "box": ObjectInfo("box", "printed carton box 10 x 5.5 x 16 cm", (_bx((0.05, 0.0275, 0.08), (0, 0, 0.08)),),
                      0.25, 0.0275),
    "can": ObjectInfo("can", "drink can with a labelled side", (_cyl(0.033, 0.120),), 0.35, 0.033,
                      "z-continuous"),
    "bottle": ObjectInfo("bottle", "bottle with shoulder, neck and cap (revolved profile)",
                         (_cyl(0.036, 0.135), _cyl(0.024, 0.045, 0.135), _cyl(0.016, 0.042, 0.180)),
                         0.40, 0.020, "z-continuous"),
    "drill": ObjectInfo("drill", "drill-like composite: battery, grip, housing, chuck (non-convex)",
                        (dict(_bx((0.0375, 0.031, 0.015), (0, 0, 0.015)), mass_frac=0.5),
                         dict(_bx((0.019, 0.017, 0.055), (0.010, 0, 0.085)), mass_frac=0.15),
                         {"type": "cylinder", "size": (0.029, 0.0775), "pos": (0.0175, 0, 0.165), "axis": "x",
                          "mass_frac": 0.3},
                         {"type": "cylinder", "size": (0.016, 0.035), "pos": (0.128, 0, 0.165), "axis": "x",
                          "mass_frac": 0.05}),
                        0.60, 0.031),
    "bracket": ObjectInfo("bracket", "L-bracket with a gusset (non-convex)",
                          (_bx((0.06, 0.025, 0.005), (0, 0, 0.005)), _bx((0.006, 0.025, 0.05), (-0.054, 0, 0.05))),
                          0.20, 0.025),
    "cube": ObjectInfo("cube", "small 4.5 cm cube (a small, indistinct shape)",
                       (_bx((0.0225, 0.0225, 0.0225), (0, 0, 0.0225)),), 0.08, 0.0225),
    "blocks": ObjectInfo("blocks", "three primitives: a box body, a round post, a small block (one colour each)",
                         (_bx((_BLK_BODY[0] / 2, _BLK_BODY[1] / 2, _BLK_BODY[2] / 2), (0, 0, _BLK_BODY[2] / 2)),
                          _cyl(_BLK_POST[0], _BLK_POST[1], _BLK_BODY[2]) | {"pos": (_BLK_POST[2], 0.0,
                                                                                 _BLK_BODY[2] + _BLK_POST[1] / 2)},
                          _bx((_BLK_CUBE[0] / 2,) * 3, (_BLK_CUBE[1], 0.0, _BLK_BODY[2] + _BLK_CUBE[0] / 2))),
                         0.30, _BLK_BODY[1] / 2),
}
#: The objects a ``tabletop`` scene draws from when no target is named (the catalogue before
#: ``blocks`` was added: keeping this list fixed keeps every seed's scene as it was).
DEFAULT_OBJECTS = ("mug", "box", "can", "bottle", "drill", "bracket", "cube")
#: Objects made of parts that each sample their own atlas tile: part name -> tile.
PARTS = {"blocks": {"body": ATLAS_TILES["body"], "post": ATLAS_TILES["accent"], "block": ATLAS_TILES["label"]}}

_BUILDERS = {"mug": _mug, "box": _box_obj, "can": _can, "bottle": _bottle, "drill": _drill,
             "bracket": _bracket, "cube": _cube, "blocks": _blocks}
_REVOLVED = {"mug", "can", "bottle"}


def object_names():
    """Names of the catalogue's objects, in catalogue order."""
    return list(OBJECTS)


def object_info(name) -> ObjectInfo:
    """The :class:`ObjectInfo` of ``name``; ``ValueError`` listing the valid names otherwise."""
    if name not in OBJECTS:
        raise ValueError(f"object: unknown object {name!r}; expected one of {', '.join(OBJECTS)}")
    return OBJECTS[name]


def make_mesh(name) -> trimesh.Trimesh:
    """Build the mesh of ``name`` from scratch (needs manifold3d for the composite objects)."""
    object_info(name)
    m = _BUILDERS[name]()
    if not m.is_watertight or m.volume <= 0:
        raise RuntimeError(f"object {name!r}: generated mesh is not a closed outward surface")
    return m


# -- texture coordinates ---------------------------------------------------------------------

def _face_tiles(name, mesh):
    """Atlas tile per face: which part of the object a face belongs to."""
    c = mesh.triangles_center
    n = mesh.face_normals
    r = np.hypot(c[:, 0], c[:, 1])
    tile = np.full(len(c), ATLAS_TILES["body"])
    if name == "mug":
        inner = (r < _MUG_R - _MUG_WALL / 2) & (c[:, 2] > _MUG_BOTTOM - 1e-6)
        tile[inner] = ATLAS_TILES["accent"]
    elif name == "box":
        tile[np.abs(n[:, 1]) > 0.9] = ATLAS_TILES["label"]
    elif name == "can":
        side = np.abs(n[:, 2]) < 0.5
        tile[:] = ATLAS_TILES["dark"]
        tile[side & (c[:, 2] > 0.012) & (c[:, 2] < 0.108)] = ATLAS_TILES["label"]
    elif name == "bottle":
        tile[(np.abs(n[:, 2]) < 0.5) & (c[:, 2] > 0.035) & (c[:, 2] < 0.105)] = ATLAS_TILES["label"]
        tile[c[:, 2] > 0.197] = ATLAS_TILES["accent"]
    elif name == "drill":
        grip = (c[:, 2] < 0.136) | (c[:, 0] > 0.093)
        tile[grip] = ATLAS_TILES["dark"]
    elif name == "cube":
        tile[n[:, 2] > 0.9] = ATLAS_TILES["accent"]
    elif name == "blocks":
        above = c[:, 2] > _BLK_BODY[2] + 1e-6
        tile[above & (c[:, 0] > 0)] = ATLAS_TILES["accent"]  # the post
        tile[above & (c[:, 0] < 0)] = ATLAS_TILES["label"]   # the small block
    return tile


def _face_uv(name, mesh):
    """Texture coordinates per face corner (n_faces, 3, 2) into the 2x2 atlas."""
    V, F = mesh.vertices, mesh.faces
    n = mesh.face_normals
    lo, hi = mesh.bounds
    ext = np.maximum(hi - lo, 1e-9)
    tri = V[F]  # (f, 3, 3)
    uv = np.zeros(F.shape + (2,))
    cyl = (name in _REVOLVED) & (np.abs(n[:, 2]) < 0.7)
    # Cylindrical projection of the sides of revolved objects; the seam lies on the object's +y.
    cen = tri.mean(1)
    a_c = np.arctan2(cen[:, 0], -cen[:, 1])
    a = np.arctan2(tri[..., 0], -tri[..., 1])
    rr = np.hypot(tri[..., 0], tri[..., 1])
    a = np.where(rr > 1e-9, a, a_c[:, None])
    a = a_c[:, None] + (a - a_c[:, None] + np.pi) % (2 * np.pi) - np.pi
    uv_cyl = np.stack([(a + np.pi) / (2 * np.pi), (tri[..., 2] - lo[2]) / ext[2]], -1)
    # Planar projection along each face's dominant axis elsewhere.
    k = np.argmax(np.abs(n), axis=1)
    axes = np.array([[1, 2], [0, 2], [0, 1]])[k]  # (f, 2)
    norm = (tri - lo) / ext
    uv_pl = np.take_along_axis(norm, np.broadcast_to(axes[:, None, :], (len(F), 3, 2)), axis=2)
    uv = np.where(cyl[:, None, None], uv_cyl, uv_pl)
    uv = np.clip(uv, 0.0, 1.0)
    tile = _face_tiles(name, mesh)
    t0 = np.stack([(tile % 2) * 0.5, (tile // 2) * 0.5], 1)[:, None, :]
    return t0 + _MARGIN + uv * (0.5 - 2 * _MARGIN)


# -- files -----------------------------------------------------------------------------------

def asset_dir() -> Path:
    """``scenes/assets/objects`` of the installed scenes."""
    from polar_sim.sim.scenes import scene_dir

    return scene_dir() / "assets" / "objects"


def asset_path(name) -> Path:
    """Path of the OBJ file of object ``name``."""
    object_info(name)
    return asset_dir() / f"{name}.obj"


def _write_obj(path, mesh, uv):
    uvq = np.round(uv.reshape(-1, 2), 4)
    uniq, inv = np.unique(uvq, axis=0, return_inverse=True)
    inv = inv.reshape(-1, 3)
    lines = [f"# polar_sim object mesh: metres, origin at the base centre, z up ({len(mesh.faces)} faces)"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.vertices]
    lines += [f"vt {u:.4f} {v:.4f}" for u, v in uniq]
    for f, t in zip(mesh.faces + 1, inv + 1):
        lines.append(f"f {f[0]}/{t[0]} {f[1]}/{t[1]} {f[2]}/{t[2]}")
    Path(path).write_text("\n".join(lines) + "\n")


def write_assets(out_dir=None):
    """Write every object's OBJ file (mesh and texture coordinates) into ``out_dir``
    (default: :func:`asset_dir`). Returns the written paths."""
    out = Path(out_dir) if out_dir is not None else asset_dir()
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name in OBJECTS:
        mesh = make_mesh(name)
        p = out / f"{name}.obj"
        _write_obj(p, mesh, _face_uv(name, mesh))
        paths.append(p)
        logger.info("wrote %s (%d faces, %.1f kB)", p, len(mesh.faces), p.stat().st_size / 1e3)
    return paths


def load_mesh(name) -> trimesh.Trimesh:
    """The shipped mesh of object ``name`` (object frame, metres), exactly as MuJoCo loads it."""
    p = asset_path(name)
    if not p.is_file():
        raise FileNotFoundError(f"object: mesh file {str(p)!r} is missing; regenerate it with "
                                "`python -m polar_sim.sim.builders.objects`")
    V, F = [], []
    for line in p.read_text().splitlines():
        if line.startswith("v "):
            V.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            F.append([int(tok.split("/")[0]) - 1 for tok in line.split()[1:4]])
    return trimesh.Trimesh(np.array(V), np.array(F), process=False)


def diameter(mesh) -> float:
    """Largest distance (m) between two vertices of a mesh (:func:`polar_sim.geometry.diameter`)."""
    return geometry.diameter(mesh.vertices)


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    write_assets()
