"""Scripted baseline policies for the environments (``polar-sim eval --policy MODULE:CALLABLE``).

A policy is a callable ``policy(obs) -> action``; classes here keep their own state and expose
``reset()``, which the evaluator calls at the start of every episode.
"""

from __future__ import annotations

import numpy as np

from polar_sim.control import PurePursuit
from polar_sim.envs._gridplan import ObstacleMemory, cost_to_go

__all__ = ["SDFReactive", "SDFPotentialField", "SDFNavigator", "PurePursuitVO", "VisualServoReach"]


def _angle(v):
    return float(np.arctan2(v[1], v[0]))


class SDFReactive:
    """An SDF-gradient reactive controller for ``GPISNav-v0`` (a distance-based Bug algorithm).

    It reads only the SDF stencil and the goal, both in the robot frame. Each stencil point p
    with distance d and gradient g gives a surface point estimate s = p - d g (the gradient
    points away from the surface); the nearest of these is the nearest obstacle.

    - **Go**: head for the goal, pushed away from surfaces closer than ``safe``.
    - **Follow**: when the way to the goal is blocked, keep the obstacle at ``follow_distance``
      and move along its tangent (the gradient turned by 90 degrees), on the side that first
      points toward the goal. Leave when the goal is nearer than where following began (by
      ``leave_margin``) and the way to it is clear. This escapes the dead ends that trap a pure
      potential field. Blocked again no nearer to the goal than the previous time, it follows
      the other way round. Like Bug algorithms it keeps only distances to the goal as memory.

    Parameters
    ----------
    safe : float
        Clearance (m) below which surfaces repel in go mode, and the blocked test's clearance.
    follow_distance : float
        Distance (m) kept from the obstacle while following it.
    max_var : float
        Stencil points with map variance above this are ignored (unknown space).
    leave_margin : float
        How much nearer to the goal (m) the robot must be before it stops following.
    patience : int
        Steps of following without getting nearer after which it follows the other way.
    """

    def __init__(self, safe=0.6, follow_distance=0.55, max_var=0.5, leave_margin=0.3, patience=150,
                 stencil_rays=16, stencil_radii=(0.5, 1.0, 2.0, 3.0)):
        from polar_sim.envs.observers import SDFStencil

        self.safe = float(safe)
        self.follow_distance = float(follow_distance)
        self.max_var = float(max_var)
        self.leave_margin = float(leave_margin)
        self.patience = int(patience)
        self._points = SDFStencil(stencil_rays, stencil_radii).points_robot
        self.reset()

    def reset(self):
        self._mode = "go"
        self._d_hit = np.inf
        self._last_hit = np.inf
        self._side = 1.0
        self._steps = 0

    def _surface_points(self, obs):
        d = np.asarray(obs["sdf"], float)
        g = np.asarray(obs["sdf_grad"], float).reshape(-1, 2)
        ok = (np.asarray(obs["sdf_var"], float) < self.max_var) & (d < 1.5)
        norm = np.linalg.norm(g, axis=1)
        ok &= norm > 0.3
        g = g / np.maximum(norm, 1e-9)[:, None]
        return self._points[ok] - d[ok, None] * g[ok]

    def _clearance(self, s, direction, half_width):
        """Distance (m) to the nearest surface point within ``half_width`` m of the ray along
        ``direction`` (robot frame), ahead of the robot."""
        u = direction / max(np.linalg.norm(direction), 1e-9)
        along = s @ u
        across = np.abs(s @ np.array([-u[1], u[0]]))
        hit = (along > 0) & (across < half_width)
        return float(along[hit].min()) if hit.any() else np.inf

    def __call__(self, obs):
        goal = np.asarray(obs["goal"], float)
        dg = float(np.linalg.norm(goal))
        to_goal = goal / max(dg, 1e-9)
        s = self._surface_points(obs)
        ds = np.linalg.norm(s, axis=1) if len(s) else np.zeros(0)
        blocked = bool(len(s)) and self._clearance(s, to_goal, 0.4) < min(self.safe + 0.2, dg)

        if self._mode == "go" and blocked:
            k = int(np.argmin(ds))
            away = -s[k] / max(ds[k], 1e-9)
            tangent = np.array([-away[1], away[0]])
            side = 1.0 if tangent @ to_goal >= 0 else -1.0
            if dg > self._last_hit - self.leave_margin:
                # Blocked again no nearer than last time: the greedy side led back here, so try
                # the other way round (alternating sides keeps the search from cycling).
                side = -self._side
            self._mode, self._d_hit, self._side, self._steps = "follow", dg, side, 0
            self._last_hit = min(dg, self._last_hit)
        elif self._mode == "follow":
            self._steps += 1
            if dg < self._d_hit - self.leave_margin and not blocked:
                self._mode = "go"
            elif self._steps > self.patience:
                # Following for long without getting nearer (circling clutter): turn back.
                self._side, self._d_hit, self._steps = -self._side, dg, 0

        if self._mode == "go" or not len(s):
            direction = to_goal + 1.5 * self._repulsion(s, ds)
        else:
            # The followed surface is on the robot's left for side +1, right for side -1; keep
            # to points on that side (or nearly ahead) so a doorway's far jamb is not mistaken
            # for the wall being followed.
            on_side = self._side * s[:, 1] > -0.15
            cand = np.where(on_side, ds, np.inf)
            k = int(np.argmin(cand)) if np.isfinite(cand).any() else int(np.argmin(ds))
            d_near = float(ds[k])
            away = -s[k] / max(d_near, 1e-9)
            tangent = self._side * np.array([-away[1], away[0]])
            direction = tangent + 2.0 * (self.follow_distance - d_near) * away
        return self._steer(direction, s, dg if self._mode == "go" else np.inf)

    def _repulsion(self, s, ds):
        """Sum of unit pushes away from surface points nearer than ``safe``, weighted by depth."""
        close = ds < self.safe
        if not close.any():
            return np.zeros(2)
        w = (self.safe - ds[close]) / self.safe
        return -(w[:, None] * s[close] / ds[close, None]).sum(0)

    def _steer(self, direction, s, dg):
        """The action that turns toward ``direction`` (robot frame) and drives as the clearance
        ahead allows, slowing within 1 m of the goal (``dg``, m)."""
        heading = _angle(direction)
        omega = float(np.clip(1.8 * heading, -1.0, 1.0))
        # The chassis reaches 0.3 m ahead and the wheels 0.33 m to the side: slow down from
        # 0.9 m ahead, stop at 0.4 m.
        ahead = self._clearance(s, np.array([1.0, 0.0]), 0.4) if len(s) else np.inf
        v = 0.9 * max(np.cos(heading), 0.0) ** 2 * float(np.clip((ahead - 0.4) / 0.5, 0.0, 1.0))
        v *= min(1.0, dg)
        return np.array([v, omega], dtype=np.float32)


class SDFPotentialField(SDFReactive):
    """``SDFReactive`` without its follow state: head for the goal, pushed off surfaces nearer
    than ``safe``. The classic potential field, and what a memoryless policy gets for free; it
    stalls wherever a wall stands between the robot and the goal."""

    def __call__(self, obs):
        goal = np.asarray(obs["goal"], float)
        dg = float(np.linalg.norm(goal))
        s = self._surface_points(obs)
        ds = np.linalg.norm(s, axis=1) if len(s) else np.zeros(0)
        return self._steer(goal / max(dg, 1e-9) + 1.5 * self._repulsion(s, ds), s, dg)


class SDFNavigator(SDFReactive):
    """The SDF-gradient reactive controller steered by a remembered map, for ``GPISNav-v0``.

    It reads what ``SDFReactive`` reads (the stencil, the goal in the robot frame and the
    twist) and adds memory. The goal vector fixes the robot's position relative to the goal, and
    the heading of the estimated ``pose`` (GPISNav-v1; in v0 the integrated yaw rate) fixes its
    heading; in that goal-anchored frame it keeps an obstacle
    grid, marking the stencil's surface estimates s = p - d g and clearing the disk of radius d
    around every stencil point, which the SDF says is free. Each step it plans the cheapest
    path to the goal on that grid, taking unknown cells as free (optimistic planning), and steers
    toward the path point ``lookahead`` m ahead, with ``SDFReactive``'s repulsion from nearby
    surfaces and its speed law. Where the grid has no path it falls back to ``SDFReactive``.

    Parameters
    ----------
    cell, inflate : float
        Grid cell (m) and obstacle inflation for planning (m).
    lookahead : float
        Distance along the planned path to the steering point, m.
    dt : float
        The environment's step, s (to integrate the yaw rate).
    half : float
        Half the side of the grid, m, centred on the goal: it must reach the start (the default
        covers GPISNav-v0's worlds; 180 x 180 cells).
    **reactive
        ``SDFReactive``'s parameters.
    """

    def __init__(self, cell=0.2, inflate=0.45, lookahead=1.0, dt=0.1, half=18.0, **reactive):
        self.cell, self.inflate, self.half = float(cell), float(inflate), float(half)
        self.lookahead = float(lookahead)
        self.dt = float(dt)
        super().__init__(**reactive)

    def reset(self):
        super().reset()
        self.memory = ObstacleMemory(self.half, self.cell, self.inflate)
        self._theta = 0.0
        self._yaw_rate = None

    def _steering_point(self, p):
        """The point ``lookahead`` m along the cheapest path from ``p`` (memory frame), or None."""
        mem = self.memory
        goal_ij = mem.index(np.zeros((1, 2)))[0]
        here = mem.index(p[None])[0]
        # Plan with the full inflation, then with a thinner one: a goal among clutter can be
        # closed off by a 20 cm grid's rounding although the rover fits.
        for inflate in (self.inflate, 0.6 * self.inflate):
            cost = mem.cost(inflate)
            # The goal and the robot's own cell stay passable: the goal is known free, and a
            # robot pressed against a wall must still be able to plan its way out.
            cost[goal_ij[0], goal_ij[1]] = 1.0
            if not np.isfinite(cost[here[0], here[1]]):
                cost[here[0], here[1]] = 1.0 + mem.clearance_weight
            # Only the cells cheaper than the robot's are walked below: the search can stop there.
            dist = cost_to_go(cost, int(goal_ij[0]), int(goal_ij[1]), until=here)
            if np.isfinite(dist[here[0], here[1]]):
                break
        else:
            return None
        ij = here.copy()
        for _ in range(max(1, int(round(self.lookahead / self.cell)))):
            i0, i1 = max(ij[0] - 1, 0), min(ij[0] + 2, mem.n)
            j0, j1 = max(ij[1] - 1, 0), min(ij[1] + 2, mem.n)
            win = dist[i0:i1, j0:j1]
            k = np.unravel_index(int(np.argmin(win)), win.shape)
            nxt = np.array([i0 + k[0], j0 + k[1]])
            if dist[nxt[0], nxt[1]] >= dist[ij[0], ij[1]]:
                break
            ij = nxt
        if (ij == here).all():
            return None
        return mem.centre(ij[None])[0]

    def __call__(self, obs):
        if "pose" in obs:
            # GPISNav-v1 observes the estimated pose: its heading anchors the memory (integrating
            # the odometry's yaw rate would carry its drift into the grid).
            self._theta = float(obs["pose"][2])
        else:
            w = float(obs["twist"][1])
            if self._yaw_rate is not None:
                self._theta += 0.5 * (self._yaw_rate + w) * self.dt  # trapezoidal rule
            self._yaw_rate = w
        c, sn = np.cos(self._theta), np.sin(self._theta)
        R = np.array([[c, -sn], [sn, c]])
        goal = np.asarray(obs["goal"], float)
        p = -R @ goal
        s = self._surface_points(obs)
        d = np.asarray(obs["sdf"], float)
        free = (np.asarray(obs["sdf_var"], float) < self.max_var) & (d > 0.25)
        radius = np.minimum(d[free], 3.0) - 0.15
        self.memory.add(p + s @ R.T, p + self._points[free] @ R.T, radius)

        target = self._steering_point(p)
        if target is None:
            return super().__call__(obs)
        dg = float(np.linalg.norm(goal))
        ds = np.linalg.norm(s, axis=1) if len(s) else np.zeros(0)
        to_target = R.T @ (target - p)
        to_target /= max(np.linalg.norm(to_target), 1e-9)
        return self._steer(to_target + 1.5 * self._repulsion(s, ds), s, dg)


class PurePursuitVO:
    """Pure pursuit on visual odometry for ``GroundVO-v0``: steer onto the waypoint.

    It reads only ``waypoint`` (the route point a fixed distance ahead of the estimated position,
    in the estimated robot frame) and ``twist`` (the VO's speed): the arc through the waypoint has
    curvature kappa = 2 y / d^2 (:meth:`polar_sim.control.PurePursuit.curvature`), the yaw rate is
    kappa times the speed, and the speed set-point is ``speed``, lowered where the arc is tight so
    the lateral acceleration stays under ``max_lateral_accel``. From rest the set-point ramps up at
    ``accel``: a monocular VO's speed and yaw-rate filters lag a hard start, and the lag stays in
    the estimated pose for the rest of the route.

    Parameters
    ----------
    speed : float
        Cruise speed set-point, m/s.
    accel : float
        Ramp of the set-point from rest, m/s^2 (counted in steps of ``dt``).
    max_lateral_accel : float
        m/s^2; v <= sqrt(a / |kappa|).
    max_speed, max_yaw_rate : float
        The environment's ``max_speed`` (m/s) and ``max_yaw_rate`` (rad/s), to normalise the action.
    dt : float
        The environment's step, s.
    """

    def __init__(self, speed=6.0, accel=1.0, max_lateral_accel=2.0, max_speed=10.0, max_yaw_rate=1.0, dt=0.1):
        self.speed = float(speed)
        self.accel = float(accel)
        self.max_lateral_accel = float(max_lateral_accel)
        self.max_speed = float(max_speed)
        self.max_yaw_rate = float(max_yaw_rate)
        self.dt = float(dt)
        self.reset()

    def reset(self):
        self._steps = 0

    def __call__(self, obs):
        kappa = PurePursuit.curvature(*(float(c) for c in obs["waypoint"]))
        self._steps += 1
        v = min(self.speed, self.accel * self._steps * self.dt,
                np.sqrt(self.max_lateral_accel / max(abs(kappa), 1e-9)))
        # The yaw rate follows the speed the rover has (the VO's), not the set-point it is
        # still accelerating toward, so the arc is the one through the waypoint.
        v_now = float(np.clip(obs["twist"][0], 0.5, v)) if v > 0.5 else v
        omega = kappa * v_now
        return np.array([np.clip(v / self.max_speed, -1, 1), np.clip(omega / self.max_yaw_rate, -1, 1)],
                        dtype=np.float32)


class VisualServoReach:
    """A position-based visual servo for ``ObjectTrack-v0``: move the hand to the pre-grasp pose
    the tracker estimates.

    It reads ``pregrasp`` (the estimated pre-grasp pose minus the hand's: dx, dy, dz in the world,
    m, and the yaw still to turn, rad) and ``object_std`` (the tracker's uncertainty). The hand
    velocity is proportional to the error (``gain``, 1/s), capped at the environment's
    ``max_speed``; while the hand is still far off sideways it stays up to ``approach_height`` m
    above the pre-grasp height, so it comes down onto the object from above instead of sweeping
    into it. When the tracker is unsure (translation 1-sigma above ``max_std`` m) it moves at
    ``unsure_scale`` of the speed.

    Parameters
    ----------
    gain, yaw_gain : float
        Proportional gains, 1/s.
    approach_height : float
        m above the pre-grasp height kept while the horizontal error is large.
    max_std, unsure_scale : float
        Tracker uncertainty (m) above which to slow down, and the speed factor then.
    max_speed, max_yaw_rate : float
        The environment's ``max_speed`` (m/s) and ``max_yaw_rate`` (rad/s), to normalise the action.
    """

    def __init__(self, gain=4.0, yaw_gain=3.0, approach_height=0.08, max_std=0.02, unsure_scale=0.3,
                 max_speed=0.3, max_yaw_rate=1.5):
        self.gain = float(gain)
        self.yaw_gain = float(yaw_gain)
        self.approach_height = float(approach_height)
        self.max_std = float(max_std)
        self.unsure_scale = float(unsure_scale)
        self.max_speed = float(max_speed)
        self.max_yaw_rate = float(max_yaw_rate)

    def reset(self):
        pass

    def __call__(self, obs):
        d = np.asarray(obs["pregrasp"], dtype=np.float64)
        e = d[:3].copy()
        lateral = float(np.hypot(e[0], e[1]))
        e[2] += min(self.approach_height, 1.5 * lateral)
        v = self.gain * e
        speed = float(np.linalg.norm(v))
        cap = self.max_speed
        if float(np.max(np.asarray(obs["object_std"], dtype=np.float64)[3:])) > self.max_std:
            cap *= self.unsure_scale
        if speed > cap:
            v *= cap / speed
        w = float(np.clip(self.yaw_gain * d[3], -self.max_yaw_rate, self.max_yaw_rate))
        return np.clip(np.append(v / self.max_speed, w / self.max_yaw_rate), -1.0, 1.0).astype(np.float32)
