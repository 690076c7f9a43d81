"""LidarNav: the raw task of goal-reaching navigation in seeded cluttered indoor worlds."""

from __future__ import annotations

import dataclasses

import numpy as np
from gymnasium import spaces

from polar_sim._validation import as_float
from polar_sim.envs import _pose2d
from polar_sim.envs._gridplan import GeodesicDistance
from polar_sim.envs.base import PolarMujocoEnv, check_kwargs
from polar_sim.envs.noise import LIDAR_NOISE, ODOMETRY_NOISE, WheelOdometry, as_lidar_noise, as_odometry_noise
from polar_sim.geometry import between2d

__all__ = ["LidarNavEnv", "NavTask", "TIERS", "DEFAULT_TIER", "resolve_tier", "REWARD_V0", "REWARD_V1",
           "as_reward_weights"]

GOAL_RADIUS = 0.4  # m
COLLISION_PENALTY = 5.0
SUCCESS_BONUS = 5.0
TIME_COST = 0.01
LIDAR_MAX = 30.0
MAX_LAYOUT_ATTEMPTS = 20  # navworld layouts tried per reset before its error is raised

#: v0's reward weights (progress per m, time per step, collision, success, proximity per step, m).
REWARD_V0 = {"progress": 1.0, "time": TIME_COST, "collision": COLLISION_PENALTY, "success": SUCCESS_BONUS,
             "proximity": 0.0, "proximity_radius": 0.3}
#: v1's default reward weights: a collision costs 1 instead of 5, and a clearance under 0.3 m
#: costs up to 0.02 per step (chosen on dev worlds, seeds 1000-1019, among collision 5 / 1 and
#: proximity 0 / 0.02, by 12k-step PPO runs; see ``LidarNavEnv``'s Reward section).
REWARD_V1 = {**REWARD_V0, "collision": 1.0, "proximity": 0.02}

#: Difficulty tiers: the world each one builds (rooms per side, room side in m, clutter pieces).
TIERS = {
    "room": {"rooms": 1, "room_size": 6.0, "clutter": 6},
    "rooms2": {"rooms": 2, "room_size": 4.0, "clutter": 6},
    "rooms3": {"rooms": 3, "room_size": 4.0, "clutter": 10},
}
DEFAULT_TIER = "rooms3"
_DEFAULT = "default"  # sentinel: the version's default noise


def resolve_tier(tier, rooms, room_size, clutter):
    """(rooms, room_size, clutter) of ``tier`` (None: the default), each overridden when given and
    checked against the world's limits (:func:`polar_sim.sim.builders.navworld.check_layout`) before
    anything is built."""
    from polar_sim.sim.builders.navworld import check_layout

    name = DEFAULT_TIER if tier is None else tier
    if not isinstance(name, str) or name not in TIERS:
        raise ValueError(f"tier: unknown tier {tier!r}; expected one of {', '.join(TIERS)}")
    t = TIERS[name]
    rooms = t["rooms"] if rooms is None else rooms
    clutter = t["clutter"] if clutter is None else clutter
    room_size = t["room_size"] if room_size is None else room_size
    rooms, room_size, clutter, *_ = check_layout(rooms, room_size, clutter)
    return rooms, room_size, clutter


def as_reward_weights(weights, version=1):
    """The reward weights: the version's defaults (:data:`REWARD_V1`, v0: :data:`REWARD_V0`)
    updated by ``weights`` (a dict with some of their keys, each finite and >= 0; v0 accepts
    only None, its reward being fixed)."""
    if weights is None:
        return dict(REWARD_V0 if version == 0 else REWARD_V1)
    if version == 0:
        raise ValueError("reward_weights: version 0 has a fixed reward; use the v1 ids")
    if not isinstance(weights, dict):
        raise TypeError(f"reward_weights: expected a dict with keys among {sorted(REWARD_V1)}, got {weights!r}")
    out = dict(REWARD_V1)
    for k, v in weights.items():
        if k not in REWARD_V1:
            raise ValueError(f"reward_weights: unknown key {k!r}; expected keys among {sorted(REWARD_V1)}")
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not np.isfinite(v) \
                or v < 0:
            raise ValueError(f"reward_weights: {k!r} must be a finite number >= 0, got {v!r}")
        out[k] = float(v)
    if out["proximity_radius"] <= 0:
        raise ValueError(f"reward_weights: 'proximity_radius' must be > 0, got {out['proximity_radius']!r}")
    return out


def _positive(x, name, upper=None):
    """A finite number in (0, upper] (an int or float; strings and booleans are refused)."""
    return as_float(x, name, minimum=0.0, exclusive_minimum=True, maximum=upper)


@dataclasses.dataclass(frozen=True)
class NavTask:
    """What the robot is told at the start of an episode (``env.unwrapped.task``).

    Attributes
    ----------
    goal_start : (2,) the goal in the start frame (x forward, y left at the start pose), m.
    sensor_offset : (3,) the lidar's pose in the robot frame (x, y, yaw), m and rad (calibration).
    beam_angles : (n,) the lidar's beam angles in the sensor frame, rad.
    min_range, max_range : float, m; a beam with no return reads ``inf`` (30 in the observation).
    dt : float, s per step.
    extent : float, m; every position of the episode, in the world or the start frame, lies within
        this distance of the start.
    """

    goal_start: np.ndarray
    sensor_offset: np.ndarray
    beam_angles: np.ndarray
    min_range: float
    max_range: float
    dt: float
    extent: float


class LidarNavEnv(PolarMujocoEnv):
    """## Description
    The indoor rover drives to a goal in a procedurally generated world of rooms, doors and
    clutter (``navworld``; a new layout every episode, drawn from the episode seed). This raw
    task environment emits what the robot's sensors give: the 2D lidar scan and the wheel
    odometry, with the goal given once in the start frame (as PointNav without GPS+compass).
    Where the robot is must come from the user's own localisation; ``GPISNav-v1`` adds ours
    (an online GPIS map and ICP-G on it).

    Version 0 (``LidarNav-v0``, the raw base of ``GPISNav-v0``) is the GPS+compass variant: exact
    ranges, the goal in the true robot frame every step and the exact twist.

    ## Observation Space
    ``Dict``, keys sorted. Version 1:

    | key | shape | dtype | meaning |
    |---|---|---|---|
    | ``goal_start`` | (2,) | float32 | the goal in the start frame (x forward, y left at the start pose), m; the same all episode |
    | ``ranges`` | (n_beams,) | float32 | lidar ranges, m, 270 deg field of view, noisy (``lidar_noise``); no return = 30 |
    | ``twist`` | (2,) | float32 | wheel odometry: distance (m) and turn (rad) of the last step over ``dt``, i.e. speed (m/s) and yaw rate (rad/s), noisy (``odometry_noise``) |

    Version 0: ``goal`` (2,) the goal in the true robot frame, ``ranges`` exact, ``twist`` the
    exact forward speed and yaw rate.

    ## Action Space
    ``Box(-1, 1, (2,))``: normalised ``(v, omega)``; v = a0 * ``max_speed``, omega = a1 *
    ``max_yaw_rate``. Actions within 1e-6 of the box are taken as its bound; further outside the
    box or with NaN they raise ``ValueError`` and leave the environment unchanged.

    ## Reward
    ``progress`` (decrease of the shortest-path distance to the goal around the walls and
    clutter, m, as in Habitat's PointNav) − ``time`` (per step) − ``collision`` (on a collision)
    + ``success`` (on reaching the goal) − ``proximity`` (v1, per step: the weight times
    ``clip(1 − clearance / proximity_radius, 0, 1)``, the clearance being the exact scene SDF at
    the true robot position minus the robot's radius, m). The terms are in
    ``info["reward_terms"]``, each with its weight applied; the weights are ``reward_weights``
    (defaults :data:`REWARD_V1`; v0: progress 1 per m, time 0.01, collision 5, success 5, no
    proximity term). (The straight-line distance would reward pushing into a wall that stands
    between the robot and the goal.)

    Why v1's defaults differ from v0's (chosen on dev worlds, see ``benchmarks/RESULTS.md``):
    with a collision costing 5, an episode that makes 2 m of progress and then touches clutter
    returns less, discounted at 0.99, than standing still for the whole episode (−5 × 0.99^20 +
    ~1.8 against −0.01 × ~95), so a learner's first lesson was to stop, and PPO reached 0 % on
    the room tier. A collision still ends the episode and is never a success.

    ## Episode End
    Terminated when the robot is within 0.4 m of the goal (success) or touches an obstacle (a
    MuJoCo contact between a robot geom and a non-ground geom). Truncated by the ``TimeLimit``
    of the registration (600 steps = 60 s; 300 for the ``room`` tier).

    ## Arguments
    | argument | default | meaning |
    |---|---|---|
    | ``render_mode`` | None | ``"rgb_array"``: top-down view |
    | ``render_size`` | (480, 480) | (width, height) of the rendered view, pixels |
    | ``tier`` | ``"rooms3"`` | ``"room"`` (one 6 m room, 6 pieces of clutter), ``"rooms2"`` (2x2 rooms of 4 m, 6 pieces), ``"rooms3"`` (3x3 rooms of 4 m, 10 pieces) |
    | ``rooms``, ``room_size``, ``clutter`` | from ``tier`` | rooms per side, m, pieces of clutter |
    | ``n_beams`` | 270 | lidar beams |
    | ``max_speed`` | 1.0 | m/s at action 1 (the rover's limit is 1.5) |
    | ``max_yaw_rate`` | 1.5 | rad/s at action 1 (the rover's limit is 2) |
    | ``lidar_noise`` | (0.01, 0.01) | (range sigma m, dropout probability), or None; v0: None |
    | ``odometry_noise`` | ``OdometryNoise()`` | wheel odometry noise (:class:`polar_sim.envs.noise.OdometryNoise` or a dict of its fields: 3 % of each step's distance, a 2 % scale error, 3 % of each turn plus 0.01 rad/m, a yaw drift of 0.01 rad/s (1-sigma, drawn per episode)), or None; v0: None |
    | ``reward_weights`` | None | v1: a dict overriding some of :data:`REWARD_V1` (``progress`` per m, ``time`` per step, ``collision``, ``success``, ``proximity`` per step, ``proximity_radius`` m; each finite and >= 0); v0: None only |
    | ``kinematic`` | None | the rover's motion: False, the wheel physics (MuJoCo, 20 substeps of 5 ms per step, a PI wheel controller; v0, v1); True, the exact unicycle with the commanded ``(v, omega)`` (``World(kinematic="planar")``; contacts still found by MuJoCo, the world built once and given each episode's layout in place, ``World.relayout``; v2); None, the version's |
    | ``version`` | 1 | set by the registered id: 0 is ``LidarNav-v0``, 2 ``LidarNav-v2`` |

    ## Truth in ``info``
    ``robot_pose2d`` (x, y, theta, world), ``goal`` (world, m), ``goal_distance`` (straight line,
    m), ``geodesic_distance`` (shortest path for the rover, m), ``collision``, ``path_length``
    (m), ``is_success``, ``layout_seed``; version 1 also ``start_pose2d`` (the true start pose,
    world).

    ## Version History
    - v2: v1 with the kinematic rover (``kinematic=True``): each step moves it along the exact
      unicycle arc of the commanded ``(v, omega)`` instead of simulating its wheels, a collision is
      still a MuJoCo contact, and the worlds, sensors, noise, reward and observations are v1's.
      About 3x the steps per CPU-second of v1 (``benchmarks/RESULTS.md``), for learning.
    - v1: lidar noise (1 cm, 1 % dropout) and wheel odometry noise on by default; the goal is
      given once in the start frame (``goal_start``) instead of every step in the true robot
      frame; ``twist`` is the wheel odometry instead of the exact twist; difficulty tiers;
      ``reward_weights``, with a collision costing 1 instead of 5 and a proximity term.
    - v0: first release (GPS+compass: the goal in the true robot frame, exact twist, no noise).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, *, render_mode=None, render_size=(480, 480), tier=None, rooms=None, room_size=None,
                 clutter=None, n_beams=270, max_speed=1.0, max_yaw_rate=1.5, lidar_noise=_DEFAULT,
                 odometry_noise=_DEFAULT, reward_weights=None, kinematic=None, version=1, **unknown):
        check_kwargs(type(self), unknown)
        super().__init__(render_mode=render_mode, render_size=render_size)
        if version not in (0, 1, 2) or isinstance(version, bool):
            raise ValueError(f"version: expected 0, 1 or 2, got {version!r}")
        self._version = int(version)
        if kinematic is not None and not isinstance(kinematic, (bool, np.bool_)):
            raise TypeError(f"kinematic: expected None (the version's default) or a bool, got {kinematic!r}")
        self._kinematic = self._version == 2 if kinematic is None else bool(kinematic)
        self._reward_w = as_reward_weights(reward_weights, self._version)
        self._rooms, self._room_size, self._clutter = resolve_tier(tier, rooms, room_size, clutter)
        self._tier = tier
        if isinstance(n_beams, bool) or not isinstance(n_beams, (int, np.integer)) or not 8 <= n_beams <= 4096:
            raise ValueError(f"n_beams: expected an integer in 8..4096, got {n_beams!r}")
        self._n_beams = int(n_beams)
        self._max_speed = _positive(max_speed, "max_speed", upper=1.5)
        self._max_yaw_rate = _positive(max_yaw_rate, "max_yaw_rate", upper=2.0)
        if self._version == 0:
            for name, value in (("lidar_noise", lidar_noise), ("odometry_noise", odometry_noise)):
                if value is not _DEFAULT and value is not None:
                    raise ValueError(f"{name}: version 0 (GPS+compass) has no noise; use the v1 ids")
            lidar_noise = odometry_noise = None
        self._lidar_noise = as_lidar_noise(LIDAR_NOISE if lidar_noise is _DEFAULT else lidar_noise)
        self._odometry = WheelOdometry(as_odometry_noise(ODOMETRY_NOISE if odometry_noise is _DEFAULT
                                                         else odometry_noise))
        self.task = None
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.observation_space = spaces.Dict(self._obs_spaces())

    @property
    def extent(self):
        """m: every position of an episode lies within this distance of the start (the world's diagonal)."""
        return float((self._rooms * self._room_size + 2.0) * np.sqrt(2))

    def _obs_spaces(self):
        reach = self.extent
        twist = spaces.Box(np.array([-2 * self._max_speed, -4 * self._max_yaw_rate], np.float32),
                           np.array([2 * self._max_speed, 4 * self._max_yaw_rate], np.float32))
        goal = spaces.Box(-reach, reach, (2,), np.float32)
        ranges = spaces.Box(0.0, LIDAR_MAX, (self._n_beams,), np.float32)
        if self._version == 0:
            return {"goal": goal, "ranges": ranges, "twist": twist}
        return {"goal_start": goal, "ranges": ranges, "twist": twist}

    # -- world ----------------------------------------------------------------------------
    def _make_world(self, layout_seed):
        from polar_sim.sim import World

        noise = {"lidar": self._lidar_noise} if self._lidar_noise is not None else None
        # The kinematic rover's world is pooled: built once, then given each episode's layout in
        # place (World.relayout), which costs a fraction of a compilation and gives the same world.
        reuse = self._world if (self._kinematic and self._world is not None) else None
        # A few layouts (a few in a thousand on the room tier) have no reachable start/goal pair;
        # such a draw is replaced by the next seed of a sequence keyed on it, so a seeded reset
        # still gives one world, and every valid layout seed keeps its world.
        seq = np.random.SeedSequence(layout_seed)
        for attempt in range(MAX_LAYOUT_ATTEMPTS):
            try:
                if reuse is not None:
                    world = reuse.relayout(layout_seed)
                else:
                    world = World("navworld", seed=layout_seed, rooms=self._rooms, room_size=self._room_size,
                                  clutter=self._clutter, lidar_beams=self._n_beams, noise=noise,
                                  kinematic="planar" if self._kinematic else False, pooled=self._kinematic)
            except ValueError as err:
                if "no reachable start/goal pair" not in str(err) or attempt == MAX_LAYOUT_ATTEMPTS - 1:
                    raise
                layout_seed = int(seq.spawn(1)[0].generate_state(1)[0] % (2**31 - 1))
                continue
            self._layout_seed = layout_seed
            return world

    def _reset_scene(self):
        w = self._world
        self._goal = np.asarray(w.meta.goal, dtype=np.float64)
        x0, _, y0, _ = w.meta.bounds
        self._geodesic = GeodesicDistance(w.meta.occupancy, (x0, y0), w.meta.occupancy_res, self._goal)
        self._pose = w.robot_pose2d()
        self._start = self._pose.copy()
        self._geo = self._prev_dist = self._geodesic(self._pose[:2])
        self._robot_radius = float(w.meta.robot_radius)
        self._path_length = 0.0
        self._collision = False
        self._scan = None  # cast when first read (see ``scan``)
        if self._version >= 1:
            # The odometry noise has its own stream, drawn after the layout: the same seed gives
            # the same world whatever the noise settings.
            self._odometry.reset(np.random.default_rng(int(self.np_random.integers(0, 2**31 - 1))))
        self._odo = np.zeros(3)
        self._odo_twist = np.zeros(2)
        spec = w.lidar_spec("lidar")
        mount = between2d(self._pose, w.lidar_pose2d("lidar"))
        goal_start = between2d(self._start, np.array([self._goal[0], self._goal[1], 0.0]))[:2]
        self.task = NavTask(goal_start, mount, spec.angles.copy(), float(spec.min_range),
                            float(spec.max_range), float(w.dt), self.extent)

    def _apply_action(self, a):
        v, om = a[0] * self._max_speed, a[1] * self._max_yaw_rate
        prev = self._pose
        w = self._world
        w.step((v, om))
        self._pose = w.robot_pose2d()
        self._path_length += float(np.hypot(self._pose[0] - prev[0], self._pose[1] - prev[1]))
        self._collision = w.robot_collision()
        self._geo = self._geodesic(self._pose)  # for the reward and the info alike
        self._scan = None
        if self._version >= 1:
            # Wheels measure the distance driven along the heading and the turn (no side slip).
            inc = _pose2d.between(prev, self._pose)
            dt = w.dt
            ds, dth = self._odometry.measure(inc[0], inc[2], dt)
            self._odo = np.array([ds * np.cos(dth / 2), ds * np.sin(dth / 2), dth])
            self._odo_twist = np.array([ds / dt, dth / dt])

    # -- what a module reads --------------------------------------------------------------
    @property
    def scan(self):
        """The last lidar scan (:class:`polar_sim.sim.LidarScan`, ranges in m with ``inf`` = no
        return, noisy as observed). Its ``T_world_sensor`` is the true sensor pose: truth, for
        oracles and scoring only.

        The scan of a step is cast when it is first read (a module that reads no scan, such as
        ``GPISNav`` with ``pose_source="truth", sdf_source="truth"``, casts none); the lidar
        noise draws from its generator only for scans that are cast, so reading the scan every
        step, as the observation does, gives the same scans whatever else is read."""
        if self._scan is None:
            self._scan = self._world.lidar("lidar")
        return self._scan

    @property
    def sensor_pose2d(self):
        """The lidar's true pose (x, y, yaw) in the world now, m and rad (truth: for oracles and
        scoring only; the same as the scan's ``T_world_sensor``, without casting it)."""
        return self._world.lidar_pose2d("lidar")

    @property
    def odometry(self):
        """The last step's measured wheel odometry (3,): (dx, dy, dtheta) in the robot frame at the
        previous step, m and rad (the arc of the measured distance and turn; zeros at reset and in v0)."""
        return self._odo.copy()

    # -- observation, info, reward --------------------------------------------------------
    def _goal_distance(self):
        return float(np.hypot(*(self._goal - self._pose[:2])))

    def _twist(self):
        lim = self.observation_space["twist"]
        if self._version == 0:
            tw = self._world.robot_twist()
            return np.clip(np.array([tw[0], tw[5]], np.float32), lim.low, lim.high)
        return np.clip(self._odo_twist.astype(np.float32), lim.low, lim.high)

    def _get_obs(self, ranges=True):
        """The observation; without the ``ranges`` (and casting no scan) if ``ranges`` is False,
        for a module environment that reads only the rest."""
        obs = {"twist": self._twist()}
        if ranges:
            scan = self.scan
            r = np.where(np.isfinite(scan.ranges), scan.ranges, LIDAR_MAX).astype(np.float32)
            obs["ranges"] = np.minimum(r, LIDAR_MAX)
        if self._version == 0:
            obs["goal"] = between2d(self._pose, np.array([self._goal[0], self._goal[1], 0.0]))[:2].astype(np.float32)
        else:
            obs["goal_start"] = self.task.goal_start.astype(np.float32)
        return dict(sorted(obs.items()))

    def _get_info(self):
        d = self._goal_distance()
        info = {"robot_pose2d": self._pose.copy(), "goal": self._goal.copy(), "goal_distance": d,
                "geodesic_distance": self._geo, "collision": self._collision,
                "path_length": self._path_length,
                "is_success": bool(d < GOAL_RADIUS and not self._collision), "layout_seed": self._layout_seed}
        if self._version >= 1:
            info["start_pose2d"] = self._start.copy()
        return info

    def _get_reward(self):
        d = self._goal_distance()
        w = self._reward_w
        terms = {"progress": w["progress"] * (self._prev_dist - self._geo), "time": -w["time"],
                 "collision": -w["collision"] if self._collision else 0.0,
                 "success": w["success"] if (d < GOAL_RADIUS and not self._collision) else 0.0}
        if self._version >= 1:
            # Clearance of the robot's disc from the exact scene SDF (truth, as the rest of the reward).
            clear = float(self._world.sdf(self._pose[None, :2])[0]) - self._robot_radius
            terms["proximity"] = -w["proximity"] * float(np.clip(1.0 - clear / w["proximity_radius"], 0.0, 1.0))
        self._prev_dist = self._geo
        terminated = self._collision or d < GOAL_RADIUS
        return sum(terms.values()), terminated, terms

    def _render_frame(self):
        w, h = self._render_size
        half = self._rooms * self._room_size / 2
        return self._world.render_view(width=w, height=h, lookat=[0, 0, 0], distance=1.1 * half / np.tan(np.radians(30)),
                                       elevation=-89.99, azimuth=90.0)
