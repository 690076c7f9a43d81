"""``World``: one MuJoCo scene with its sensors, its controller or script, and exact truth."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from polar_sim._validation import as_bool, as_float, as_float_array, as_int, as_positive_float, as_rng
from polar_sim.geometry import T_to_pose2d, make_pose, matrix_to_quat, pinhole_intrinsics
from polar_sim.sim import truth as _truth
from polar_sim.sim.actors.robots import RoverController
from polar_sim.sim.meta import RoverMeta, check_meta
from polar_sim.sim.scenes import load_scene
from polar_sim.sim.sensors import CameraFrame, CameraRig, DepthNoise, Lidar, RangeNoise, camera_pose, parse_lidars

__all__ = ["World"]

_OBJ = mujoco.mjtObj


def _slices_for(m, tol, radius=0.0):
    """Slices (<= 256) that draw every static cylinder and capsule (and one of ``radius`` m)
    within ``tol`` metres."""
    static = m.body_weldid[m.geom_bodyid] == 0
    round_ = np.isin(m.geom_type, (mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_CAPSULE))
    r = np.append(m.geom_size[static & round_, 0], radius)
    if r.max() <= tol:
        return 0
    return int(min(256, np.ceil(np.pi / np.arccos(1.0 - tol / r.max()))))


class World:
    """A simulated scene: load, reset, step, sense, and read exact ground truth.

    Parameters
    ----------
    scene : str or path
        A name from :func:`list_scenes` or a path to an MJCF file.
    seed : int
        Seed of the scene's procedural layout (textures, terrain, obstacles, objects) and of the
        sensor noise. The same seed builds the same world, bit for bit.
    kinematic : bool or "planar"
        Rover scenes only: move the rover by the exact unicycle model instead of the wheel
        physics (for unit tests and exact nonholonomic motion); MuJoCo still detects its
        contacts. On terrain the body follows the ground height and tilts with the local surface
        normal. ``"planar"`` (flat scenes, floor at z = 0): the same unicycle on the floor, with
        the body's orientation set in closed form from the heading, about 10x cheaper per step
        than ``True``, which derives it from a rotation matrix (through scipy) and is kept as it
        was for the recordings made with it; the two agree to within 1e-15.
    noise : dict, optional
        ``{sensor_name: RangeNoise(...) | DepthNoise(...)}``. Noise is off by default.
    control_dt : float, optional
        Control period of one :meth:`step`, seconds; a multiple of the physics timestep.
        Defaults to the scene's (0.1 s for the rover scenes, 1/30 s for the camera scenes).
    **scene_options
        Options of a named scene (see :func:`polar_sim.sim.scenes.scene_options`), e.g.
        ``camera_height=1.2`` for the rover scenes or ``script="push"`` for ``tabletop``.

    Attributes
    ----------
    cameras, lidars : tuple of str
        Sensor names in this scene.
    dt : float
        Control period of :meth:`step`, seconds.
    meta : polar_sim.sim.meta.SceneMeta
        The scene's metadata, a frozen dataclass per scene (:data:`polar_sim.sim.meta.SCENE_META`):
        ``w.meta.route`` (n, 2) for the rover scenes, ``w.meta.goal`` for navworld, ``w.meta.target``
        for tabletop, ...
    """

    def __init__(self, scene="rover_flat", seed=0, *, kinematic=False, noise=None, control_dt=None,
                 **scene_options):
        self.scene = scene
        self.seed = as_int(seed, "seed", minimum=0)
        planar = isinstance(kinematic, str) and kinematic == "planar"
        kinematic = True if planar else as_bool(kinematic, "kinematic")
        if noise is not None and not isinstance(noise, dict):
            raise TypeError(f"noise: expected a dict {{sensor name: noise model}} or None, got {type(noise).__name__}")
        if control_dt is not None:
            control_dt = as_positive_float(control_dt, "control_dt")
        spec, self.meta = load_scene(scene, self.seed, **scene_options)
        self._scene_options = dict(scene_options)
        try:
            self.model = spec.compile()
        except Exception as exc:
            raise ValueError(f"scene: {scene!r} does not compile: {exc}") from exc
        m = self.model
        _check_model(m, scene)
        # Cameras render primitives as polygons: a cylinder of radius r drawn with n slices lies up
        # to r (1 - cos(pi / n)) inside its exact surface, 2.7 mm for a 0.43 m round table at
        # MuJoCo's default 28. Use enough slices that the widest static cylinder or capsule is drawn
        # within 0.5 mm, so depth back-projects onto the exact geometry that lidar rays and sdf()
        # use; no more, since every slice costs frame rate (128 slices cut 640x480 by 30 %).
        m.vis.quality.numslices = max(int(m.vis.quality.numslices),
                                      _slices_for(m, tol=5e-4, radius=getattr(self.meta, "max_round_radius", 0.0)))
        if getattr(self.meta, "pooled", False):  # a layout written into the compiled model's slots
            self.meta = self._relayout_meta(self.seed)
        self.data = mujoco.MjData(m)
        self.cameras = tuple(_truth.name_of(m, _OBJ.mjOBJ_CAMERA, i) for i in range(m.ncam))
        self._lidars = {k: Lidar(m, s) for k, s in parse_lidars(m).items()}
        self.lidars = tuple(self._lidars)
        # The site of the first 2D lidar: its height is the plane of the 2D sdf().
        self._plane_site = next((_truth.id_of(m, _OBJ.mjOBJ_SITE, lid.spec.site) for lid in self._lidars.values()
                                 if lid.spec.kind == "lidar2d"), None)
        self._rig = None
        self._closed = False
        self.kinematic = kinematic
        # A rover is one added by a scene builder (it brings its configuration and controller).
        self._has_rover = isinstance(self.meta, RoverMeta) and _has_body(m, "rover")
        if self.kinematic and not self._has_rover:
            raise ValueError("kinematic: only scenes with a rover can move kinematically")
        terrain = getattr(self.meta, "terrain", None)
        if planar and terrain is not None and np.any(terrain.heights):
            raise ValueError(f"kinematic: 'planar' needs a flat scene; {scene!r} has hills (use True)")
        self._planar = planar
        self._controller = RoverController(m, self.meta.rover_config) if self._has_rover else None
        self._script = getattr(self.meta, "script", None)
        ts = m.opt.timestep
        if control_dt is None:
            # The scene's period, snapped to a whole number of physics steps.
            dt0 = getattr(self.meta, "control_dt", 0.1 if self._has_rover else 1.0 / 30.0)
            control_dt = max(1, round(dt0 / ts)) * ts
        self.dt = float(control_dt)
        self._substeps = int(round(self.dt / ts))
        if self._substeps < 1 or self._substeps > 1_000_000 or abs(self._substeps * ts - self.dt) > 1e-9:
            raise ValueError(f"control_dt: {self.dt} s is not a positive multiple of the physics timestep {ts} s")
        self._noise = {}
        for name, model_ in (noise or {}).items():
            self.set_noise(name, model_)
        self._labels = _truth.label_table(m, getattr(self.meta, "target", None))
        self._robot_set = frozenset(np.flatnonzero(self._labels == _truth.LABELS["robot"]).tolist())
        self._ground_set = frozenset(np.flatnonzero(self._labels == _truth.LABELS["ground"]).tolist())
        self._ids = {"rover": _truth.id_of(m, _OBJ.mjOBJ_BODY, "rover") if self._has_rover else -1,
                     "hand": _truth.id_of(m, _OBJ.mjOBJ_BODY, "hand"),
                     "cameras": {c: _truth.id_of(m, _OBJ.mjOBJ_CAMERA, c) for c in self.cameras},
                     "sites": {k: _truth.id_of(m, _OBJ.mjOBJ_SITE, s.spec.site) for k, s in self._lidars.items()},
                     "objects": {o: m.body(o).id for o in getattr(self.meta, "objects", ())}}
        self._sdf = None
        self.reset(self.seed)

    # -- lifecycle ------------------------------------------------------------------------
    def reset(self, seed=None):
        """Restore the initial state. ``seed`` reseeds the sensor noise (the layout is fixed by
        the constructor's seed; build a new ``World`` for another layout)."""
        self._check_open()
        if seed is not None:
            self._rng = as_rng(as_int(seed, "seed", minimum=0))
        elif not hasattr(self, "_rng"):
            self._rng = as_rng(self.seed)
        mujoco.mj_resetData(self.model, self.data)
        if self._controller is not None:
            self._controller.reset()
        if self._script is not None:
            self._script.reset(self.model, self.data)
        mujoco.mj_forward(self.model, self.data)
        if self._has_rover and not self.kinematic:
            # Let the rover settle on its wheels so t = 0 starts from rest on the ground.
            for _ in range(int(0.5 / self.model.opt.timestep)):
                self._controller.apply(self.model, self.data, 0.0, 0.0, self.model.opt.timestep)
                mujoco.mj_step(self.model, self.data)
            self.data.time = 0.0
        elif self.kinematic:
            self._kin = np.array(self.meta.start_pose2d, dtype=np.float64)
            if self._planar:
                self._kin = tuple(float(v) for v in self._kin)
            self._set_kinematic_pose(0.0, 0.0)
        return self

    def relayout(self, seed):
        """Give the world the procedural layout of ``seed`` in place and reset it: the same
        geometry, start and goal as ``World(scene, seed, **options)``, without recompiling the
        model (about a millisecond instead of several). Only for a scene built with
        ``pooled=True`` (``navworld``); a seed whose layout cannot be drawn raises ``ValueError``
        and leaves the world as it was."""
        self._check_open()
        if not getattr(self.meta, "pooled", False):
            raise ValueError(f"relayout: scene {self.scene!r} was not built pooled (pass pooled=True to a scene "
                             "that supports it: navworld); build a new World for another layout")
        seed = as_int(seed, "seed", minimum=0)
        self.meta = self._relayout_meta(seed)
        self.seed = seed
        self._sdf = None  # the static geometry changed
        return self.reset(seed)

    def _relayout_meta(self, seed):
        """Write the layout of ``seed`` into the pooled model's slots; returns its metadata."""
        from polar_sim.sim.scenes import SCENES

        return check_meta(self.scene, SCENES[self.scene].load_relayout()(self.model, seed, **self._scene_options))

    def close(self):
        """Free the renderers. Safe to call twice."""
        if self._rig is not None:
            self._rig.close()
            self._rig = None
        self._closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _check_open(self):
        if getattr(self, "_closed", False):
            raise RuntimeError("World is closed")

    # -- stepping -------------------------------------------------------------------------
    @property
    def time(self):
        """Simulation time, seconds."""
        return float(self.data.time)

    def step(self, action=None):
        """Advance one control period :attr:`dt`.

        Rover scenes take ``action = (v, omega)``: forward speed (m/s) and yaw rate (rad/s)
        commands for the wheel controller (or the exact unicycle in kinematic mode); no action
        means (0, 0). Scripted scenes (tabletop, object_orbit) take no action and run their
        script. Bad actions raise ``ValueError`` and leave the world unchanged.
        """
        self._check_open()
        if self._has_rover:
            v, w = self._check_action(action)
            if self.kinematic:
                self._kinematic_step(v, w)
                return
            ts = self.model.opt.timestep
            for _ in range(self._substeps):
                self._controller.apply(self.model, self.data, v, w, ts)
                mujoco.mj_step(self.model, self.data)
            return
        if action is not None:
            raise ValueError(f"action: scene {self.scene!r} is scripted and takes no action, got {action!r}")
        for _ in range(self._substeps):
            if self._script is not None:
                self._script.apply(self.model, self.data)
            mujoco.mj_step(self.model, self.data)
        if self._script is not None:
            self._script.after_step(self.model, self.data)

    def command_hand(self, velocity, yaw_rate):
        """Command the scripted hand (scenes whose script takes commands, e.g. ``tabletop`` with
        ``script="reach"``): velocity (3,) m/s in the world frame and yaw rate (rad/s, about world
        z), held until the next call. Raises ``ValueError`` for a scene without such a hand, or
        non-finite values (the command is then unchanged)."""
        self._check_open()
        if not callable(getattr(self._script, "command", None)):
            raise ValueError(f"command_hand: scene {self.scene!r} has no commanded hand (tabletop, script='reach')")
        self._script.command(velocity, yaw_rate)

    def _check_action(self, action):
        if action is None:
            return 0.0, 0.0
        if type(action) is tuple and len(action) == 2 and all(type(v) in (float, np.float64) for v in action):
            v, w = float(action[0]), float(action[1])  # an environment's own command: no array to build
            a = (v, w)
            if not (math.isfinite(v) and math.isfinite(w)):
                raise ValueError(f"action: contains NaN or inf: {[v, w]}")
        else:
            a = self._check_action_array(action)
        cfg = self.meta.rover_config
        if abs(a[0]) > cfg.max_speed + 1e-9 or abs(a[1]) > cfg.max_yaw_rate + 1e-9:
            raise ValueError(f"action: ({a[0]:.3g}, {a[1]:.3g}) exceeds the rover's limits "
                             f"|v| <= {cfg.max_speed} m/s, |omega| <= {cfg.max_yaw_rate} rad/s")
        return float(a[0]), float(a[1])

    @staticmethod
    def _check_action_array(action):
        a = as_float_array(action, "action")
        if a.shape != (2,):
            raise ValueError(f"action: expected (v [m/s], omega [rad/s]) of shape (2,), got shape {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"action: contains NaN or inf: {a.tolist()}")
        return a

    def _kinematic_step(self, v, w):
        if self._planar:
            return self._planar_step(v, w)
        x, y, th = self._kin
        dt = self.dt
        if abs(w) > 1e-12:
            x += v / w * (np.sin(th + w * dt) - np.sin(th))
            y -= v / w * (np.cos(th + w * dt) - np.cos(th))
        else:
            x += v * dt * np.cos(th)
            y += v * dt * np.sin(th)
        self._kin = np.array([x, y, th + w * dt])
        self.data.time += dt
        self._set_kinematic_pose(v, w)

    def _planar_step(self, v, w):
        """``_kinematic_step`` on the flat floor, in Python floats."""
        x, y, th = self._kin
        dt = self.dt
        if abs(w) > 1e-12:
            x += v / w * (math.sin(th + w * dt) - math.sin(th))
            y -= v / w * (math.cos(th + w * dt) - math.cos(th))
        else:
            x += v * dt * math.cos(th)
            y += v * dt * math.sin(th)
        self._kin = (x, y, th + w * dt)
        self.data.time += dt
        self._set_planar_pose(v, w)

    def _set_planar_pose(self, v, w):
        x, y, th = self._kin
        qpos, qvel = self.data.qpos, self.data.qvel
        a, va = self._controller.qpos_adr, self._controller.qvel_adr
        qpos[a : a + 7] = (x, y, self.meta.rover_config.wheel_radius, math.cos(th / 2), 0.0, 0.0,
                           math.sin(th / 2))
        qvel[va : va + 6] = (v * math.cos(th), v * math.sin(th), 0.0, 0.0, 0.0, w)
        mujoco.mj_forward(self.model, self.data)

    def _set_kinematic_pose(self, v, w):
        if self._planar:
            return self._set_planar_pose(v, w)
        m, d = self.model, self.data
        cfg = self.meta.rover_config
        x, y, th = self._kin
        terrain = getattr(self.meta, "terrain", None)
        z = float(terrain.height(x, y)) if terrain is not None else 0.0
        n = terrain.normal(x, y) if terrain is not None else np.array([0.0, 0.0, 1.0])
        h = np.array([np.cos(th), np.sin(th), 0.0])
        xb = h - (h @ n) * n
        xb /= np.linalg.norm(xb)
        R = np.stack([xb, np.cross(n, xb), n], 1)
        adr = self._controller.qpos_adr
        vadr = self._controller.qvel_adr
        # Directly above the ground point (x, y), at the height where a wheel of radius r
        # touches the local tangent plane: the unicycle holds exactly in the horizontal plane.
        d.qpos[adr : adr + 3] = [x, y, z + cfg.wheel_radius / n[2]]
        d.qpos[adr + 3 : adr + 7] = matrix_to_quat(R)
        d.qvel[vadr : vadr + 3] = v * xb
        d.qvel[vadr + 3 : vadr + 6] = [0.0, 0.0, w]
        mujoco.mj_forward(m, d)

    # -- sensors --------------------------------------------------------------------------
    def set_noise(self, sensor, model):
        """Switch a sensor's noise model on (``RangeNoise`` / ``DepthNoise``) or off (``None``)."""
        _check_name(sensor, "sensor")
        if sensor not in self.cameras and sensor not in self._lidars:
            raise ValueError(f"sensor: unknown sensor {sensor!r}; this scene has {sorted(self.cameras + self.lidars)}")
        want = DepthNoise if sensor in self.cameras else RangeNoise
        if model is not None and not isinstance(model, want):
            raise TypeError(f"noise[{sensor!r}]: expected {want.__name__} or None, got {type(model).__name__}")
        if model is None:
            self._noise.pop(sensor, None)
        else:
            self._noise[sensor] = model

    def camera(self, name, *, width=None, height=None, depth=True, labels=True):
        """Render camera ``name``: a :class:`CameraFrame` (rgb, depth, labels, geom ids, K, pose, t).

        ``width``/``height`` default to the camera's resolution in the scene. ``depth=False`` and
        ``labels=False`` skip those renders (faster): the frame's ``depth`` / ``labels`` and
        ``geom_ids`` are then None (a camera with a noise model still renders depth for it).
        """
        self._check_open()
        cid = self._camera_id(name)
        w, h = self._camera_size(cid, width, height)
        depth, labels = as_bool(depth, "depth"), as_bool(labels, "labels")
        if self._rig is None:
            self._rig = CameraRig(self.model)
        noise = self._noise.get(name)
        rgb, d, lab, gids = self._rig.render(self.model, self.data, cid, w, h, self._labels,
                                             depth=bool(depth) or noise is not None, seg=bool(labels))
        K = pinhole_intrinsics(w, h, self.model.cam_fovy[cid])
        if noise is not None:
            rgb, d = noise.apply(rgb, d, K[0, 0], self._rng)
        if not labels:
            lab = gids = None
        return CameraFrame(rgb, d if depth else None, lab, gids, K, camera_pose(self.data, cid), self.time)

    def camera_intrinsics(self, name, *, width=None, height=None):
        """Intrinsics K (3, 3) (OpenCV) of camera ``name`` rendered at ``width`` x ``height`` px."""
        cid = self._camera_id(name)
        return pinhole_intrinsics(*self._camera_size(cid, width, height), self.model.cam_fovy[cid])

    def _camera_id(self, name):
        if _check_name(name, "name") not in self.cameras:
            raise ValueError(f"name: unknown camera {name!r}; this scene has {list(self.cameras)}")
        return self.model.camera(name).id

    def _camera_size(self, cid, width, height):
        return _image_size(self.model, cid, width, height)

    def render_view(self, *, width=640, height=480, lookat=None, distance=None, azimuth=90.0,
                    elevation=-45.0):
        """RGB (H, W, 3) uint8 of the scene from a free third-person camera.

        ``lookat`` (3,) defaults to the robot (rover scenes) or the scene centre; ``distance``
        (m) defaults to a view that frames the robot's surroundings. ``elevation=-90`` looks
        straight down (a top-down map view).
        """
        self._check_open()
        width, height = _image_size(self.model, None, width, height)
        if lookat is not None:
            lookat = as_float_array(lookat, "lookat")
            if lookat.shape != (3,) or not np.isfinite(lookat).all():
                raise ValueError(f"lookat: expected a finite point (3,), got shape {lookat.shape}")
        if distance is not None:
            distance = as_float(distance, "distance", minimum=0.0, exclusive_minimum=True, maximum=1e6)
        azimuth = as_float(azimuth, "azimuth")
        elevation = as_float(elevation, "elevation", minimum=-90.0, maximum=90.0)
        if lookat is None:
            if self._has_rover:
                lookat = self.data.xpos[self.model.body("rover").id]
            else:
                lookat = self.model.stat.center
        if distance is None:
            distance = (12.0 * self.meta.rover_config.wheelbase if self._has_rover
                        else 1.5 * self.model.stat.extent)
        if self._rig is None:
            self._rig = CameraRig(self.model)
        return self._rig.render_free(self.model, self.data, width, height, np.asarray(lookat, float),
                                     float(distance), float(azimuth), float(elevation))

    def amodal_mask(self, name, *, width=None, height=None):
        """Full silhouette (H, W) bool of the target object seen from camera ``name``, as if
        nothing occluded it (its geoms are in the target group). Compare with
        ``frame.labels == LABELS["target"]``, the visible part, for the occlusion ratio."""
        self._check_open()
        if _check_name(name, "name") not in self.cameras:
            raise ValueError(f"name: unknown camera {name!r}; this scene has {list(self.cameras)}")
        cid = self.model.camera(name).id
        w, h = _image_size(self.model, cid, width, height)
        if self._rig is None:
            self._rig = CameraRig(self.model)
        return self._rig.render_target_mask(self.model, self.data, cid, w, h)

    def lidar(self, name, *, noise=True):
        """Cast lidar ``name``: a :class:`LidarScan` (2D) or :class:`LidarScan3D`.

        ``noise=False`` casts the exact scan, ignoring the sensor's noise model (and drawing
        nothing from the noise generator, so the noisy scans that follow are unchanged).
        """
        self._check_open()
        if _check_name(name, "name") not in self._lidars:
            raise ValueError(f"name: unknown lidar {name!r}; this scene has {list(self.lidars)}")
        noise = as_bool(noise, "noise")
        return self._lidars[name].scan(self.model, self.data, self._noise.get(name) if noise else None, self._rng)

    def lidar_spec(self, name):
        """The declaration (beams, range limits, site) of lidar ``name``."""
        if _check_name(name, "name") not in self._lidars:
            raise ValueError(f"name: unknown lidar {name!r}; this scene has {list(self.lidars)}")
        return self._lidars[name].spec

    # -- truth ----------------------------------------------------------------------------
    def truth(self):
        """Exact state as a dict of fresh arrays.

        Keys: ``time``; rover scenes: ``robot_pose`` (4, 4), ``robot_pose2d`` (x, y, yaw),
        ``robot_twist`` (6,) = body-frame linear (m/s) then angular (rad/s) velocity,
        ``robot_collision`` (bool, a robot geom touches a non-ground geom); all scenes:
        ``cameras`` {name: T_world_cam (4, 4), OpenCV axes}, ``lidars`` {name: T_world_sensor},
        ``objects`` {name: 4x4 world pose} and ``object_twists`` {name: (6,)} of the movable
        objects, ``target`` (name of the tracked object or None), and ``hand_pose`` where a hand
        exists.
        """
        m, d = self.model, self.data
        ids = self._ids
        out = {"time": self.time, "target": getattr(self.meta, "target", None)}
        if self._has_rover:
            b = ids["rover"]
            T = _truth.body_pose(d, b)
            out["robot_pose"] = T
            out["robot_pose2d"] = T_to_pose2d(T)
            out["robot_twist"] = _truth.body_twist(m, d, b)
            out["robot_collision"] = self.robot_collision()
        out["cameras"] = {c: camera_pose(d, i) for c, i in ids["cameras"].items()}
        out["lidars"] = {k: make_pose(d.site_xmat[i].reshape(3, 3).copy(), d.site_xpos[i].copy())
                         for k, i in ids["sites"].items()}
        out["objects"] = {name: _truth.body_pose(d, i) for name, i in ids["objects"].items()}
        out["object_twists"] = {name: _truth.body_twist(m, d, i) for name, i in ids["objects"].items()}
        if ids["hand"] >= 0:
            out["hand_pose"] = _truth.body_pose(d, ids["hand"])
        if self._script is not None:
            out.update(self._script.truth(m, d))
        return out

    # -- cheap truth of the rover, for the per-step loop of an environment ---------------------
    def robot_pose2d(self):
        """True rover pose (x, y, yaw) (3,), m and rad: ``truth()["robot_pose2d"]`` without the rest."""
        b = self._rover_id()
        x, R = self.data.xpos[b], self.data.xmat[b]
        return np.array([x[0], x[1], np.arctan2(R[3], R[0])])

    def robot_twist(self):
        """True rover twist (6,): ``truth()["robot_twist"]``."""
        return _truth.body_twist(self.model, self.data, self._rover_id())

    def robot_collision(self):
        """True if a rover geom touches a geom other than the ground: ``truth()["robot_collision"]``."""
        self._rover_id()
        d = self.data
        n = d.ncon
        if n == 0:
            return False
        # A handful of contacts: plain Python over sets beats numpy's fancy indexing here.
        robot, ground = self._robot_set, self._ground_set
        for g1, g2 in d.contact.geom[:n].tolist():
            r1, r2 = g1 in robot, g2 in robot
            if (r1 and not r2 and g2 not in ground) or (r2 and not r1 and g1 not in ground):
                return True
        return False

    def lidar_pose2d(self, name):
        """True planar pose (x, y, yaw) (3,) of lidar ``name``: ``T_to_pose2d`` of :meth:`lidar_pose`."""
        self._check_open()
        if _check_name(name, "name") not in self._lidars:
            raise ValueError(f"name: unknown lidar {name!r}; this scene has {list(self.lidars)}")
        i = self._ids["sites"][name]
        x, R = self.data.site_xpos[i], self.data.site_xmat[i]
        return np.array([x[0], x[1], np.arctan2(R[3], R[0])])

    def lidar_pose(self, name):
        """True pose (4, 4) of lidar ``name``'s sensor frame: the ``T_world_sensor`` its scan would
        carry now, without casting the scan."""
        self._check_open()
        if _check_name(name, "name") not in self._lidars:
            raise ValueError(f"name: unknown lidar {name!r}; this scene has {list(self.lidars)}")
        i = self._ids["sites"][name]
        return make_pose(self.data.site_xmat[i].reshape(3, 3), self.data.site_xpos[i].copy())

    def _rover_id(self):
        if not self._has_rover:
            raise ValueError(f"scene {self.scene!r} has no rover")
        return self._ids["rover"]

    def geom_labels(self):
        """Label of every geom id, (ngeom,) int (see ``truth.LABELS``)."""
        return self._labels.copy()

    def sdf(self, points):
        """Exact signed distance (n,) of the static scene, metres, negative inside.

        ``points`` (n, 3) are world points. ``points`` (n, 2) are taken in the horizontal plane
        of the 2D lidar (its current height) and measured within that plane, ground excluded.
        """
        p, dim = self._sdf_points(points)
        if dim == 3:
            return self._scene_sdf()(p)
        return self._scene_sdf().section(p, self.lidar_plane_height())

    def sdf_gradient(self, points, *, step=1e-3):
        """:meth:`sdf` (n,) and its gradient (n, 2) or (n, 3) at the same points, the gradient by
        central differences ``(sdf(p + step e) - sdf(p - step e)) / (2 step)`` along each axis
        (``step`` in m, > 0): one call for the distance and the gradient of a whole stencil."""
        p, dim = self._sdf_points(points)
        h = as_positive_float(step, "step")
        if dim == 2:
            return self._scene_sdf().section_gradient(p, self.lidar_plane_height(), h)
        f = self._scene_sdf()
        g = np.stack([(f(p + e) - f(p - e)) / (2 * h) for e in h * np.eye(3)], 1)
        return f(p), g

    def sdf_stencil(self, pose2d, offsets, *, frame=None, step=None):
        """The 2D :meth:`sdf` at points ``offsets`` (n, 2) given in the frame of the planar pose
        ``pose2d`` (x, y, theta), that pose itself given in ``frame`` (a planar pose in the world;
        None: the world): the world points are ``frame ∘ pose2d ∘ offsets``, m and rad. A robot's
        stencil of SDF samples in one call. With ``step`` (m), also the central-difference gradient
        (n, 2) along ``frame``'s axes, as :meth:`sdf_gradient` gives it; returns ``d`` or
        ``(d, grad)``. The results equal composing the points with
        :func:`polar_sim.geometry.compose2d`'s formulas and calling :meth:`sdf` / :meth:`sdf_gradient`.
        """
        from polar_sim._validation import as_pose2d

        pose = as_pose2d(pose2d, "pose2d")
        fr = None if frame is None else as_pose2d(frame, "frame")
        off = self._sdf_points(offsets)[0]
        if off.shape[1] != 2:
            raise ValueError(f"offsets: expected shape (n, 2), got {off.shape}")
        h = 0.0 if step is None else as_positive_float(step, "step")
        trig = lambda p: np.array([p[0], p[1], np.cos(p[2]), np.sin(p[2])])  # noqa: E731
        out = self._scene_sdf().section_stencil(off, trig(pose), np.zeros(0) if fr is None else trig(fr),
                                               self.lidar_plane_height(), h)
        if out is None:  # shapes the compiled loop does not cover: compose, then the general path
            pts = _compose_points(pose, off)
            if fr is not None:
                pts = _compose_points(fr, pts)
            if step is None:
                return self.sdf(pts)
            d, g = self.sdf_gradient(pts, step=h)
            if fr is not None:
                c, s = np.cos(fr[2]), np.sin(fr[2])
                g = np.stack([c * g[:, 0] + s * g[:, 1], -s * g[:, 0] + c * g[:, 1]], 1)
            return d, g
        return out[0] if step is None else out

    def _sdf_points(self, points):
        from polar_sim._validation import as_points

        p = as_float_array(points, "points")
        dim = p.shape[1] if (p.ndim == 2 and p.shape[1] in (2, 3)) else 3
        return as_points(p, dim, "points"), dim

    def _scene_sdf(self):
        if self._sdf is None:
            self._sdf = _truth.SceneSDF(self.model, self.data, getattr(self.meta, "terrain", None))
        return self._sdf

    def nearest_surface(self, points):
        """Label (n,) of the static surface nearest to each world point (n, 3) (see
        ``truth.LABELS``), from the exact geometry; the terrain counts as ground."""
        from polar_sim._validation import as_points

        p = as_points(points, 3, "points")
        _, g = self._scene_sdf()(p, return_geom=True)
        return np.where(g < 0, _truth.LABELS["ground"], self._labels[np.maximum(g, 0)])

    def lidar_plane_height(self):
        """World height (m) of the plane 2D points of :meth:`sdf` live in: the first 2D lidar's."""
        site = self._plane_site
        return 0.0 if site is None else float(self.data.site_xpos[site][2])

    def object_points(self, name, n, seed=0):
        """(n, 3) points and (n, 3) outward unit normals sampled uniformly on the surface of
        object ``name``, in the object's frame, metres. Same ``seed``, same points."""
        try:
            bid = self.model.body(name).id
        except KeyError as exc:
            raise ValueError(f"name: unknown object {name!r}; objects: {list(getattr(self.meta, 'objects', ()))}") from exc
        n = as_int(n, "n", minimum=1)
        mesh = _truth.body_trimesh(self.model, bid)
        import trimesh

        pts, face = trimesh.sample.sample_surface(mesh, n, seed=as_int(seed, "seed"))
        return np.asarray(pts), np.asarray(mesh.face_normals[face])

    def object_mesh(self, name):
        """``trimesh.Trimesh`` of object ``name`` in its own frame."""
        return _truth.body_trimesh(self.model, self._body_id(name))

    def _body_id(self, name):
        try:
            return self.model.body(_check_name(name, "name")).id
        except KeyError:
            raise ValueError(f"name: unknown object {name!r}; objects: {list(getattr(self.meta, 'objects', ()))}") from None


def _compose_points(pose, points):
    """Points (n, 2) in the frame of a planar pose carried into the pose's parent frame."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.stack([pose[0] + c * points[:, 0] - s * points[:, 1], pose[1] + s * points[:, 0] + c * points[:, 1]], 1)


def _check_name(name, arg):
    """A sensor or body name must be a str (a list or array would compare elementwise)."""
    if not isinstance(name, str):
        raise TypeError(f"{arg}: expected a name (str), got {type(name).__name__}")
    return name


def _image_size(model, cam_id, width, height):
    """(width, height) in pixels: positive ints within the scene's offscreen buffer; None takes
    the camera's resolution in the scene (640 x 480 if it has none)."""
    res = model.cam_resolution[cam_id] if cam_id is not None else (0, 0)
    g = model.vis.global_
    out = []
    for arg, v, default, limit in (("width", width, res[0] or 640, g.offwidth),
                                   ("height", height, res[1] or 480, g.offheight)):
        v = default if v is None else as_int(v, arg, minimum=1)
        if v > limit:
            raise ValueError(f"{arg}: {v} px exceeds the scene's offscreen buffer ({g.offwidth} x {g.offheight}; "
                             "<visual><global offwidth/offheight> in the MJCF)")
        out.append(int(v))
    return tuple(out)


def _check_model(m, scene):
    """Refuse a compiled model the simulator cannot step or ray-cast sensibly."""
    ts = float(m.opt.timestep)
    if not np.isfinite(ts) or ts <= 0:
        raise ValueError(f"scene: {str(scene)[:200]!r} has a physics timestep of {ts} s; expected > 0")
    from polar_sim.sim.scenes import MAX_MESH_FACES

    if m.nmeshface > MAX_MESH_FACES:
        raise ValueError(f"scene: {str(scene)[:200]!r} holds {m.nmeshface} mesh faces; the limit is "
                         f"{MAX_MESH_FACES} (MAX_MESH_FACES)")


def _has_body(model, name):
    return _truth.id_of(model, _OBJ.mjOBJ_BODY, name) >= 0
