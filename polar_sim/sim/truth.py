"""Exact ground truth: per-geom labels, body poses and twists, geom meshes, and the scene SDF."""

from __future__ import annotations

import functools

import mujoco
import numpy as np
import trimesh
from matplotlib.path import Path as MplPath

from polar_sim.geometry import make_pose, quat_to_matrix
from polar_sim.sim import sdf as _sdf
from polar_sim.sim.actors.robots import GROUP

__all__ = ["LABELS", "name_of", "id_of", "label_table", "body_pose", "body_twist", "geom_trimesh", "body_trimesh",
           "SceneSDF", "static_geoms", "subtree"]

#: Per-pixel classes of ``CameraFrame.labels``.
LABELS = {"none": 0, "ground": 1, "obstacle": 2, "target": 3, "occluder": 4, "robot": 5}

_G = mujoco.mjtGeom


def name_of(model, obj, i):
    """Name of object ``i`` of type ``obj`` (an ``mjtObj``), "" if unnamed (``model.geom(i).name``
    without building the accessor, which costs a few hundred microseconds per call)."""
    return mujoco.mj_id2name(model, obj, i) or ""


def id_of(model, obj, name):
    """Id of the object of type ``obj`` named ``name``, -1 if there is none."""
    return mujoco.mj_name2id(model, obj, name)


def subtree(model, root_body):
    """Ids of ``root_body`` and all its descendants."""
    ids = [root_body]
    for b in range(root_body + 1, model.nbody):
        p = model.body_parentid[b]
        if p in ids and b not in ids:
            ids.append(b)
    return ids


def _is_ground(model, g):
    name = name_of(model, mujoco.mjtObj.mjOBJ_GEOM, g)
    return (model.geom_type[g] in (_G.mjGEOM_PLANE, _G.mjGEOM_HFIELD)
            or model.geom_group[g] == GROUP["ground"]
            or name.startswith(("ground", "terrain", "floor")))


def label_table(model, target=None):
    """Label (see :data:`LABELS`) of every geom id, as an int array of shape (ngeom,).

    Rules, first match wins: geoms of the body ``rover`` and its children are ``robot``; of a
    body whose name starts with ``hand`` (and children) ``occluder``; of the ``target`` body
    ``target``; ground planes, heightfields, the ground group and geoms named ground*/terrain*/
    floor* are ``ground``; everything else is ``obstacle``.
    """
    lut = np.full(model.ngeom, LABELS["obstacle"], dtype=np.int32)
    for g in range(model.ngeom):
        if _is_ground(model, g):
            lut[g] = LABELS["ground"]
    def mark(body_ids, label):
        for g in range(model.ngeom):
            if model.geom_bodyid[g] in body_ids:
                lut[g] = label
    if target is not None:
        mark(subtree(model, model.body(target).id), LABELS["target"])
    for b in range(model.nbody):
        if name_of(model, mujoco.mjtObj.mjOBJ_BODY, b).startswith("hand"):
            mark(subtree(model, b), LABELS["occluder"])
    rover = id_of(model, mujoco.mjtObj.mjOBJ_BODY, "rover")
    if rover >= 0:
        mark(subtree(model, rover), LABELS["robot"])
    return lut


def body_pose(data, body_id):
    """World pose (4, 4) of a body."""
    return make_pose(data.xmat[body_id].reshape(3, 3), data.xpos[body_id])


def body_twist(model, data, body_id):
    """Body twist (6,) = linear velocity (3,) then angular velocity (3,), both in the body frame.

    Linear velocity is that of the body frame's origin, m/s; angular in rad/s.
    """
    v = np.zeros(6)
    # (angular, linear) with world orientation, the linear part at the body's centre of mass
    # (MuJoCo's "local" option would use the principal axes of inertia, not the body frame).
    mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body_id, v, 0)
    w, v_com = v[:3], v[3:]
    v_origin = v_com + np.cross(w, data.xpos[body_id] - data.xipos[body_id])
    R = data.xmat[body_id].reshape(3, 3)
    return np.concatenate([R.T @ v_origin, R.T @ w])


def geom_trimesh(model, g):
    """A ``trimesh.Trimesh`` of geom ``g`` in its own frame (primitives tessellated finely)."""
    t = model.geom_type[g]
    s = model.geom_size[g]
    if t == _G.mjGEOM_MESH:
        mid = model.geom_dataid[g]
        v0, nv = model.mesh_vertadr[mid], model.mesh_vertnum[mid]
        f0, nf = model.mesh_faceadr[mid], model.mesh_facenum[mid]
        # MuJoCo stores mesh vertices in a frame centred on the mesh's inertia; the geom frame is
        # that frame, so the vertices are already geom-frame coordinates.
        return trimesh.Trimesh(model.mesh_vert[v0 : v0 + nv].copy(), model.mesh_face[f0 : f0 + nf].copy(),
                               process=False)
    if t == _G.mjGEOM_BOX:
        return trimesh.creation.box(extents=2 * s)
    if t == _G.mjGEOM_SPHERE:
        return trimesh.creation.icosphere(subdivisions=4, radius=s[0])
    if t == _G.mjGEOM_CYLINDER:
        return trimesh.creation.cylinder(radius=s[0], height=2 * s[1], sections=96)
    if t == _G.mjGEOM_CAPSULE:
        return trimesh.creation.capsule(radius=s[0], height=2 * s[1], count=[64, 32])
    if t == _G.mjGEOM_ELLIPSOID:
        m = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
        m.apply_scale(s)
        return m
    raise ValueError(f"geom {model.geom(g).name!r}: no mesh for geom type {int(t)}")


def body_trimesh(model, body_id, groups=(GROUP["static"], GROUP["dynamic"], GROUP["target"])):
    """All visible geoms of one body merged into a mesh in the body frame (the tracked object's
    visible geoms are in the target group)."""
    parts = []
    for g in range(model.ngeom):
        if model.geom_bodyid[g] != body_id or model.geom_group[g] not in groups:
            continue
        m = geom_trimesh(model, g)
        m.apply_transform(make_pose(quat_to_matrix(model.geom_quat[g]), model.geom_pos[g]))
        parts.append(m)
    if not parts:
        raise ValueError(f"body {model.body(body_id).name!r} has no visible geoms")
    return trimesh.util.concatenate(parts)


def static_geoms(model):
    """Geoms of the static scene: on bodies welded to the world (no joints, not mocap),
    visible (not in the hidden collision group), ground included."""
    static = np.ones(model.nbody, bool)
    for b in range(1, model.nbody):  # parents come before their children
        static[b] = (model.body_jntnum[b] == 0 and model.body_mocapid[b] < 0
                     and static[model.body_parentid[b]])
    keep = static[model.geom_bodyid] & (model.geom_group != GROUP["collision"])
    return np.flatnonzero(keep).tolist()


class SceneSDF:
    """Exact signed distance of the static scene, in 3D and in a horizontal section.

    Parameters
    ----------
    model, data : the compiled scene (static geoms do not move, so poses are read once).
    terrain : optional ``TerrainGrid``; when given, the ground tiles are represented by it
        exactly (distance to the triangulated surface, negative below it).
    """

    def __init__(self, model, data, terrain=None):
        self._terrain = terrain
        self._terrain_mesh = None
        ids = static_geoms(model)
        if terrain is not None:  # ground meshes are represented by the terrain grid
            ids = [g for g in ids if not (model.geom_type[g] == _G.mjGEOM_MESH and _is_ground(model, g))]
        self._ids = np.array(ids, dtype=np.int64)
        # The static geoms' poses, read once (they do not move).
        self._type = model.geom_type[self._ids].astype(np.int64)
        self._size = model.geom_size[self._ids].copy()
        self._R = data.geom_xmat[self._ids].reshape(-1, 3, 3).copy()
        self._x = data.geom_xpos[self._ids].copy()
        self._model = model
        self._meshes = {}
        self._sections = {}

    @functools.cached_property
    def _items(self):
        """(geom, type, size (3,), R (3, 3), position (3,), name) of every static geom."""
        return [(int(g), int(t), s, R, x, name_of(self._model, mujoco.mjtObj.mjOBJ_GEOM, int(g)))
                for g, t, s, R, x in zip(self._ids, self._type, self._size, self._R, self._x)]

    # -- 3D ---------------------------------------------------------------------------------
    def __call__(self, points, return_geom=False):
        """Signed distance (n,) at world points (n, 3), metres.

        With ``return_geom``, also the id (n,) of the geom whose surface is nearest (-1 for the
        terrain grid)."""
        out = np.full(len(points), np.inf)
        which = np.full(len(points), -1, dtype=np.int64)
        for g, t, s, R, x, _ in self._items:
            p = (points - x) @ R
            if t == _G.mjGEOM_BOX:
                d = _sdf.sdf_box(p, s)
            elif t == _G.mjGEOM_SPHERE:
                d = _sdf.sdf_sphere(p, s[0])
            elif t == _G.mjGEOM_CYLINDER:
                d = _sdf.sdf_cylinder(p, s[0], s[1])
            elif t == _G.mjGEOM_CAPSULE:
                d = _sdf.sdf_capsule(p, s[0], s[1])
            elif t == _G.mjGEOM_PLANE:
                d = _sdf.sdf_plane(p)
            else:
                d = self._mesh_sdf(g, p)
            closer = d < out
            which[closer] = g
            out[closer] = d[closer]
        if self._terrain is not None:
            d = self._terrain_sdf(points)
            closer = d < out
            which[closer] = -1
            out[closer] = d[closer]
        return (out, which) if return_geom else out

    def _mesh_sdf(self, g, p):
        if g not in self._meshes:
            m = geom_trimesh(self._model, g)
            if not m.is_watertight:
                raise ValueError(f"geom {self._model.geom(g).name!r}: mesh is not watertight, no signed distance")
            self._meshes[g] = m
        # trimesh's sign convention is positive inside.
        return -trimesh.proximity.signed_distance(self._meshes[g], p)

    def _terrain_sdf(self, points):
        grid = self._terrain
        if self._terrain_mesh is None:
            self._terrain_mesh = trimesh.Trimesh(grid.vertices(), grid.faces(), process=False)
        _, dist, _ = trimesh.proximity.closest_point(self._terrain_mesh, points)
        above = points[:, 2] >= grid.height(points[:, 0], points[:, 1])
        return np.where(above, dist, -dist)

    # -- 2D section -------------------------------------------------------------------------
    def _section_tables(self):
        """Vertical boxes, vertical cylinders/capsules and spheres as arrays (for the compiled
        section), and the remaining geoms for mesh sectioning; ground and planes left out."""
        if hasattr(self, "_tables"):
            return self._tables
        t, R = self._type, self._R
        ground = np.array([t_ == _G.mjGEOM_PLANE or _is_ground(self._model, int(g)) for g, t_ in zip(self._ids, t)],
                          dtype=bool)
        vertical = np.abs(np.abs(R[:, 2, 2]) - 1.0) < 1e-9
        box = ~ground & (t == _G.mjGEOM_BOX) & vertical
        disc = ~ground & ((t == _G.mjGEOM_SPHERE) | (np.isin(t, (_G.mjGEOM_CYLINDER, _G.mjGEOM_CAPSULE)) & vertical))
        bt = (self._x[box], R[box, :2, :2], self._size[box]) if box.any() else None
        dt = None
        if disc.any():
            kind = np.where(t[disc] == _G.mjGEOM_CYLINDER, 0, np.where(t[disc] == _G.mjGEOM_CAPSULE, 1, 2))
            dt = (self._x[disc], self._size[disc, 0], np.where(kind == 2, 0.0, self._size[disc, 1]), kind)
        rest = ~ground & ~box & ~disc
        other = [(int(g), R_, x) for g, R_, x in zip(self._ids[rest], R[rest], self._x[rest])]
        self._tables = (bt, dt, other)
        return self._tables

    def _cut(self, z):
        """The rectangles (k, 8) and discs (m, 3) of :func:`polar_sim.sim.sdf.section_boxes_discs`
        that the plane at height ``z`` cuts (kept while the cut shapes and radii stay the same)."""
        if getattr(self, "_cut_z", None) == z:
            return self._cut_tables
        boxes, discs, _ = self._section_tables()
        box_cut = np.abs(z - boxes[0][:, 2]) < boxes[2][:, 2] if boxes is not None else np.zeros(0, bool)
        radius = np.zeros(0)
        if discs is not None:
            c, r, hl, kind = discs
            dz = np.abs(z - c[:, 2])
            radius = np.full(len(r), -1.0)
            cyl = (kind == 0) & (dz < hl)
            radius[cyl] = r[cyl]
            cap = kind == 1
            body = cap & (dz <= hl)
            radius[body] = r[body]
            end = cap & (dz > hl) & (dz - hl < r)
            radius[end] = np.sqrt(r[end] ** 2 - (dz[end] - hl[end]) ** 2)
            sph = (kind == 2) & (dz < r)
            radius[sph] = np.sqrt(r[sph] ** 2 - dz[sph] ** 2)
        key = box_cut.tobytes() + radius.tobytes()
        if getattr(self, "_cut_key", None) != key:
            B = np.zeros((0, 8))
            if box_cut.any():
                c, R2, half = boxes
                B = np.ascontiguousarray(np.c_[c[box_cut, :2], R2[box_cut].reshape(-1, 4), half[box_cut, :2]])
            D = np.zeros((0, 3))
            if (radius > 0).any():
                cut = radius > 0
                D = np.ascontiguousarray(np.c_[discs[0][cut, :2], radius[cut]])
            self._cut_key, self._cut_tables = key, (B, D)
        self._cut_z = z
        return self._cut_tables

    def section(self, points2d, z):
        """Signed distance (n,) within the horizontal plane at height ``z`` of points (n, 2).

        Ground geoms are left out: the section is what a planar lidar at height ``z`` sees.
        Vertical boxes, cylinders and capsules and all spheres are exact closed forms (one
        compiled loop over every point and shape); any other shape is sectioned as a mesh (exact
        for meshes, 96-gon for tilted cylinders).
        """
        points2d = np.ascontiguousarray(points2d, dtype=np.float64)
        out = _sdf.section_boxes_discs(points2d, *self._cut(z))
        for g, R, x in self._section_tables()[2]:
            d = self._mesh_section(g, R, x, z, points2d)
            if d is not None:
                np.minimum(out, d, out=out)
        return out

    def section_stencil(self, offsets, pose, frame, z, step):
        """:func:`polar_sim.sim.sdf.section_stencil` in the plane at height ``z`` (pose and frame as
        (x, y, cos, sin) arrays, frame empty for the world; step 0 for no gradient), or None when
        the scene has shapes other than vertical boxes, discs and spheres (the caller then
        composes the points and calls :meth:`section` / :meth:`section_gradient`)."""
        if self._section_tables()[2]:
            return None
        return _sdf.section_stencil(offsets, pose, frame, *self._cut(z), float(step))

    def section_gradient(self, points2d, z, step):
        """Distance (n,) and gradient (n, 2) in the plane at height ``z``: the gradient is the
        central difference ``(f(p + step e) - f(p - step e)) / (2 step)`` per axis, step in m."""
        points2d = np.ascontiguousarray(points2d, dtype=np.float64)
        if not self._section_tables()[2]:
            return _sdf.section_boxes_discs_gradient(points2d, *self._cut(z), float(step))
        f = lambda p: self.section(p, z)  # noqa: E731
        h = float(step)
        gx = (f(points2d + [h, 0]) - f(points2d - [h, 0])) / (2 * h)
        gy = (f(points2d + [0, h]) - f(points2d - [0, h])) / (2 * h)
        return f(points2d), np.stack([gx, gy], 1)

    def _mesh_section(self, g, R, x, z, points2d):
        key = (g, round(z, 9))
        if key not in self._sections:
            m = geom_trimesh(self._model, g)
            m.apply_transform(make_pose(R, x))
            sec = m.section(plane_origin=[0, 0, z], plane_normal=[0, 0, 1])
            if sec is None:
                self._sections[key] = None
            else:
                loops = [np.asarray(d)[:, :2] for d in sec.discrete]
                segs = np.concatenate([np.stack([l[:-1], l[1:]], 1) for l in loops])
                self._sections[key] = (loops, segs)
        entry = self._sections[key]
        if entry is None:
            return None
        loops, segs = entry
        inside = np.zeros(len(points2d), bool)
        for l in loops:
            inside ^= MplPath(l).contains_points(points2d)
        return _sdf.sdf_polygons2d(points2d, segs, inside)
