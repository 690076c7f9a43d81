"""The scripted mocap hand of the tabletop scene: its geometry, smooth trajectories, and the
manipulation actions (touch, push, lift, turn, fast, pass) a script strings together.

Hand frame: origin at the palm centre; +y points from the wrist to the fingers, +z is the back
of the hand, so the palm faces -z. The fingers hang down (-z) from the palm's front edge and the
thumb from its back edge: a top grasp puts the palm just above an object and the fingers over the
side of it that faces the camera, which is what occludes it ("occlusion by touch").

Two ways of moving an object (tracking spec Sec. 9.4):

* Mode A, kinematic hand-held (``lift``, ``turn``, ``fast``): while held, the object's free-joint
  state is written from a smooth SE(3) trajectory and the hand follows at a fixed grasp offset;
  hand-object collisions are switched off (collision bit masks) so nothing drifts.
* Mode B, physical contact (``touch``, ``push``): the mocap hand, collisions on, presses on or
  pushes the object, which moves by the physics.

Trajectories are minimum-jerk in position and SLERP (with the same minimum-jerk timing) in
orientation, between poses at rest, so velocity and acceleration are continuous.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np



__all__ = ["add_hand", "HandScript", "ReachScript", "Segment", "min_jerk", "slerp", "look_at_quat",
           "HAND_SKIN", "COLLIDE_STATIC", "COLLIDE_HAND", "COLLIDE_OBJECT", "ACTIONS"]

HAND_SKIN = (0.87, 0.66, 0.53, 1.0)
SLEEVE = (0.22, 0.3, 0.48, 1.0)
# Collision bit masks (contype = conaffinity): world geometry and the other objects 1, hand 2,
# the target 1|2. The hand touches only the target (never the table, the walls or a
# distractor it sweeps past); a held target drops bit 2.
COLLIDE_STATIC, COLLIDE_HAND, COLLIDE_OBJECT = 1, 2, 3

# Hand geometry (hand frame, metres); see the module docstring.
PALM_HALF = (0.042, 0.05, 0.012)
FINGER_X = (-0.0285, -0.0095, 0.0095, 0.0285)
FINGER_LEN = (0.042, 0.048, 0.045, 0.036)
FINGER_R = 0.0085
FINGER_Y = 0.058
FINGER_Z0 = -0.02
THUMB_R = 0.0095
THUMB_Y = -0.064
FINGER_INNER = FINGER_Y - FINGER_R  # inner (palm-side) surface of the fingers, hand y
FINGER_OUTER = FINGER_Y + FINGER_R
TIP_Z = FINGER_Z0 - max(FINGER_LEN) - FINGER_R  # lowest fingertip point, hand z
# Fingers to thumb, inner surfaces, at the palm's underside (the thumb slants inward above).
GRASP_SPAN = FINGER_INNER + (0.054 - THUMB_R)

#: The actions a script is made of.
ACTIONS = ("touch", "push", "lift", "turn", "fast", "pass")
#: Approach directions of a grasp or touch, as yaw offsets from the camera direction (rad).
APPROACHES = {"front": 0.0, "side": -np.pi / 2, "left": np.pi / 2}


def add_hand(spec: mujoco.MjSpec, pos, quat, *, skin=HAND_SKIN, sleeve=SLEEVE):
    """Add the mocap body ``hand`` (palm box, capsule fingers and thumb, a sleeved forearm).

    Every geom collides with the objects (bit 2) but not with the static scene; all are in the
    dynamic geom group and labelled occluder (body name ``hand``). ``skin`` and ``sleeve`` are
    the RGB(A) colours (0..1) of the hand and of the forearm's sleeve.
    """
    from polar_sim.sim.actors.robots import GROUP

    skin, sleeve_rgba = tuple(skin)[:3] + (1.0,), tuple(sleeve)[:3] + (1.0,)
    body = spec.worldbody.add_body(name="hand", mocap=True, pos=list(pos), quat=list(quat))
    common = dict(group=GROUP["dynamic"], contype=COLLIDE_HAND, conaffinity=COLLIDE_HAND,
                  friction=[0.8, 0.005, 0.0001], rgba=list(skin))
    cap = mujoco.mjtGeom.mjGEOM_CAPSULE
    body.add_geom(name="hand_palm", type=mujoco.mjtGeom.mjGEOM_BOX, size=list(PALM_HALF), **common)
    for k, (x, L) in enumerate(zip(FINGER_X, FINGER_LEN)):
        body.add_geom(name=f"hand_finger{k}_proximal", type=cap, size=[FINGER_R, 0, 0],
                      fromto=[x, FINGER_Y - 0.004, -0.004, x, FINGER_Y, FINGER_Z0], **common)
        body.add_geom(name=f"hand_finger{k}_distal", type=cap, size=[FINGER_R, 0, 0],
                      fromto=[x, FINGER_Y, FINGER_Z0, x, FINGER_Y, FINGER_Z0 - L], **common)
    body.add_geom(name="hand_thumb_proximal", type=cap, size=[THUMB_R, 0, 0],
                  fromto=[0.030, -0.050, -0.004, 0.020, THUMB_Y, -0.030], **common)
    body.add_geom(name="hand_thumb_distal", type=cap, size=[THUMB_R, 0, 0],
                  fromto=[0.020, THUMB_Y, -0.030, 0.012, THUMB_Y, -0.058], **common)
    sleeve = dict(common, rgba=list(sleeve_rgba))
    # The wrist and forearm stay above the palm's underside, which rests on objects.
    body.add_geom(name="hand_wrist", type=cap, size=[0.024, 0, 0],
                  fromto=[0, -0.05, 0.013, 0, -0.09, 0.03], **common)
    body.add_geom(name="hand_forearm", type=cap, size=[0.033, 0, 0],
                  fromto=[0, -0.10, 0.03, 0, -0.27, 0.13], **sleeve)
    return body


# -- trajectories ----------------------------------------------------------------------------

# Quaternion helpers (w, x, y, z), in plain numpy: scipy's Rotation costs ~0.4 ms a call, too
# much for a script that runs before each of 600 physics substeps per second.

def quat_to_matrix(q):
    """Rotation matrix (3, 3) of a quaternion (w, x, y, z) (normalised here)."""
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def matrix_to_quat(R):
    """Quaternion (w, x, y, z) with w >= 0 of a rotation matrix (3, 3) (Shepperd's method)."""
    R = np.asarray(R, float)
    t = R[0, 0] + R[1, 1] + R[2, 2]
    k = int(np.argmax([t, R[0, 0], R[1, 1], R[2, 2]]))
    if k == 0:
        r = np.sqrt(1.0 + t)
        q = np.array([r, (R[2, 1] - R[1, 2]) / r, (R[0, 2] - R[2, 0]) / r, (R[1, 0] - R[0, 1]) / r]) / 2
    elif k == 1:
        r = np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([(R[2, 1] - R[1, 2]) / r, r, (R[0, 1] + R[1, 0]) / r, (R[0, 2] + R[2, 0]) / r]) / 2
    elif k == 2:
        r = np.sqrt(1.0 - R[0, 0] + R[1, 1] - R[2, 2])
        q = np.array([(R[0, 2] - R[2, 0]) / r, (R[0, 1] + R[1, 0]) / r, r, (R[1, 2] + R[2, 1]) / r]) / 2
    else:
        r = np.sqrt(1.0 - R[0, 0] - R[1, 1] + R[2, 2])
        q = np.array([(R[1, 0] - R[0, 1]) / r, (R[0, 2] + R[2, 0]) / r, (R[1, 2] + R[2, 1]) / r, r]) / 2
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def _rotvec(R):
    """Rotation vector (3,) of a rotation matrix."""
    q = matrix_to_quat(R)
    s = np.linalg.norm(q[1:])
    return 2.0 * np.arctan2(s, q[0]) * (q[1:] / s) if s > 1e-15 else 2.0 * q[1:]


def min_jerk(s):
    """Minimum-jerk time scaling of s in [0, 1] (clipped): 10 s^3 - 15 s^4 + 6 s^5."""
    s = min(max(s, 0.0), 1.0)
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


def slerp(q0, q1, s):
    """Spherical interpolation of unit quaternions (w, x, y, z), shortest arc."""
    q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
    d = float(q0 @ q1)
    if d < 0.0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + s * (q1 - q0)
        return q / np.linalg.norm(q)
    th = np.arccos(d)
    return (np.sin((1 - s) * th) * q0 + np.sin(s * th) * q1) / np.sin(th)


def look_at_quat(eye, target, up=(0.0, 0.0, 1.0)):
    """Quaternion of a MuJoCo camera (or its body) at ``eye`` looking at ``target``:
    the camera looks down its -z with +y up."""
    f = np.asarray(target, float) - np.asarray(eye, float)
    f /= np.linalg.norm(f)
    x = np.cross(f, up)
    x /= np.linalg.norm(x)
    z = -f
    y = np.cross(z, x)
    return matrix_to_quat(np.stack([x, y, z], 1))


def _pose(p, q):
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(q)
    T[:3, 3] = p
    return T


def _rot(axis, ang):
    from polar_sim.geometry import so3_exp

    a = np.asarray(axis, float)
    return so3_exp(a / np.linalg.norm(a) * ang)


@dataclasses.dataclass
class Segment:
    """One smooth move from pose A to pose B over [t0, t1].

    ``kind == "hand"``: A, B are hand poses (position (3,), quaternion (4,)).
    ``kind == "held"``: A, B are poses of the held object's pivot (a point ``pivot`` in the object
    frame, e.g. its centre); the object follows them and the hand sits at ``grasp`` = T_obj_hand.
    """

    t0: float
    t1: float
    phase: str
    kind: str
    A: tuple
    B: tuple
    obj: str | None = None
    pivot: np.ndarray | None = None
    grasp: np.ndarray | None = None

    def at(self, t):
        s = min_jerk((t - self.t0) / max(self.t1 - self.t0, 1e-9))
        p = self.A[0] + s * (self.B[0] - self.A[0])
        return p, slerp(self.A[1], self.B[1], s)

    def object_pose(self, t):
        p, q = self.at(t)
        R = quat_to_matrix(q)
        return _pose(p - R @ self.pivot, q)


class _Plan:
    """Appends segments from the end of the previous one."""

    def __init__(self, t0, hand):
        self.t = t0
        self.hand = hand  # (p, q)
        self.segs = []

    def move(self, pose, dur, phase):
        pose = (np.asarray(pose[0], float), np.asarray(pose[1], float))
        self.segs.append(Segment(self.t, self.t + dur, phase, "hand", self.hand, pose))
        self.t += dur
        self.hand = pose

    def reach(self, pose, phase, speed=0.22, min_dur=0.6):
        d = np.linalg.norm(np.asarray(pose[0]) - self.hand[0])
        self.move(pose, max(min_dur, d / speed), phase)

    def hold(self, dur, phase):
        self.move(self.hand, dur, phase)

    def held(self, obj, pivot, grasp, A, B, dur, phase):
        self.segs.append(Segment(self.t, self.t + dur, phase, "held", A, B, obj, pivot, grasp))
        self.t += dur
        R = quat_to_matrix(B[1])
        Th = _pose(B[0] - R @ pivot, B[1]) @ grasp
        self.hand = (Th[:3, 3].copy(), matrix_to_quat(Th[:3, :3]))


class HandScript:
    """The tabletop script: a list of actions on the target, run one after another.

    Parameters
    ----------
    actions : list of str
        Names from :data:`ACTIONS`, each optionally with parameters: ``("push", {"dir": -1})``.
    target : str
        The body the actions work on.
    objects : list of str
        Movable object bodies (free joints).
    samples : dict
        ``{object: (n, 3) surface points in the object frame}``, used to place the hand.
    camera_pos : (3,)
        Where the camera stands (the hand keeps its fingers toward it when grasping).
    home : (p, q)
        The hand's resting pose, out of view.
    table_z : float
        Height of the table top, m.
    rng_seed : int
        Seed of the small random choices (turn angle, approach yaw).
    cycle : bool
        Start over after the last action (``demo``); otherwise rest at home.
    light : callable or None
        ``scale(t)`` multiplying the key light's diffuse colour.
    camera : callable or None
        ``(p, q) = pose(t)`` of the camera rig (a mocap body); None keeps it still.
    key_light : str
        The light that ``light`` scales.
    speed : float
        Multiplies the speed of the reaching and held motions.
    """

    def __init__(self, actions, target, objects, samples, camera_pos, home, table_z, rng_seed,
                 *, cycle=False, light=None, camera=None, key_light="key", speed=1.0):
        self.actions = [a if isinstance(a, tuple) else (a, {}) for a in actions]
        if not self.actions or any(a[0] not in ACTIONS for a in self.actions):
            raise ValueError(f"actions: expected a non-empty list of {', '.join(ACTIONS)}, got {actions!r}")
        self.target = target
        self.objects = list(objects)
        self.samples = samples
        self.camera_pos = np.asarray(camera_pos, float)
        self.home = (np.asarray(home[0], float), np.asarray(home[1], float))
        self.table_z = float(table_z)
        self.rng_seed = int(rng_seed)
        self.cycle = cycle
        self.light = light
        self.camera = camera
        self.key_light = key_light
        self.speed = speed
        self._ids = None

    # -- World's script protocol -----------------------------------------------------------
    def reset(self, model, data):
        self._bind(model)
        self._rng = np.random.default_rng(self.rng_seed)
        self._grab(model, self.target, False)
        model.light_diffuse[self._light] = self._light0
        self._segs, self._k, self._next_action, self._held = [], 0, 0, None
        self._plan_end = 0.0
        self._phase = "rest"
        self._set_hand(data, self.home)
        if self.camera is not None:
            self._set_rig(data, self.camera(0.0))
        # Let the objects settle on the table so that t = 0 starts at rest.
        for _ in range(int(round(0.25 / model.opt.timestep))):
            mujoco.mj_step(model, data)
        data.time = 0.0
        data.qvel[:] = 0.0
        self._update(model, data)

    def apply(self, model, data):
        self._update(model, data)

    def after_step(self, model, data):
        # Bring mocap, held object, light and contacts to data.time exactly: mj_step leaves the
        # kinematics one substep behind the integrated state.
        self._update(model, data)
        mujoco.mj_forward(model, data)

    def truth(self, model, data):
        hand = set(self._hand_geoms)
        tgt = set(self._obj_geoms[self.target])
        contact = self._held == self.target
        for i in range(data.ncon):
            g1, g2 = data.contact.geom1[i], data.contact.geom2[i]
            if (g1 in hand and g2 in tgt) or (g2 in hand and g1 in tgt):
                contact = True
                break
        return {"in_contact": bool(contact), "grasped": self._held == self.target,
                "held": self._held, "phase": self._phase, "light_scale": float(self._light_scale)}

    # -- internals -------------------------------------------------------------------------
    def _bind(self, model):
        if self._ids is not None:
            return
        self._ids = True
        self._mocap = model.body_mocapid[model.body("hand").id]
        self._rig = model.body_mocapid[model.body("camera_rig").id] if self.camera is not None else None
        self._hand_geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == model.body("hand").id]
        self._obj_geoms = {}
        self._qadr, self._vadr = {}, {}
        from polar_sim.sim.actors.robots import GROUP

        for o in self.objects:
            b = model.body(o).id
            self._obj_geoms[o] = [g for g in range(model.ngeom)
                                  if model.geom_bodyid[g] == b and model.geom_group[g] == GROUP["collision"]]
            j = model.body_jntadr[b]
            self._qadr[o], self._vadr[o] = model.jnt_qposadr[j], model.jnt_dofadr[j]
        self._light = model.light(self.key_light).id
        self._light0 = model.light_diffuse[self._light].copy()

    def _set_hand(self, data, pose):
        data.mocap_pos[self._mocap] = pose[0]
        data.mocap_quat[self._mocap] = pose[1]

    def _set_rig(self, data, pose):
        data.mocap_pos[self._rig] = pose[0]
        data.mocap_quat[self._rig] = pose[1]

    def _object_pose(self, data, o):
        a = self._qadr[o]
        return _pose(data.qpos[a : a + 3], data.qpos[a + 3 : a + 7])

    def _grab(self, model, o, on):
        g = self._obj_geoms[o]
        bits = COLLIDE_STATIC if on else COLLIDE_OBJECT
        model.geom_contype[g] = bits
        model.geom_conaffinity[g] = bits

    def _update(self, model, data):
        t = float(data.time)
        while t >= self._plan_end - 1e-12:
            self._plan_next(data, max(t, self._plan_end))
        while self._segs[self._k].t1 <= t and self._k + 1 < len(self._segs):
            self._k += 1
        seg = self._segs[self._k]
        self._phase = seg.phase
        held = seg.obj if seg.kind == "held" else None
        if held != self._held:
            if self._held is not None:
                self._grab(model, self._held, False)
                v = self._vadr[self._held]
                data.qvel[v : v + 6] = 0.0
            if held is not None:
                self._grab(model, held, True)
            self._held = held
        if seg.kind == "held":
            To = seg.object_pose(t)
            a, v = self._qadr[held], self._vadr[held]
            data.qpos[a : a + 3] = To[:3, 3]
            data.qpos[a + 3 : a + 7] = matrix_to_quat(To[:3, :3])
            h = 1e-3
            T1, T0 = seg.object_pose(t + h), seg.object_pose(t - h)
            data.qvel[v : v + 3] = (T1[:3, 3] - T0[:3, 3]) / (2 * h)
            # Free-joint angular velocity is in the body frame.
            data.qvel[v + 3 : v + 6] = _rotvec(T0[:3, :3].T @ T1[:3, :3]) / (2 * h)
            Th = To @ seg.grasp
            self._set_hand(data, (Th[:3, 3], matrix_to_quat(Th[:3, :3])))
        else:
            self._set_hand(data, seg.at(t))
        self._light_scale = 1.0 if self.light is None else float(self.light(t))
        model.light_diffuse[self._light] = self._light0 * self._light_scale
        if self.camera is not None:
            self._set_rig(data, self.camera(t))

    def _plan_next(self, data, t0):
        hand = (data.mocap_pos[self._mocap].copy(), data.mocap_quat[self._mocap].copy())
        plan = _Plan(t0, hand)
        if self._next_action >= len(self.actions):
            if self.cycle:
                self._next_action = 0
            else:
                plan.reach(self.home, "return")
                plan.hold(1e6, "rest")
        if self._next_action < len(self.actions):
            name, params = self.actions[self._next_action]
            self._next_action += 1
            To = self._object_pose(data, self.target)
            getattr(self, f"_plan_{name}")(plan, To, params)
            if self._next_action >= len(self.actions) and not self.cycle:
                plan.reach(self.home, "return")
                plan.hold(1e6, "rest")
        self._segs = self._segs[self._k:] + plan.segs if self._segs else plan.segs
        self._k = 0
        self._plan_end = plan.t

    # -- geometry of a grasp -----------------------------------------------------------------
    def _world_samples(self, To):
        P = self.samples[self.target]
        return P @ To[:3, :3].T + To[:3, 3]

    def _toward_camera(self, To):
        d = self.camera_pos[:2] - To[:2, 3]
        return d / np.linalg.norm(d)

    def _top_grasp(self, To, gap_side, gap_top, yaw_pref=0.0):
        """Hand pose (p, q) of a top grasp: palm ``gap_top`` above the object's top, fingers
        ``gap_side`` off its side facing the camera (negative: pressing into it). The approach
        yaw is the camera direction turned by the offset closest to ``yaw_pref`` for which the
        object fits between the fingers and the thumb."""
        P = self._world_samples(To)
        top = P[:, 2].max()
        near = P[P[:, 2] > top + TIP_Z + FINGER_R]
        u0 = self._toward_camera(To)
        best = None
        d = np.radians(np.arange(-80, 81, 5))
        for off in yaw_pref + d[np.argsort(np.abs(d), kind="stable")]:
            c, s = np.cos(off), np.sin(off)
            u = np.array([c * u0[0] - s * u0[1], s * u0[0] + c * u0[1], 0.0])
            x = np.cross(u, [0.0, 0.0, 1.0])
            lat = near @ x
            mid = 0.5 * (lat.max() + lat.min())
            band = near[np.abs(lat - mid) < PALM_HALF[0] + 0.005]
            depth = np.ptp(band @ u)
            if best is None or depth < best[0] - 1e-9:
                best = (depth, u, x, mid, band)
            if depth <= GRASP_SPAN - 0.006:
                best = (depth, u, x, mid, band)
                break
        _, u, x, mid, band = best
        along = (band @ u).max() + gap_side - FINGER_INNER
        p = along * u + mid * x
        p[2] = top + PALM_HALF[2] + gap_top
        R = np.stack([x, u, [0.0, 0.0, 1.0]], 1)
        return p, matrix_to_quat(R)

    def _approach(self, plan, pose, phase="reach"):
        """Reach a pose from above: over it at a safe height, then straight down."""
        above = pose[0].copy()
        above[2] = max(above[2] + 0.10, self.table_z + 0.32)
        plan.reach((above, pose[1]), phase, speed=0.25 * self.speed)
        plan.move(pose, 0.8 / self.speed, "descend")

    def _leave(self, plan):
        p = plan.hand[0].copy()
        p[2] = max(p[2] + 0.10, self.table_z + 0.32)
        plan.move((p, plan.hand[1]), 0.7 / self.speed, "withdraw")

    def _pivot(self, To):
        top = self.samples[self.target][:, 2].max()
        piv = np.array([0.0, 0.0, 0.5 * top])
        return piv, (To[:3, :3] @ piv + To[:3, 3], matrix_to_quat(To[:3, :3]))

    # -- actions -----------------------------------------------------------------------------
    def _plan_touch(self, plan, To, prm):
        """Rest the palm on the object's top (pressing 1 mm), fingers over its front, then leave."""
        pose = self._top_grasp(To, 0.0035, -0.0003, self._yaw(prm, "front"))
        self._approach(plan, pose)
        plan.hold(prm.get("hold", 1.6), "touch")
        p = pose[0].copy()
        p[2] += 0.0001  # ease off a little, still touching
        plan.move((p, pose[1]), 0.8, "touch")
        self._leave(plan)

    def _plan_push(self, plan, To, prm):
        """Push the object ``dist`` metres along world ±x with the outside of the fingers."""
        sign = float(prm.get("dir", 1.0))
        dist = float(prm.get("dist", 0.10))
        v = np.array([sign, 0.0, 0.0])
        x = np.cross(v, [0.0, 0.0, 1.0])
        P = self._world_samples(To)
        low = P[P[:, 2] < self.table_z + 0.04]
        mid = 0.5 * ((low @ x).max() + (low @ x).min())
        # Start clear of every part of the object in the hand's path (overhangs included), so
        # the hand comes down beside it, never onto it.
        band = P[np.abs(P @ x - mid) < PALM_HALF[0] + 0.01]
        gap = (low @ v).min() - (band @ v).min()
        start = ((band @ v).min() - FINGER_OUTER - 0.02) * v + mid * x
        start[2] = self.table_z + 0.007 - TIP_Z
        q = matrix_to_quat(np.stack([x, v, [0.0, 0.0, 1.0]], 1))
        self._approach(plan, (start, q))
        travel = dist + gap + 0.02
        plan.move((start + travel * v, q), travel / 0.06, "push")
        plan.hold(0.4, "push")
        plan.move((start + (travel - 0.015) * v, q), 0.4, "release")
        self._leave(plan)

    def _yaw(self, prm, default):
        """Approach yaw (rad) relative to the camera direction: ``approach`` "front" puts the
        fingers on the camera's side of the object (most occlusion), "side" brings the hand in
        from the right (fingers on the object's left), "left" from the left; plus ``yaw``
        (default: seeded, +-0.3 rad)."""
        a = prm.get("approach", default)
        if a not in APPROACHES:
            raise ValueError(f"approach: unknown value {a!r}; expected one of {', '.join(map(repr, APPROACHES))}")
        jitter = prm.get("yaw")
        return APPROACHES[a] + (self._rng.uniform(-0.3, 0.3) if jitter is None else float(jitter))

    def _grasp_and(self, plan, To, moves, hp):
        """Top-grasp the target with the hand at ``hp`` (p, q), carry its pivot through
        ``moves`` = [(dp (3,), R (3, 3) applied in the world about the pivot, duration, phase)],
        then let go (the last move should put it back on the table)."""
        self._approach(plan, hp)
        plan.hold(0.3, "grasp")
        piv, A = self._pivot(To)
        G = np.linalg.inv(To) @ _pose(*hp)
        R0 = To[:3, :3]
        cur = A
        for dp, R, dur, phase in moves:
            nxt = (A[0] + np.asarray(dp, float), matrix_to_quat(R @ R0))
            plan.held(self.target, piv, G, cur, nxt, dur / self.speed, phase)
            cur = nxt
        plan.hold(0.3, "release")
        self._leave(plan)

    def _grasp_pose(self, To, prm):
        return self._top_grasp(To, 0.0035, 0.002, self._yaw(prm, "side"))

    def _away(self, hp, To, ang_deg):
        """``ang_deg`` with the sign that turns the forearm away from the camera, not toward it."""
        fore = -quat_to_matrix(hp[1])[:, 1]
        u = np.array([*self._toward_camera(To), 0.0])
        a = abs(np.radians(ang_deg))
        return min((a, -a), key=lambda x: float((_rot([0, 0, 1], x) @ fore) @ u))

    def _plan_lift(self, plan, To, prm):
        """Lift 15 cm, tilt toward the camera and turn a little, bring it back, put it down."""
        hp = self._grasp_pose(To, prm)
        h = float(prm.get("height", 0.15))
        u = self._toward_camera(To)
        tilt = _rot(np.cross([0.0, 0.0, 1.0], [u[0], u[1], 0.0]), np.radians(prm.get("tilt_deg", 30)))
        yaw = _rot([0, 0, 1], self._away(hp, To, prm.get("yaw_deg", 35)))
        I = np.eye(3)
        up = [0, 0, h]
        self._grasp_and(plan, To, [(up, I, 1.4, "lift"), (up, tilt, 1.2, "tilt"), (up, yaw @ tilt, 1.2, "turn"),
                                   (up, I, 1.4, "lift"), ([0, 0, 0], I, 1.4, "place")], hp)

    def _plan_turn(self, plan, To, prm):
        """Lift 3 cm, turn about the vertical by 70-100 deg, roll 30 deg and back, put it down.

        The turn swings the forearm away from the camera, which brings the fingers round to the
        camera's side; the grasp starts turned back by half the angle, so that the hand passes
        the side of the object half way and never covers its front fully."""
        yaw = self._yaw(prm, "side")
        ang = prm.get("yaw_deg")
        if ang is None:
            ang = self._rng.uniform(70, 100)
        a = self._away(self._top_grasp(To, 0.0035, 0.002, yaw), To, ang)
        hp = self._top_grasp(To, 0.0035, 0.002, yaw - a / 2)
        Rz = _rot([0, 0, 1], a)
        u = self._toward_camera(To)
        roll = _rot([u[0], u[1], 0.0], np.radians(prm.get("roll_deg", 30)))
        up = [0, 0, 0.03]
        self._grasp_and(plan, To, [(up, np.eye(3), 0.6, "lift"), (up, Rz, 2.0, "turn"),
                                   (up, roll @ Rz, 0.9, "roll"), (up, Rz, 0.9, "roll"),
                                   ([0, 0, 0], Rz, 0.6, "place")], hp)

    def _plan_fast(self, plan, To, prm):
        """Lift 10 cm and shake: 0.5 s moves of +-7 cm and +-25 deg about changing axes
        (peaks about 0.6-0.7 m/s at the base and 190 deg/s), then put it back."""
        u = self._toward_camera(To)
        x = np.cross([u[0], u[1], 0.0], [0, 0, 1.0])
        up = np.array([0, 0, 0.10])
        axes = [[0, 0, 1], x, [u[0], u[1], 0], [1, 1, 1]]
        moves = [(up, np.eye(3), 0.8, "lift")]
        n = int(prm.get("shakes", 8))
        for k in range(n):
            s = 1.0 if k % 2 == 0 else -1.0
            dp = up + s * 0.07 * x + np.array([0, 0, 0.03 * ((k // 2) % 2)])
            moves.append((dp, _rot(axes[(k // 2) % len(axes)], s * np.radians(25)), 0.5, "fast"))
        moves += [(up, np.eye(3), 0.6, "fast"), ([0, 0, 0], np.eye(3), 0.8, "place")]
        self._grasp_and(plan, To, moves, self._grasp_pose(To, prm))

    def _plan_pass(self, plan, To, prm):
        """Sweep the hand sideways through the line of sight, ``frac`` of the way from the
        object's centre to the camera, without touching anything. The fingers point along the
        sweep and the arm trails behind it; ``height`` (m) raises the path above the line on
        which the fingertips cross the object's centre, so it sets how much the hand hides."""
        piv, A = self._pivot(To)
        c = A[0]
        f = float(prm.get("frac", 0.3))
        Q = c + f * (self.camera_pos - c)
        Q[2] += -TIP_Z + float(prm.get("height", 0.0))
        u = self._toward_camera(To)
        r = np.cross([0, 0, 1.0], [u[0], u[1], 0.0])  # the camera's right, horizontal
        side = float(prm.get("dir", 1.0))  # +1: right to left
        y = -side * r
        q = matrix_to_quat(np.stack([np.cross(y, [0, 0, 1.0]), y, [0, 0, 1.0]], 1))
        a, b = Q - 0.40 * y, Q + 0.40 * y
        above = a.copy()
        above[2] = max(a[2] + 0.1, self.table_z + 0.32)
        plan.reach((above, q), "reach", speed=0.25 * self.speed)
        plan.move((a, q), 0.7, "reach")
        plan.move((b, q), float(prm.get("duration", 2.6)) / self.speed, "pass")
        self._leave(plan)


class ReachScript:
    """The tabletop script ``reach``: the hand is driven from outside, a scripted disturbance
    slides the target.

    The hand keeps its palm down (hand z = world z) and follows a velocity command set with
    :meth:`command`: a world-frame linear velocity (m/s) and a yaw rate about world z (rad/s),
    integrated at every physics substep. The palm centre stays inside ``workspace`` (a box,
    metres): a command that would leave it stops at the boundary along that axis. The hand collides
    with the target only, as in the other scripts, so it can push it.

    The target rests for 0.3-1.0 s, then slides along the table by 4-10 cm in a seeded direction
    while turning by up to +-0.5 rad about the vertical, in 0.8-1.4 s (minimum-jerk), rests for
    0.8-2.0 s, slides again, and so on. Each slide starts from the target's actual pose (the hand may
    have pushed it) and keeps its base centre inside ``region`` (x0, x1, y0, y1), m. While it
    slides the target is moved kinematically (free-joint position and velocity written, as a held
    object in Mode A) and does not collide with the hand; physics takes over when it stops.

    Parameters
    ----------
    target : str
        The body the disturbance moves.
    objects : list of str
        Movable object bodies (free joints).
    home : (p, q)
        The hand's starting pose (palm down; its yaw is read from q).
    table_z : float
        Height of the table top, m.
    rng_seed : int
        Seed of the disturbance (times, directions, distances, turns).
    region : (4,) floats
        Box (x0, x1, y0, y1) the target's base centre stays in while it slides, m.
    workspace : (6,) floats
        Box (x0, x1, y0, y1, z0, z1) the palm centre stays in, m.
    """

    def __init__(self, target, objects, home, table_z, rng_seed, *, region, workspace):
        self.target = target
        self.objects = list(objects)
        self.home = (np.asarray(home[0], float), np.asarray(home[1], float))
        self.table_z = float(table_z)
        self.rng_seed = int(rng_seed)
        self.region = np.asarray(region, float)
        self.workspace = np.asarray(workspace, float)
        self._ids = None
        self._cmd = (np.zeros(3), 0.0)

    def command(self, velocity, yaw_rate):
        """Set the hand's velocity (3,) m/s (world frame) and yaw rate (rad/s, about world z) until
        the next call. Raises ``ValueError`` on non-finite values."""
        v = np.asarray(velocity, dtype=np.float64).reshape(-1)
        w = float(yaw_rate)
        if v.shape != (3,) or not np.isfinite(v).all() or not np.isfinite(w):
            raise ValueError(f"velocity, yaw_rate: expected finite (3,) and a finite number, got {velocity!r}, "
                             f"{yaw_rate!r}")
        self._cmd = (v.copy(), w)

    # -- World's script protocol -----------------------------------------------------------
    def reset(self, model, data):
        if self._ids is None:
            self._ids = True
            self._mocap = model.body_mocapid[model.body("hand").id]
            self._hand_geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == model.body("hand").id]
            from polar_sim.sim.actors.robots import GROUP

            b = model.body(self.target).id
            self._tgt_geoms = [g for g in range(model.ngeom)
                               if model.geom_bodyid[g] == b and model.geom_group[g] == GROUP["collision"]]
            j = model.body_jntadr[b]
            self._qadr, self._vadr = model.jnt_qposadr[j], model.jnt_dofadr[j]
        self._rng = np.random.default_rng(self.rng_seed)
        self._cmd = (np.zeros(3), 0.0)
        self._p = self.home[0].copy()
        R = quat_to_matrix(self.home[1])
        self._yaw = float(np.arctan2(R[1, 0], R[0, 0]))
        self._set_collide(model, True)
        self._slide = None
        self._phase = "rest"
        self._write_hand(data)
        # Let the objects settle on the table so that t = 0 starts at rest.
        for _ in range(int(round(0.25 / model.opt.timestep))):
            mujoco.mj_step(model, data)
        data.time = 0.0
        data.qvel[:] = 0.0
        self._t = 0.0
        self._next_slide = float(self._rng.uniform(0.3, 1.0))
        mujoco.mj_forward(model, data)

    def apply(self, model, data):
        self._update(model, data)

    def after_step(self, model, data):
        self._update(model, data)
        mujoco.mj_forward(model, data)

    def truth(self, model, data):
        hand, tgt = set(self._hand_geoms), set(self._tgt_geoms)
        contact = False
        for i in range(data.ncon):
            g1, g2 = data.contact.geom1[i], data.contact.geom2[i]
            if (g1 in hand and g2 in tgt) or (g2 in hand and g1 in tgt):
                contact = True
                break
        return {"in_contact": contact, "grasped": False, "held": None, "phase": self._phase,
                "light_scale": 1.0}

    # -- internals -------------------------------------------------------------------------
    def _write_hand(self, data):
        data.mocap_pos[self._mocap] = self._p
        data.mocap_quat[self._mocap] = [np.cos(self._yaw / 2), 0.0, 0.0, np.sin(self._yaw / 2)]

    def _set_collide(self, model, hand_too):
        bits = COLLIDE_OBJECT if hand_too else COLLIDE_STATIC
        model.geom_contype[self._tgt_geoms] = bits
        model.geom_conaffinity[self._tgt_geoms] = bits

    def _update(self, model, data):
        t = float(data.time)
        dt = t - self._t
        self._t = t
        if dt > 0:
            v, w = self._cmd
            ws = self.workspace
            self._p = np.clip(self._p + v * dt, ws[0::2], ws[1::2])
            self._yaw = float((self._yaw + w * dt + np.pi) % (2 * np.pi) - np.pi)
        self._write_hand(data)
        if self._slide is None and t >= self._next_slide:
            self._plan_slide(model, data, t)
        if self._slide is not None:
            self._move_target(model, data, t)

    def _target_pose(self, data):
        a = self._qadr
        return _pose(data.qpos[a : a + 3], data.qpos[a + 3 : a + 7])

    def _plan_slide(self, model, data, t):
        rng = self._rng
        To = self._target_pose(data)
        dur = float(rng.uniform(0.8, 1.4))
        dist = float(rng.uniform(0.04, 0.10))
        turn = float(rng.uniform(-0.5, 0.5))
        x0, x1, y0, y1 = self.region
        p = To[:2, 3]
        d = None
        for _ in range(16):
            phi = rng.uniform(-np.pi, np.pi)
            q = p + dist * np.array([np.cos(phi), np.sin(phi)])
            if x0 <= q[0] <= x1 and y0 <= q[1] <= y1:
                d = q - p
                break
        if d is None:  # pushed out of the region: slide back toward its centre
            c = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
            d = (c - p) * min(1.0, dist / max(np.linalg.norm(c - p), 1e-9))
        self._slide = (t, t + dur, To, np.array([d[0], d[1], 0.0]), turn)
        self._phase = "slide"
        self._set_collide(model, False)

    def _move_target(self, model, data, t):
        t0, t1, To, dp, turn = self._slide
        a, v = self._qadr, self._vadr
        if t >= t1:
            T = self._slide_pose(1.0)
            data.qpos[a : a + 3] = T[:3, 3]
            data.qpos[a + 3 : a + 7] = matrix_to_quat(T[:3, :3])
            data.qvel[v : v + 6] = 0.0
            self._slide = None
            self._phase = "rest"
            self._set_collide(model, True)
            self._next_slide = t + float(self._rng.uniform(0.8, 2.0))
            return
        T = self._slide_pose(min_jerk((t - t0) / (t1 - t0)))
        data.qpos[a : a + 3] = T[:3, 3]
        data.qpos[a + 3 : a + 7] = matrix_to_quat(T[:3, :3])
        h = 1e-3
        T1 = self._slide_pose(min_jerk((t + h - t0) / (t1 - t0)))
        T0 = self._slide_pose(min_jerk((t - h - t0) / (t1 - t0)))
        data.qvel[v : v + 3] = (T1[:3, 3] - T0[:3, 3]) / (2 * h)
        # Free-joint angular velocity is in the body frame.
        data.qvel[v + 3 : v + 6] = _rotvec(T0[:3, :3].T @ T1[:3, :3]) / (2 * h)

    def _slide_pose(self, s):
        _, _, To, dp, turn = self._slide
        T = To.copy()
        T[:3, :3] = _rot([0.0, 0.0, 1.0], s * turn) @ To[:3, :3]
        T[:3, 3] = To[:3, 3] + s * dp
        return T
