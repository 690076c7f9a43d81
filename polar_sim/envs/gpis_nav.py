"""GPISNav: goal-reaching navigation on SDF observations from an online map (LidarNav + GPIS)."""

from __future__ import annotations

import cv2
import numpy as np
from gymnasium import spaces

from polar_sim.envs import _pose2d
from polar_sim.envs.base import check_kwargs
from polar_sim.envs.lidar_nav import _DEFAULT, LidarNavEnv
from polar_sim.envs.localization import POSE_SOURCES, make_pose_source
from polar_sim.envs.module_env import ModuleEnv
from polar_sim.envs.observers import SDFStencil, TruthSource, make_sdf_source
from polar_sim.envs.sdf_grid import GRID_SDF_BOUND, GRID_VAR_MAX, SDFGrid, VisitedMask
from polar_sim.geometry import compose2d, inv2d

__all__ = ["GPISNavEnv", "stencil_observation", "OBS_MODES", "LOST_DISTANCE", "RENDER_SPAN", "RENDER_SDF_RANGE",
           "RENDER_ZERO_BAND", "RENDER_UNSEEN_VAR", "RENDER_UNSEEN_GREY"]

SDF_BOUND = 50.0
GRAD_BOUND = 10.0
OBS_MODES = ("stencil", "grid")
LOST_DISTANCE = 0.5  # m: info["track_lost"] when the estimate is further than this from the truth
#: The map panel of ``render()``: the robot's surroundings within RENDER_SPAN m each way, world axes;
#: the map's distance coloured by viridis from RENDER_SDF_RANGE[0] to [1] m (clipped), white where
#: |d| < RENDER_ZERO_BAND m (the map's surface). For legends and colour bars (``polar-sim demo``).
RENDER_SPAN = 4.0
RENDER_SDF_RANGE = (-1.0, 2.0)
RENDER_ZERO_BAND = 0.05
#: Grey (RGB) where the map's variance is at least RENDER_UNSEEN_VAR: never observed, the map's
#: prior (GPIS: 1 + map_noise), so its distance there is only an extrapolation.
RENDER_UNSEEN_VAR = 1.0
RENDER_UNSEEN_GREY = (150, 150, 150)


def stencil_observation(source, stencil, pose2d, queried=None):
    """Query an SDF source at the stencil around ``pose2d``: ``sdf`` (n,), ``sdf_grad`` (2n,) in
    the robot frame, interleaved (gx0, gy0, gx1, gy1, ...), ``sdf_var`` (n,); float32, clipped
    to the observation bounds. (Flat, because learning libraries expect 1-D vector parts.)
    ``queried`` passes an already computed ``source.query`` result at the stencil."""
    d, g, v = queried if queried is not None else source.query(stencil.world_points(pose2d))
    c, s = float(np.cos(pose2d[2])), float(np.sin(pose2d[2]))
    gx, gy = g[:, 0], g[:, 1]
    g_robot = np.empty((len(g), 2))
    g_robot[:, 0] = c * gx + s * gy
    g_robot[:, 1] = -s * gx + c * gy
    # np.clip is minimum(maximum(.)); written out, it skips the wrapper's overhead on small arrays.
    v = np.where(np.isnan(v), 1e6, v)  # nan_to_num(nan=1e6, posinf=1e6) then the clip to [0, 1e6]
    return {
        "sdf": _clip(d, -SDF_BOUND, SDF_BOUND).astype(np.float32),
        "sdf_grad": _clip(g_robot, -GRAD_BOUND, GRAD_BOUND).astype(np.float32).ravel(),
        "sdf_var": _clip(v, 0.0, 1e6).astype(np.float32),
    }


def _clip(x, lo, hi):
    return np.minimum(np.maximum(x, lo), hi)


class GPISNavEnv(ModuleEnv):
    """## Description
    ``LidarNav`` composed with an online map: every step (10 Hz) the 270-beam lidar scan updates
    the map, and the agent sees the map's signed distance, gradient and variance around the
    robot, with the goal in the robot frame. In v1 the loop is closed in localisation: the
    robot knows where it is only from its own estimate (``pose_source``), the map is fused at
    the estimated sensor pose, and the observation is computed at the estimated robot pose, in
    the start frame (the goal is given once in that frame, as in PointNav without GPS). The
    lidar and the wheel odometry are noisy. The true pose, the exact SDF and the errors are in
    ``info`` for scoring, never in the observation.

    ``GPISNav-v0`` is the GPS+compass variant: no noise, the map fused at the true sensor pose,
    the stencil and the goal at the true pose, the exact twist.

    ## Observation Space
    ``Dict``, keys sorted:

    | key | shape | dtype | meaning |
    |---|---|---|---|
    | ``goal`` | (2,) | float32 | goal in the estimated robot frame, m (clipped to the world's diagonal) |
    | ``pose`` | (3,) | float32 | v1: the estimated pose (x, y, theta) in the start frame, m, rad |
    | ``sdf`` | (n,) | float32 | ``obs_mode="stencil"``: map distance at the stencil, m, clipped to +-50 |
    | ``sdf_grad`` | (2n,) | float32 | stencil: map gradient in the robot frame, (gx, gy) per point, clipped to +-10 |
    | ``sdf_var`` | (n,) | float32 | stencil: map variance (1e6 where the map knows nothing) |
    | ``sdf_grid`` | (C, N, N) | float32 | ``obs_mode="grid"``: egocentric image, N = ``grid_size`` cells of ``grid_resolution`` m, the robot at the centre looking up (row 0 ahead, column 0 to the left); channels distance (m, clipped to +-4), variance (clipped to [0, 2]; about 1 where the map knows nothing) and with ``grid_visited`` the cells the robot has been in by its own estimate (0/1) |
    | ``twist`` | (2,) | float32 | v1: wheel odometry speed (m/s) and yaw rate (rad/s), noisy; v0: exact |

    n = ``stencil_rays`` x len(``stencil_radii``) = 16 x 4 by default (radii 0.5, 1, 2, 3 m).

    ## Action Space, Reward, Episode End
    As ``LidarNav``: normalised ``(v, omega)``; progress − time − collision + success − proximity,
    from the true pose, weighted by ``reward_weights`` (v1 defaults: collision 1, proximity 0.02
    per step within 0.3 m of a surface; v0: collision 5, no proximity term); terminated on success
    or collision, truncated at 600 steps (300 for the room tier).

    ## Arguments
    ``LidarNav``'s (``tier``, ``rooms``, ``room_size``, ``clutter``, ``n_beams``,
    ``max_speed``, ``max_yaw_rate``, ``lidar_noise``, ``odometry_noise``, ``reward_weights``,
    ``kinematic``), plus:

    | argument | default | meaning |
    |---|---|---|
    | ``pose_source`` | ``"slam"`` | ``"slam"``: odometry prediction, ICP-G on the online map, the scan fused at the registered pose; ``"odometry"``: dead reckoning; ``"truth"``: the GPS+compass oracle (v0: always) |
    | ``localize_params`` | None | keyword arguments of :func:`polar_sim.gpis.localize.localize` (slam) |
    | ``obs_mode`` | ``"stencil"`` | ``"stencil"`` or ``"grid"`` |
    | ``sdf_source`` | ``"gpis"`` | ``"gpis"`` (online GPIS map, faithful distance), ``"truth"`` (exact SDF), ``"occupancy_edt"`` (signed EDT of a 5 cm log-odds grid), or any object with ``reset/update/query`` |
    | ``sdf_params`` | None | keyword arguments of the map: parameters or stage fields (e.g. ``{"local_gp__map_scale": 1.0}``); the registered versions keep ``noise__reevaluation="gated"``, the map's default before issue 35, unless it is given here |
    | ``stencil_rays``, ``stencil_radii`` | 16, (0.5, 1, 2, 3) | directions and distances (m) of the stencil |
    | ``grid_size``, ``grid_resolution``, ``grid_visited`` | 32, 0.25, False | the grid image: cells per side, m per cell, the visited channel |

    ## Truth in ``info``
    ``LidarNav``'s (true ``robot_pose2d``, ``goal``, ``geodesic_distance``, ``collision``,
    ``is_success``, ...), plus ``sdf_true`` (n,) the exact SDF at the stencil around the true
    pose and ``sdf_error`` (n,) = the map at the stencil around the estimated pose − ``sdf_true``
    (the observation's error, in both obs modes), ``sdf_source``; v1 also ``pose_source``,
    ``est_pose2d`` (the estimate, in the world through the true start pose), ``pose_error`` (m),
    ``heading_error`` (rad), ``localization_status`` (ICP-G's: ``"ok"``, ``"max_iter"``,
    ``"no_data"``, ``"diverged"``; ``"odometry"``, ``"truth"``), ``localization_failures`` (steps
    this episode whose registration was not used) and ``track_lost`` (pose error > 0.5 m). A lost
    track is reported, never repaired from the truth.

    ## Version History
    - v2: v1 with the kinematic rover (``kinematic=True``: the exact unicycle of the commanded
      ``(v, omega)``, collisions still MuJoCo contacts; ``LidarNav``'s Version History). The same
      worlds, sensors, noise, localisation, reward and observations; about 3x the steps per
      CPU-second with ``pose_source="truth", sdf_source="truth"``. For learning.
    - v1: closed-loop localisation (``pose_source``, default ``"slam"``), noise on by default
      (lidar 1 cm and 1 % dropout, wheel odometry), the map and the observation in the start
      frame at the estimated pose, the goal given once in the start frame, the ``pose``
      observation, ``twist`` from the wheel odometry, ``obs_mode="grid"``, difficulty tiers,
      the localisation scored in ``info``; the reward's collision cost 1 instead of 5 and a
      proximity term (``reward_weights``), so that a learner is not taught to stand still.
    - v0: first release (GPS+compass, no noise).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, *, render_mode=None, render_size=(480, 480), pose_source=None, localize_params=None,
                 obs_mode="stencil", sdf_source="gpis", sdf_params=None, stencil_rays=16,
                 stencil_radii=(0.5, 1.0, 2.0, 3.0), grid_size=32, grid_resolution=0.25, grid_visited=False,
                 tier=None, rooms=None, room_size=None, clutter=None, n_beams=270, max_speed=1.0, max_yaw_rate=1.5,
                 lidar_noise=_DEFAULT, odometry_noise=_DEFAULT, reward_weights=None, kinematic=None, version=1,
                 **unknown):
        check_kwargs(type(self), unknown)
        if obs_mode not in OBS_MODES:
            raise ValueError(f"obs_mode: unknown mode {obs_mode!r}; expected one of {', '.join(OBS_MODES)}")
        if version == 0:
            if pose_source not in (None, "truth"):
                raise ValueError(f"pose_source: version 0 (GPS+compass) always uses the true pose; got "
                                 f"{pose_source!r}; use the v1 ids for {', '.join(POSE_SOURCES)}")
            if obs_mode != "stencil":
                raise ValueError("obs_mode: version 0 has only the stencil; use the v1 ids for obs_mode='grid'")
        base = LidarNavEnv(render_mode=render_mode, render_size=render_size, tier=tier, rooms=rooms,
                           room_size=room_size, clutter=clutter, n_beams=n_beams, max_speed=max_speed,
                           max_yaw_rate=max_yaw_rate, lidar_noise=lidar_noise, odometry_noise=odometry_noise,
                           reward_weights=reward_weights, kinematic=kinematic, version=version)
        self._v0 = version == 0
        self._pose_source = make_pose_source("truth" if self._v0 else ("slam" if pose_source is None else pose_source),
                                             localize_params)
        self._obs_mode = obs_mode
        self._stencil = SDFStencil(stencil_rays, stencil_radii)
        SDFGrid.check(grid_size, grid_resolution)  # checked whatever the mode (a wrong value is never silent)
        self._grid = SDFGrid(grid_size, grid_resolution) if obs_mode == "grid" else None
        if not isinstance(grid_visited, (bool, np.bool_)):
            raise TypeError(f"grid_visited: expected a bool, got {grid_visited!r}")
        self._visited = VisitedMask(base.extent, self._grid.resolution) if (self._grid and grid_visited) else None
        self._source = make_sdf_source(sdf_source, **(sdf_params or {}))
        self._source_name = sdf_source if isinstance(sdf_source, str) else type(sdf_source).__name__
        super().__init__(base)
        self.observation_space = spaces.Dict(self._obs_spaces())

    def _obs_spaces(self):
        raw = self.base.observation_space
        goal = raw["goal"] if self._v0 else raw["goal_start"]
        obs = {"goal": goal, "twist": raw["twist"]}
        if not self._v0:
            reach = float(goal.high[0])
            obs["pose"] = spaces.Box(np.array([-reach, -reach, -np.pi], np.float32),
                                     np.array([reach, reach, np.pi], np.float32))
        if self._grid is None:
            n = self._stencil.size
            obs.update(sdf=spaces.Box(-SDF_BOUND, SDF_BOUND, (n,), np.float32),
                       sdf_grad=spaces.Box(-GRAD_BOUND, GRAD_BOUND, (2 * n,), np.float32),
                       sdf_var=spaces.Box(0.0, 1e6, (n,), np.float32))
        else:
            c, n = 2 + (self._visited is not None), self._grid.size
            lo = np.zeros((c, n, n), np.float32)
            hi = np.ones((c, n, n), np.float32)
            lo[0], hi[0], hi[1] = -GRID_SDF_BOUND, GRID_SDF_BOUND, GRID_VAR_MAX
            obs["sdf_grid"] = spaces.Box(lo, hi, dtype=np.float32)
        return dict(sorted(obs.items()))

    # -- the module -----------------------------------------------------------------------
    def _raw_obs(self):
        return self.base._get_obs(ranges=False)  # the module reads the scan itself, when it needs it

    def _module_reset(self, obs, info):
        b = self.base
        # v1's map frame is the start frame; the true start pose only scores the estimate and
        # lets the oracles ("truth" pose or map) speak in that frame.
        self._origin = None if self._v0 else info["start_pose2d"]
        self._source.reset()
        if isinstance(self._source, TruthSource):
            self._source.world, self._source.origin = b.world, self._origin
        self._truth_sdf = TruthSource(b.world)
        self._pose_source.reset(b.task.sensor_offset, self._origin, self._source)
        if self._visited is not None:
            self._visited.reset()
        self._update(*self._pose_source.initial(b, info["robot_pose2d"]), info)

    def _module_step(self, obs, info):
        self._update(*self._pose_source.update(self.base, info["robot_pose2d"], self._source), info)

    def _update(self, est, sensor, info):
        if not isinstance(self._source, TruthSource):  # the exact map needs no scan
            scan = self.base.scan
            self._source.update(scan.angles, scan.ranges, sensor)
        self._est = est
        # One map query and one exact SDF per step, shared by the observation and the info.
        offsets = self._stencil.points_robot
        if isinstance(self._source, TruthSource):
            self._queried = self._source.query_stencil(est, offsets)
        else:
            self._queried = self._source.query(self._stencil.world_points(est))
        self._sdf_true = self.base.world.sdf_stencil(info["robot_pose2d"], offsets)
        if self._grid is not None:
            d, _, v = self._source.query(self._grid.world_points(est))
            vis = None
            if self._visited is not None:
                self._visited.add(est[:2])
                vis = self._visited.sample(self._grid.world_points(est))
            self._grid_img = self._grid.image(d, v, vis)

    # -- observation, info ----------------------------------------------------------------
    def _get_obs(self, raw):
        obs = {"twist": raw["twist"]}
        if self._grid is None:
            obs.update(stencil_observation(self._source, self._stencil, self._est, self._queried))
        else:
            obs["sdf_grid"] = self._grid_img.copy()
        if self._v0:
            obs["goal"] = raw["goal"]
        else:
            sp = self.observation_space
            g = _pose2d.between(self._est, (self.base.task.goal_start[0], self.base.task.goal_start[1], 0.0))[:2]
            obs["goal"] = _clip(g, sp["goal"].low, sp["goal"].high).astype(np.float32)
            obs["pose"] = _clip(self._est, sp["pose"].low, sp["pose"].high).astype(np.float32)
        return dict(sorted(obs.items()))

    def _get_info(self, info):
        info["sdf_true"] = self._sdf_true.astype(np.float32)
        info["sdf_error"] = (self._queried[0] - self._sdf_true).astype(np.float32)
        info["sdf_source"] = self._source_name
        if not self._v0:
            ps = self._pose_source
            est_world = _pose2d.compose(self._origin, self._est)
            true = info["robot_pose2d"]
            err = float(np.hypot(est_world[0] - true[0], est_world[1] - true[1]))
            info.update(pose_source=ps.name, est_pose2d=est_world, pose_error=err,
                        heading_error=_pose2d.wrap(float(est_world[2] - true[2])),
                        localization_status=ps.status, localization_failures=int(getattr(ps, "failures", 0)),
                        track_lost=bool(err > LOST_DISTANCE))
        return info

    def _render_frame(self):
        """Top-down view beside the map's SDF around the robot, world axes (zero level in white,
        never observed in grey; the true robot red, the estimated one orange, the goal green)."""
        top = self.base.render()
        h, w = top.shape[:2]
        n, span = 96, RENDER_SPAN
        pose = self.base._pose
        xs = np.linspace(-span, span, n)
        X, Y = np.meshgrid(xs, xs[::-1])
        pts = np.stack([X.ravel() + pose[0], Y.ravel() + pose[1]], 1)
        if self._origin is not None:  # world points into the map frame
            pts = compose2d(inv2d(self._origin), np.c_[pts, np.zeros(len(pts))])[:, :2]
        out = self._source.query(pts)
        d = out[0].reshape(n, n)
        lo, hi = RENDER_SDF_RANGE
        v = np.clip((d - lo) / (hi - lo), 0, 1)
        heat = cv2.applyColorMap((255 * v).astype(np.uint8), cv2.COLORMAP_VIRIDIS)[..., ::-1].copy()
        heat[np.abs(d) < RENDER_ZERO_BAND] = 255
        if len(out) > 2:  # a source with a variance: grey where it has seen nothing
            heat[np.asarray(out[2]).reshape(n, n) >= RENDER_UNSEEN_VAR] = RENDER_UNSEEN_GREY
        heat = cv2.resize(heat, (w, h), interpolation=cv2.INTER_NEAREST)
        c = np.array([w // 2, h // 2])

        def px(xy):
            q = (np.asarray(xy) - pose[:2]) / span * (w / 2)
            return int(c[0] + q[0]), int(c[1] - q[1])

        robots = [(pose, (255, 80, 80))]
        if self._origin is not None:
            robots.append((compose2d(self._origin, self._est), (255, 160, 0)))
        for p, colour in robots[::-1]:
            tip = p[:2] + 20 * span / (w / 2) * np.array([np.cos(p[2]), np.sin(p[2])])
            cv2.circle(heat, px(p[:2]), 6, colour, -1)
            cv2.line(heat, px(p[:2]), px(tip), colour, 2)
        cv2.circle(heat, px(self.base._goal), 8, (60, 220, 60), 2)
        return np.hstack([top, heat])
