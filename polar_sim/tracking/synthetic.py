"""A small synthetic RGB-D renderer for tests, benchmarks and examples (no MuJoCo).

Triangle meshes are rasterised with a z-buffer (numba) into planar metric depth, per-pixel part
labels and Lambert-shaded RGB. :func:`make_sequence` builds a hand-held object sequence on a
checkered table: the object moves and turns, and a skin-coloured "hand" rigidly attached to it
touches its camera-facing side. It is a stand-in for the simulator's ``tabletop`` sequences, good
enough to exercise every code path with exact truth (pose, visible mask, hand mask).

Conventions: OpenCV camera axes, pixel centres at integer coordinates, depth along the optical axis
in metres (0 = missing), poses ``T_cam_obj`` map object to camera coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh
from numba import njit

from polar_sim.geometry import inv_pose, make_pose, pinhole_intrinsics, so3_exp, transform_points

__all__ = [
    "Part",
    "make_object",
    "make_hand",
    "make_table",
    "look_at",
    "render",
    "sample_model",
    "kinect_noise",
    "Sequence",
    "make_sequence",
]

#: Label values in the label image returned by :func:`render` for :func:`make_sequence` scenes.
BACKGROUND, TABLE, TARGET, HAND, OCCLUDER = -1, 0, 1, 2, 3


@dataclass
class Part:
    """A coloured triangle mesh: vertices (V, 3) m in its own frame, faces (F, 3), colours (F, 3) uint8."""

    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray
    label: int = 0

    @classmethod
    def from_trimesh(cls, mesh, colors, label=0):
        colors = np.broadcast_to(np.asarray(colors, dtype=np.uint8), (len(mesh.faces), 3)).copy()
        return cls(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), colors, label)

    @property
    def mesh(self):
        """The part as a ``trimesh.Trimesh`` (no processing, so faces keep their order)."""
        return trimesh.Trimesh(self.vertices, self.faces, process=False)


def _stripes(mesh, base, stripe, axis=2, period=0.03):
    """Face colours: ``base`` with bands of ``stripe`` every ``period`` metres along ``axis``."""
    c = mesh.triangles_center[:, axis]
    band = (np.floor(c / (period / 2.0)).astype(int) % 2) == 1
    cols = np.tile(np.asarray(base, np.uint8), (len(mesh.faces), 1))
    cols[band] = stripe
    return cols


def make_object(name="mug"):
    """One of the test objects as a :class:`Part` (label TARGET), object frame at its base centre.

    ``"mug"``: open cylinder 8 cm wide, 10 cm high, with a torus handle (non-convex); ``"box"``:
    12 x 8 x 6 cm; ``"cylinder"``: 7 cm wide, 14 cm high (rotationally symmetric).
    """
    if name == "mug":
        body = trimesh.creation.annulus(0.034, 0.04, 0.10, sections=48)
        body.apply_translation([0, 0, 0.05])
        bottom = trimesh.creation.cylinder(0.034, 0.008, sections=48)
        bottom.apply_translation([0, 0, 0.004])
        handle = trimesh.creation.torus(0.025, 0.007, major_sections=32, minor_sections=12)
        handle.apply_transform(make_pose(so3_exp([np.pi / 2, 0, 0]), [0.058, 0, 0.05]))
        body = body.subdivide_to_size(0.012)
        mesh = trimesh.util.concatenate([body, bottom, handle])
        cols = _stripes(mesh, (200, 40, 40), (235, 235, 225), period=0.04)
        hidx = len(body.faces) + len(bottom.faces)
        cols[hidx:] = (40, 60, 190)
    elif name == "box":
        mesh = trimesh.creation.box([0.12, 0.08, 0.06])
        mesh.apply_translation([0, 0, 0.03])
        mesh = mesh.subdivide().subdivide()
        cols = _stripes(mesh, (30, 140, 200), (240, 200, 40), axis=0, period=0.04)
    elif name == "cylinder":
        mesh = trimesh.creation.cylinder(0.035, 0.14, sections=48)
        mesh.apply_translation([0, 0, 0.07])
        mesh = mesh.subdivide_to_size(0.012)
        cols = _stripes(mesh, (60, 170, 60), (250, 250, 250), period=0.05)
    else:
        raise ValueError(f"name: unknown object {name!r}; expected 'mug', 'box' or 'cylinder'")
    return Part.from_trimesh(mesh, cols, TARGET)


def make_hand(color=(225, 170, 140)):
    """A box hand (skin-coloured by default): palm 4.5 x 2 x 6 cm and two fingers, frame at the
    palm's back face centre."""
    palm = trimesh.creation.box([0.045, 0.02, 0.06])
    palm.apply_translation([0, -0.01, 0])
    f1 = trimesh.creation.box([0.016, 0.016, 0.05])
    f1.apply_translation([0.012, -0.008, 0.055])
    f2 = trimesh.creation.box([0.016, 0.016, 0.04])
    f2.apply_translation([-0.01, -0.008, 0.05])
    mesh = trimesh.util.concatenate([palm, f1, f2])
    return Part.from_trimesh(mesh, color, HAND)


def make_table(size=1.2, cells=12):
    """A checkered table top (z = 0, size x size metres) as a :class:`Part` with label TABLE."""
    xs = np.linspace(-size / 2, size / 2, cells + 1)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    faces, cols = [], []
    for i in range(cells):
        for j in range(cells):
            a = i * (cells + 1) + j
            b, c, d = a + 1, a + cells + 1, a + cells + 2
            col = (150, 130, 100) if (i + j) % 2 else (120, 105, 85)
            faces += [(a, c, b), (b, c, d)]
            cols += [col, col]
    return Part(V, np.array(faces, np.int64), np.array(cols, np.uint8), TABLE)


def look_at(eye, target, up=(0.0, 0.0, 1.0)):
    """Pose ``T_world_cam`` (4, 4) of an OpenCV camera at ``eye`` looking at ``target`` (metres)."""
    eye, target, up = (np.asarray(a, float) for a in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_pose(np.stack([x, y, z], 1), eye)



@njit(cache=True)
def _raster(V, F, fx, fy, cx, cy, zbuf, fid, near):
    H, W = zbuf.shape
    for f in range(F.shape[0]):
        ia, ib, ic = F[f, 0], F[f, 1], F[f, 2]
        za, zb, zc = V[ia, 2], V[ib, 2], V[ic, 2]
        if za < near or zb < near or zc < near:
            continue
        ua = fx * V[ia, 0] / za + cx
        va = fy * V[ia, 1] / za + cy
        ub = fx * V[ib, 0] / zb + cx
        vb = fy * V[ib, 1] / zb + cy
        uc = fx * V[ic, 0] / zc + cx
        vc = fy * V[ic, 1] / zc + cy
        area = (ub - ua) * (vc - va) - (vb - va) * (uc - ua)
        if abs(area) < 1e-12:
            continue
        x0 = max(0, int(np.ceil(min(ua, ub, uc))))
        x1 = min(W - 1, int(np.floor(max(ua, ub, uc))))
        y0 = max(0, int(np.ceil(min(va, vb, vc))))
        y1 = min(H - 1, int(np.floor(max(va, vb, vc))))
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                w0 = ((ub - x) * (vc - y) - (vb - y) * (uc - x)) / area
                w1 = ((uc - x) * (va - y) - (vc - y) * (ua - x)) / area
                w2 = 1.0 - w0 - w1
                if w0 < -1e-9 or w1 < -1e-9 or w2 < -1e-9:
                    continue
                z = 1.0 / (w0 / za + w1 / zb + w2 / zc)
                if z < zbuf[y, x]:
                    zbuf[y, x] = z
                    fid[y, x] = f


def render(parts, poses, K, shape, *, light=(0.3, -0.5, -1.0), ambient=0.35):
    """Rasterise coloured parts into (rgb, depth, labels).

    Parameters
    ----------
    parts : list of Part
    poses : list of ndarray (4, 4)
        ``T_cam_part`` for each part.
    K : ndarray (3, 3)
    shape : (H, W)
    light : direction (3,) in the camera frame the light travels along.

    Returns
    -------
    rgb : (H, W, 3) uint8, depth : (H, W) float32 m (0 where nothing), labels : (H, W) int8
    (the part's ``label``, BACKGROUND where nothing).
    """
    H, W = shape
    Vs, Fs, Cs, Ls, off = [], [], [], [], 0
    for part, T in zip(parts, poses):
        Vs.append(transform_points(T, part.vertices))
        Fs.append(part.faces + off)
        Cs.append(part.colors)
        Ls.append(np.full(len(part.faces), part.label, np.int8))
        off += len(part.vertices)
    V, F = np.concatenate(Vs), np.concatenate(Fs)
    zbuf = np.full((H, W), np.inf)
    fid = np.full((H, W), -1, np.int64)
    _raster(V, F, K[0, 0], K[1, 1], K[0, 2], K[1, 2], zbuf, fid, 1e-3)
    tri = V[F]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    ldir = -np.asarray(light, float) / np.linalg.norm(light)
    shade = ambient + (1 - ambient) * np.abs(n @ ldir)
    face_rgb = np.clip(np.concatenate(Cs).astype(float) * shade[:, None], 0, 255)
    hit = fid >= 0
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[:] = (70, 80, 95)
    rgb[hit] = face_rgb[fid[hit]].astype(np.uint8)
    depth = np.where(hit, zbuf, 0.0).astype(np.float32)
    labels = np.full((H, W), BACKGROUND, np.int8)
    labels[hit] = np.concatenate(Ls)[fid[hit]]
    return rgb, depth, labels


def sample_model(part, n=3000, seed=0):
    """Area-uniform surface samples of a part: points (n, 3) and unit normals (n, 3), part frame."""
    mesh = part.mesh
    pts, fidx = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.asarray(pts, float), np.asarray(mesh.face_normals[fidx], float)


def kinect_noise(depth, rng, *, dropout=0.01, edge_jump=0.02):
    """Kinect-v1-like depth: axial noise 1.2 mm + 1.9 mm (z - 0.4)^2, 1 mm steps, edge and random dropout."""
    d = depth.astype(np.float64)
    valid = d > 0
    sig = 0.0012 + 0.0019 * (d - 0.4) ** 2
    noisy = np.round((d + rng.standard_normal(d.shape) * sig) * 1000.0) / 1000.0
    edge = np.zeros_like(valid)
    for ax in (0, 1):
        jump = np.abs(np.diff(d, axis=ax)) > edge_jump
        if ax == 0:
            edge[1:] |= jump
            edge[:-1] |= jump
        else:
            edge[:, 1:] |= jump
            edge[:, :-1] |= jump
    drop = edge | (rng.random(d.shape) < dropout) | ~valid
    return np.where(drop, 0.0, noisy).astype(np.float32)


@dataclass
class Sequence:
    """A rendered-on-demand synthetic RGB-D sequence with exact truth.

    ``frame(i)`` returns a dict with ``rgb``, ``depth`` (noisy), ``depth_clean``, ``labels``
    (BACKGROUND/TABLE/TARGET/HAND/OCCLUDER per pixel), ``mask`` (visible target), ``hand``
    (visible hand) and ``pose`` (T_cam_obj).
    """

    K: np.ndarray
    shape: tuple
    target: Part
    poses: np.ndarray
    hand_poses: np.ndarray | None
    T_world_cam: np.ndarray
    seed: int = 0
    noise: bool = True
    hidden: frozenset = frozenset()
    occluded: frozenset = frozenset()
    hand_color: tuple = (225, 170, 140)
    brightness: tuple = (1.0, 1.0)
    extras: list = field(default_factory=list)

    def __len__(self):
        return len(self.poses)

    def model(self, n=3000, seed=0):
        """Model points (n, 3) and normals (n, 3) of the target, object frame."""
        return sample_model(self.target, n, seed)

    def frame(self, i):
        T_cw = inv_pose(self.T_world_cam)
        parts, poses = [make_table()], [T_cw]
        if i not in self.hidden:
            parts.append(self.target)
            poses.append(self.poses[i])
        if i not in self.hidden and self.hand_poses is not None:
            parts.append(make_hand(self.hand_color))
            poses.append(self.hand_poses[i])
        if i in self.occluded:
            # a grey board between the camera and the object, 40% of the way: full occlusion
            board = trimesh.creation.box([0.3, 0.3, 0.01])
            parts.append(Part.from_trimesh(board, (128, 128, 128), OCCLUDER))
            c = self.poses[i][:3, 3]
            poses.append(make_pose(None, 0.6 * c))
        for part, T in self.extras:
            parts.append(part)
            poses.append(T)
        rgb, depth, labels = render(parts, poses, self.K, self.shape)
        b0, b1 = self.brightness
        if (b0, b1) != (1.0, 1.0):
            gain = b0 + (b1 - b0) * i / max(len(self) - 1, 1)
            rgb = np.clip(rgb * gain, 0, 255).astype(np.uint8)
        rng = np.random.default_rng([self.seed, i])
        out = {"depth_clean": depth, "labels": labels, "pose": self.poses[i].copy()}
        if self.noise:
            depth = kinect_noise(depth, rng)
            rgb = np.clip(rgb + rng.normal(0, 3.0, rgb.shape), 0, 255).astype(np.uint8)
        out.update(rgb=rgb, depth=depth, mask=labels == TARGET, hand=labels == HAND)
        return out


def make_sequence(n_frames=60, obj="mug", *, hand=True, speed=1.0, seed=0, shape=(480, 640),
                  noise=True, hidden=(), occluded=(), hand_color=(225, 170, 140), brightness=(1.0, 1.0)):
    """A hand-held object on a table seen from 0.7 m, 30 fps.

    The object starts at rest, then slides about 8 cm, lifts 3 cm and turns +-25 deg about its
    vertical axis, peaking near 7 cm/s and 30 deg/s (both times ``speed``); the hand holds its
    camera-facing side. Frames listed in ``hidden`` drop the object and the hand from the image
    (as if they left the view); frames in ``occluded`` put a board between the camera and the
    object (full occlusion): both for lost/recover tests. ``hand_color`` (RGB) makes the hand
    match the object if wanted; ``brightness`` = (first, last) ramps the image gain linearly over
    the sequence (a lighting change).
    """
    H, W = shape
    K = pinhole_intrinsics(W, H, 45.0)
    T_wc = look_at([0.0, -0.5, 0.4], [0.0, 0.0, 0.05])
    T_cw = inv_pose(T_wc)
    target = make_object(obj)
    poses, hposes = [], []
    # grasp: palm against the object's -y side (towards the camera), fingers up its front
    radius = {"mug": 0.04, "box": 0.04, "cylinder": 0.035}[obj]
    T_obj_hand = make_pose(None, [-0.03, -radius - 0.0005, 0.04])
    for i in range(n_frames):
        s = speed * i / 30.0
        s = s * s / (s + 1.0)  # starts at rest, reaches full speed after about a second (at speed 1)
        pos = [0.08 * np.sin(0.9 * s), 0.03 * np.sin(0.6 * s), 0.03 * (1 - np.cos(0.7 * s))]
        yaw = np.deg2rad(25) * np.sin(1.1 * s)
        tilt = np.deg2rad(8) * np.sin(0.8 * s)
        T_wo = make_pose(so3_exp([tilt, 0, yaw]), pos)
        T_co = T_cw @ T_wo
        poses.append(T_co)
        hposes.append(T_co @ T_obj_hand)
    return Sequence(K, (H, W), target, np.array(poses), np.array(hposes) if hand else None, T_wc,
                    seed, noise, frozenset(hidden), frozenset(occluded), tuple(hand_color),
                    tuple(brightness))


def check_data():
    """:class:`polar_sim.params.CheckData` of :class:`polar_sim.tracking.ObjectTracker`: three
    160x120 frames of the mug without the hand, 30 fps, and the model and first pose they need."""
    from polar_sim.params import CheckData

    seq = make_sequence(3, "mug", hand=False, seed=0, shape=(120, 160))
    pts, nrm = seq.model(800)
    frames = tuple((f["rgb"], f["depth"], i / 30) for i, f in enumerate(seq.frame(i) for i in range(3)))
    return CheckData(init={"model_points": pts, "K": seq.K, "initial_pose": seq.poses[0], "model_normals": nrm},
                     frames=frames)
