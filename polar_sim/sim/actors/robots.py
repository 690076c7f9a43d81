"""The differential-drive rover: its MJCF (built into an ``MjSpec``), its wheel-level controller and its
exact kinematic mode.

The rover body frame has its origin at the centre of the driven axle, x forward, y left, z up.
The camera sits on the vertical axis through that origin (the instantaneous rotation axis of a
differential drive), so its motion satisfies the nonholonomic model the ground chapter assumes.
Its visual model shows four tyres, like a skid-steer vehicle; physically the fore and aft pairs
are frictionless casters, which avoids the lateral scrubbing that makes skid steering track its
yaw-rate commands poorly.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np


__all__ = ["RoverConfig", "ROVER_PRESETS", "add_rover", "RoverController", "GROUP"]

#: Geom groups: which groups render and which the sensors' rays see.
GROUP = {
    "static": 0,  # world geometry (walls, obstacles, tables): rendered, ray-cast, collides
    "ground": 1,  # visible ground meshes: rendered, ray-cast, no collision
    "dynamic": 2,  # movable objects and the hand: rendered, ray-cast
    "collision": 3,  # hidden collision-only geoms (heightfield, convex stand-ins): never seen
    "robot": 4,  # the rover's own geoms: rendered, excluded from its sensors' rays
    "target": 5,  # the tracked object's visible geoms: rendered alone for its amodal mask
}
RENDER_GROUPS = np.array([1, 1, 1, 0, 1, 1], dtype=np.uint8)
RAY_GROUPS = np.array([1, 1, 1, 0, 0, 1], dtype=np.uint8)
TARGET_ONLY_GROUPS = np.array([0, 0, 0, 0, 0, 1], dtype=np.uint8)


@dataclasses.dataclass(frozen=True)
class RoverConfig:
    """Geometry and limits of a rover. Lengths in metres, speeds in m/s and rad/s.

    ``camera_height`` and ``lidar_height`` are above flat ground at rest.
    """

    wheel_radius: float
    track: float  # lateral distance between left and right wheel centres
    wheelbase: float  # longitudinal distance between the front and rear casters
    chassis_half: tuple  # half sizes of the chassis box (x, y, z)
    chassis_mass: float
    camera_height: float
    camera_fovy_deg: float  # vertical field of view of the front camera, degrees
    lidar_height: float
    lidar3d_height: float
    max_speed: float
    max_yaw_rate: float
    wheel_kv: float  # velocity-actuator gain, N m s / rad
    wheel_torque: float  # torque limit per wheel, N m

    def __post_init__(self):
        # Every field is a positive finite length, mass, speed or gain; the sensors sit above
        # the ground (a negative camera_height would put the camera underground).
        from polar_sim._validation import as_float

        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name == "chassis_half":
                if not isinstance(v, (tuple, list)) or len(v) != 3:
                    raise ValueError(f"chassis_half: expected 3 half sizes (m), got {v!r}")
                for x in v:
                    as_float(x, "chassis_half", minimum=0.0, exclusive_minimum=True)
                continue
            hi = 179.0 if f.name == "camera_fovy_deg" else None
            as_float(v, f.name, minimum=0.0, exclusive_minimum=True, maximum=hi)


ROVER_PRESETS = {
    # Car-sized, KITTI-like camera height; for the outdoor scenes.
    "car": RoverConfig(
        wheel_radius=0.35, track=1.6, wheelbase=2.4, chassis_half=(1.8, 0.85, 0.25),
        chassis_mass=900.0, camera_height=1.65, camera_fovy_deg=45.0, lidar_height=1.0,
        lidar3d_height=2.0, max_speed=12.0, max_yaw_rate=1.0, wheel_kv=600.0, wheel_torque=1500.0,
    ),
    # A lab robot that fits through doors; for office2d and the GPIS navigation worlds.
    "indoor": RoverConfig(
        wheel_radius=0.1, track=0.46, wheelbase=0.36, chassis_half=(0.3, 0.2, 0.08),
        chassis_mass=25.0, camera_height=0.6, camera_fovy_deg=60.0, lidar_height=0.35,
        lidar3d_height=0.7, max_speed=1.5, max_yaw_rate=2.0, wheel_kv=8.0, wheel_torque=20.0,
    ),
}


def add_rover(spec: mujoco.MjSpec, config: RoverConfig, pose2d=(0.0, 0.0, 0.0), z0=0.0,
              *, camera_width=640, camera_height_px=480, lidar_beams=1081):
    """Add the rover body "rover" with its sensors' mount points to ``spec``.

    Adds the camera ``front``, the 2D lidar site ``lidar`` and the 3D lidar site ``lidar3d``, the
    driven wheel hinges ``wheel_left``/``wheel_right`` with velocity actuators of the same names,
    two frictionless casters, and the
    sensor declarations (``<custom><text name="sensor:...">``) that :mod:`sensors` reads.
    """
    from polar_sim._validation import as_int, as_pose2d

    if not isinstance(config, RoverConfig):
        raise TypeError(f"config: expected a RoverConfig, got {type(config).__name__}")
    lidar_beams = as_int(lidar_beams, "lidar_beams", minimum=1, maximum=100_000)
    camera_width = as_int(camera_width, "camera_width", minimum=1, maximum=8192)
    camera_height_px = as_int(camera_height_px, "camera_height_px", minimum=1, maximum=8192)
    c = config
    r = c.wheel_radius
    x, y, th = as_pose2d(pose2d, "pose2d")
    body = spec.worldbody.add_body(name="rover", pos=[x, y, z0 + r + 0.01])
    body.quat = [np.cos(th / 2), 0.0, 0.0, np.sin(th / 2)]
    body.add_freejoint(name="rover_free")
    g = GROUP["robot"]
    hx, hy, hz = c.chassis_half
    body.add_geom(name="rover_chassis", type=mujoco.mjtGeom.mjGEOM_BOX, size=[hx, hy, hz],
                  pos=[0, 0, hz + 0.02], mass=c.chassis_mass, rgba=[0.85, 0.85, 0.9, 1], group=g)
    # A mast carries the camera and the lidars above the chassis.
    mast_top = c.lidar3d_height - r
    body.add_geom(name="rover_mast", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                  fromto=[-0.15 * hx, 0, 2 * hz, -0.15 * hx, 0, mast_top], size=[0.1 * hy, 0, 0],
                  mass=1.0, rgba=[0.2, 0.2, 0.2, 1], group=g, contype=0, conaffinity=0)
    wheel_mass = 0.02 * c.chassis_mass
    # Differential drive: two driven wheels on the centre axle, so the vehicle turns about the
    # vertical axis under the camera; frictionless casters fore and aft carry the chassis.
    # Sprung suspension on the driven wheels: a rigid four-point chassis would lift them off
    # the ground in every sag. The spring is preloaded so each wheel carries about a third of
    # the weight at rest, and soft enough (10 cm preload travel) that centimetre bumps barely
    # change that share.
    total_mass = c.chassis_mass + 4 * wheel_mass
    preload = 0.1 * r / 0.35
    k_spring = 0.35 * total_mass * 9.81 / preload
    for name, sy in (("left", 1), ("right", -1)):
        wb = body.add_body(name=f"wheel_{name}", pos=[0, sy * c.track / 2, 0])
        wb.add_joint(name=f"suspension_{name}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1],
                     stiffness=k_spring, springref=-preload, damping=2.5 * np.sqrt(k_spring * wheel_mass),
                     range=[-0.5 * r, 0.5 * r], limited=mujoco.mjtLimited.mjLIMITED_TRUE)
        wb.add_joint(name=f"wheel_{name}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 1, 0],
                     armature=0.01 * wheel_mass * r * r)
        # A sphere collides smoothly with a heightfield; the visible tyre is a cylinder.
        wb.add_geom(name=f"wheel_{name}_contact", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r, 0, 0],
                    mass=wheel_mass, friction=[1.2, 0.01, 0.001], group=GROUP["collision"],
                    rgba=[0, 0, 0, 0], condim=3)
        wb.add_geom(name=f"wheel_{name}_tyre", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                    size=[r, 0.35 * r, 0], quat=[np.sqrt(0.5), np.sqrt(0.5), 0, 0], mass=0.0,
                    rgba=[0.08, 0.08, 0.08, 1], group=g, contype=0, conaffinity=0)
        act = spec.add_actuator(name=f"wheel_{name}", target=f"wheel_{name}",
                                trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_velocity(kv=c.wheel_kv)
        act.forcelimited = True
        act.forcerange = [-c.wheel_torque, c.wheel_torque]
        act.ctrllimited = True
        wmax = 1.3 * (c.max_speed + c.max_yaw_rate * c.track) / r
        act.ctrlrange = [-wmax, wmax]
    for name, sx in (("front", 1), ("rear", -1)):
        # condim=1 is a frictionless point contact, the ideal caster; priority makes the contact
        # take the caster's condim instead of the larger one of the ground.
        body.add_geom(name=f"caster_{name}", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r, 0, 0],
                      pos=[sx * c.wheelbase / 2, 0, 0], mass=wheel_mass, condim=1, priority=1,
                      group=GROUP["collision"], rgba=[0, 0, 0, 0])
        for sy in (1, -1):
            body.add_geom(name=f"caster_{name}_{'l' if sy > 0 else 'r'}_tyre",
                          type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[r, 0.35 * r, 0],
                          pos=[sx * c.wheelbase / 2, sy * c.track / 2, 0],
                          quat=[np.sqrt(0.5), np.sqrt(0.5), 0, 0], mass=0.0,
                          rgba=[0.08, 0.08, 0.08, 1], group=g, contype=0, conaffinity=0)
    # Camera: level, looking along body +x (MuJoCo cameras look down their -z with +y up).
    body.add_camera(name="front", pos=[0, 0, c.camera_height - r], xyaxes=[0, -1, 0, 0, 0, 1],
                    fovy=c.camera_fovy_deg, resolution=[camera_width, camera_height_px])
    body.add_site(name="lidar", pos=[0.0, 0, c.lidar_height - r], size=[0.02, 0, 0])
    body.add_site(name="lidar3d", pos=[-0.15 * hx, 0, c.lidar3d_height - r], size=[0.02, 0, 0])
    spec.add_text(name="sensor:lidar", data=f"type=lidar2d site=lidar beams={int(lidar_beams)} fov_deg=270 min=0.1 max=30")
    spec.add_text(name="sensor:lidar3d",
                  data="type=lidar3d site=lidar3d rows=32 cols=1024 vfov_min_deg=-25 vfov_max_deg=15 min=0.3 max=80")
    return body


class RoverController:
    """Turns a ``(v, omega)`` command into wheel speed targets, with a PI loop on the body twist.

    The wheels slip a little under traction and on slopes, so the open-loop wheel speeds
    under-deliver; the integral term on the measured speed and yaw rate closes that gap.
    """

    def __init__(self, model: mujoco.MjModel, config: RoverConfig, kp=0.6, ki=2.0):
        self.config = config
        self.kp = kp
        self.ki = ki
        def id_of(obj, name):  # mj_name2id: model.body(name) costs a few hundred microseconds
            i = mujoco.mj_name2id(model, obj, name)
            if i < 0:
                raise KeyError(f"the model has no {name!r}")
            return i

        self._act = np.array([id_of(mujoco.mjtObj.mjOBJ_ACTUATOR, f"wheel_{n}") for n in ("left", "right")])
        self.body_id = id_of(mujoco.mjtObj.mjOBJ_BODY, "rover")
        joint = id_of(mujoco.mjtObj.mjOBJ_JOINT, "rover_free")
        self.qpos_adr = model.jnt_qposadr[joint]
        self.qvel_adr = int(model.jnt_dofadr[joint])
        self._lo, self._hi = model.actuator_ctrlrange[self._act].T.tolist()
        self.reset()

    def reset(self):
        self._iv = 0.0
        self._iw = 0.0

    def _views(self, data):
        """(body x axis row of xmat, qvel, ctrl) of ``data``: views into its buffers, made once per
        MjData (building them costs more than the arithmetic of a substep)."""
        if getattr(self, "_bound", None) is not data:
            self._bound = data
            self._v = (data.xmat[self.body_id], data.qvel, data.ctrl)
        return self._v

    def body_twist(self, data):
        """Forward speed (m/s, along body x) and yaw rate (rad/s, about body z)."""
        # Scalar arithmetic: this runs every physics substep, where numpy's per-call overhead
        # on 3-vectors would cost more than the physics itself.
        x, qv, _ = self._views(data)  # body x axis in world = first column (entries 0, 3, 6)
        a = self.qvel_adr
        v = x[0] * qv[a] + x[3] * qv[a + 1] + x[6] * qv[a + 2]
        return float(v), float(qv[a + 5])

    def apply(self, model, data, v, omega, dt):
        """Write the wheel actuator targets for command ``(v, omega)`` into ``data.ctrl``."""
        c = self.config
        mv, mw = self.body_twist(data)
        ev, ew = v - mv, omega - mw
        self._iv = min(0.5, max(-0.5, self._iv + ev * dt))
        self._iw = min(0.5, max(-0.5, self._iw + ew * dt))
        v_c = v + self.kp * ev + self.ki * self._iv
        w_c = omega + self.kp * ew + self.ki * self._iw
        lo, hi = self._lo, self._hi
        ctrl = self._views(data)[2]
        ctrl[self._act[0]] = min(hi[0], max(lo[0], (v_c - w_c * c.track / 2) / c.wheel_radius))
        ctrl[self._act[1]] = min(hi[1], max(lo[1], (v_c + w_c * c.track / 2) / c.wheel_radius))
