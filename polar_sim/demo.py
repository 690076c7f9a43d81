"""``polar-sim demo``: a short headless run of the simulator and the three modules on the
built-in scenes, printing a summary and writing PNGs. Each part is one function of ``(out,
progress)``; the demo runs them in order (or in two process lanes) and reports which ran.

Progress goes to stderr: one bar per lane, labelled with the part and what it counts (scans,
frames, steps), moving every step. It is quiet when stderr is not a terminal or with
``progress=False`` (``polar-sim demo --quiet``); the summary lines go to stdout either way.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["run_demo", "DEMOS", "Progress"]


class Progress:
    """What one part reports while it runs: ``stage(label, total, unit)`` starts a counted stretch
    of work, ``update(n=1)`` advances it, ``to(k)`` sets it to ``k`` done. Events go to ``emit``
    (a callable taking one tuple); ``Progress()`` drops them."""

    def __init__(self, emit=None):
        self._emit = emit or (lambda event: None)
        self._n = 0

    def stage(self, label, total, unit):
        self._n = 0
        self._emit(("stage", label, int(total), unit))

    def to(self, k):
        self._n = int(k)
        self._emit(("to", self._n))

    def update(self, n=1):
        self.to(self._n + n)


def demo_scenes(out: Path, progress: Progress):
    """Render the rover scenes' sensors: camera, depth, labels, lidar."""
    from polar_sim.sim import World
    from polar_sim.sim.pictures import render_scene_pictures

    lines = []
    for scene, action in (("rover_terrain", (6.0, 0.08)), ("office2d", (1.0, 0.0))):
        with World(scene, seed=0) as w:
            n_pics = len(w.cameras) + 1
            progress.stage(f"scenes: {scene}, 10 steps then {n_pics} pictures", 10 + n_pics, "step")
            for _ in range(10):
                w.step(action)
                progress.update()
            paths = render_scene_pictures(w, out, width=480, height=360, progress=progress.update)
            s = w.lidar("lidar")
            t = w.truth()
            n_ret = int(np.isfinite(s.ranges).sum())
            why = (" (open terrain: most beams pass the 30 m range without a hit)" if scene == "rover_terrain"
                   else "")
            lines.append(f"{scene}: robot at ({t['robot_pose2d'][0]:.1f}, {t['robot_pose2d'][1]:.1f}) m, "
                         f"speed {t['robot_twist'][0]:.2f} m/s; 2D lidar: {n_ret} of {len(s.ranges)} beams "
                         f"returned{why} ({', '.join(p.name for p in paths)})")
    return lines


def demo_gpis(out: Path, progress: Progress):
    """Drive the indoor rover through office2d for 15 s and map it online with GPIS; compare the
    map's distance with the exact SDF."""
    from polar_sim.control import PurePursuit
    from polar_sim.demo_pictures import gpis_figure
    from polar_sim.geometry import T_to_pose2d
    from polar_sim.gpis import GPISMap2D
    from polar_sim.sim import RangeNoise, World
    from polar_sim.sim.pictures import save_figure

    m = GPISMap2D(sensor_offset=(0.0, 0.0))
    path = []
    # Along the corridor, through the west office's door, round its furniture.
    route = PurePursuit([(-13, 0), (-10.6, 0), (-10, 1.0), (-10, 3.0), (-9.5, 5.5), (-7.5, 7.0)], lookahead=0.8)
    progress.stage("gpis: mapping office2d (a GPIS update per lidar scan)", 150, "scan")
    with World("office2d", seed=0, kinematic=True, noise={"lidar": RangeNoise(sigma=0.01)}) as w:
        for _ in range(150):
            pose = w.truth()["robot_pose2d"]
            w.step((0.8, float(np.clip(route.steer(pose, 0.8), -1.5, 1.5))))
            s = w.lidar("lidar")
            m.update(s.angles, s.ranges, T_to_pose2d(s.T_world_sensor))
            path.append(w.truth()["robot_pose2d"][:2])
            progress.update()
        progress.stage("gpis: the map against the exact SDF, picture", 2, "step")
        path = np.array(path)
        x0, y0 = path.min(0) - 4
        x1, y1 = path.max(0) + 4
        X, Y = np.meshgrid(np.arange(x0, x1, 0.05), np.arange(y0, y1, 0.05))
        P = np.stack([X.ravel(), Y.ravel()], 1)
        d, _, var = m.query(P)
        true = w.sdf(P)
    progress.update()
    # Compare where the map has seen the surface (GP variance well below its prior of 1.01).
    known = var.reshape(X.shape) < 0.2
    near = known.ravel() & (true >= 0) & (true < 0.3)  # the free side, which the lidar sees
    free = known.ravel() & (true > 0.3) & (true < 2.0)
    # Where no ray has looked (behind walls, the far side of an object seen from one side) the map's
    # variance is its prior (1 + map_noise) and its distance only an extrapolation: drawn in colour it
    # reads as wedges and teardrops of "inside". Such cells are greyed out, as the variance says.
    unseen = var.reshape(X.shape) >= 1.0
    save_figure(gpis_figure(X, Y, d.reshape(X.shape), true.reshape(X.shape), unseen, path), out / "gpis_office2d.png")
    progress.update()
    med = float(np.median(np.abs(d[near] - true[near])))
    mae = float(np.mean(np.abs(d[free] - true[free])))
    return [f"office2d, 150 scans: {len(m.samples()['points'])} surface samples; |SDF error| median "
            f"{100 * med:.1f} cm within 0.3 m of walls, mean {100 * mae:.1f} cm 0.3-2 m from walls "
            "(exact SDF from the scene; the gpis_accuracy experiment scores the observed area) (gpis_office2d.png)"]


def demo_ground(out: Path, progress: Progress):
    """Run monocular VO with scale from the ground on 80 frames of a flat route."""
    from polar_sim.demo_pictures import ground_figure
    from polar_sim.ground import GroundVO
    from polar_sim.metrics.ground import classifier_iou
    from polar_sim.sim.pictures import save_figure
    from polar_sim.sim.recorders.rover_sequences import record_route

    progress.stage("ground: recording route flat_00", 80, "frame")
    rec = record_route("flat_00", max_frames=80, progress=progress.to)
    K, h = np.array(rec.meta["K"]), rec.meta["camera_height"]
    vo = GroundVO(K, h, model="6param", sampling="weighted", downsample=1, seed=0)
    errs, ious = [], []
    speeds = rec.stack("speed")
    progress.stage("ground: GroundVO (segmentation + odometry)", len(rec), "frame")
    for i, f in enumerate(rec):
        e = vo.process(f["rgb"], float(f["t"]))
        if i > 10 and e.status == "ok":
            # Frame k's estimate describes the middle frame k-1 of its triplet (spec §0).
            errs.append(e.speed_raw - float(speeds[i - 1]))
            ious.append(classifier_iou(e.ground_prob, f["ground_mask"]))
        progress.update()
    last = rec[len(rec) - 1]
    save_figure(ground_figure(last["rgb"], e.ground_prob, last["ground_mask"], len(rec) - 1, float(np.mean(ious))),
                out / "ground_prob.png")
    est = vo.trajectory()
    gt = rec.stack("T_world_cam")
    true_xyz = np.einsum("ij,njk->nik", np.linalg.inv(gt[0]), gt)[:, :3, 3]
    drift = float(np.linalg.norm(est[-1, :3, 3] - true_xyz[-1]))
    dist = float(np.sum(np.linalg.norm(np.diff(true_xyz, axis=0), axis=1)))
    return [f"flat_00, the first 80 frames ({dist:.0f} m, accelerating from rest): raw speed error "
            f"{np.mean(np.abs(errs)):.3f} m/s mean abs, ground IoU {np.mean(ious):.3f}, end drift {drift:.2f} m "
            f"({100 * drift / max(dist, 1e-9):.1f} % of the path; a short start-up cut: the filters converge over "
            "the first frames, so this is not the KITTI 100-800 m figure of the README's Results) (ground_prob.png)"]


def demo_tracking(out: Path, progress: Progress):
    """Track the mug while the hand comes down and rests on it (tabletop ``mug_touch``, 320x240,
    Kinect-like depth noise), from the true first pose; score pose and mask against the truth."""
    import cv2
    import trimesh

    from polar_sim import metrics
    from polar_sim.demo_pictures import tracking_figure
    from polar_sim.sim.builders import objects
    from polar_sim.sim.pictures import save_figure
    from polar_sim.sim.recorders.tabletop_sequences import record_sequence
    from polar_sim.tracking import ObjectTracker

    # The palm reaches the mug at about frame 100: start 20 frames before it (the physics and
    # the script need the recording from frame 0).
    start, end = 80, 125
    progress.stage("tracking: recording mug_touch (the hand comes down on the mug)", end, "frame")
    rec = record_sequence("mug_touch", seed=0, n_frames=end, width=320, height=240, progress=progress.to)
    mesh = objects.load_mesh(rec.meta["object"])
    P, face = trimesh.sample.sample_surface(mesh, 3000, seed=0)
    P = np.asarray(P, float)
    K = np.array(rec.meta["K"], float)
    G = rec.stack("T_cam_obj")
    tr = ObjectTracker(P, K, G[start], model_normals=mesh.face_normals[face])
    poses, ious, masks, hands, near = [], [], [], [], []
    progress.stage("tracking: ObjectTracker (pose + segmentation)", end - start, "frame")
    for i in range(start, end):
        f = rec[i]
        r = tr.process(f["rgb"], f["depth"])
        poses.append(r.pose)
        ious.append(metrics.iou(r.mask, f["mask_visible"]))
        masks.append(r.mask)
        hands.append(f["mask_occluder"])
        # the hand pixels that touch or cover the mug: within 8 px of its full silhouette
        near.append(cv2.dilate(f["mask_full"].astype(np.uint8), np.ones((17, 17), np.uint8)) > 0)
        progress.update()
    hand = metrics.occluder_as_target(np.stack(masks), np.stack(hands), within=np.stack(near))
    add = metrics.add(P, G[start:end], np.stack(poses))
    d = metrics.object_diameter(P)
    save_figure(tracking_figure(f, r.mask, K, P, r.pose, G[end - 1], index=end - 1, start=start, add_m=float(add[-1]),
                                iou=ious[-1], diameter=d), out / "tracking_mug.png")
    return [f"tabletop mug_touch, frames {start}-{end - 1} as the hand comes down on the mug: ADD < 0.1 d on "
            f"{100 * metrics.add_success(add, d, 0.1):.0f}% of frames (mean {1000 * add.mean():.1f} mm), "
            f"IoU > 0.5 on {100 * metrics.iou_success(np.array(ious), 0.5):.0f}%, hand pixels as target "
            f"{100 * hand:.1f}% (tracking_mug.png)"]


#: The environment of the demo's closed-loop part and the episode's seed.
ENV_ID, ENV_SEED = "polar_sim/GPISNav-v2", 1


def demo_env(out: Path, progress: Progress):
    """One GPISNav-v2 episode (the kinematic rover): the SDF navigator drives to the goal on the online map, localised on
    that map (ICP-G) from noisy lidar and wheel odometry."""
    import gymnasium as gym

    import polar_sim.envs  # noqa: F401  (registers the ids)
    from polar_sim.demo_pictures import env_figure
    from polar_sim.envs.policies import SDFNavigator
    from polar_sim.sim.pictures import save_figure

    env = gym.make(ENV_ID, render_mode="rgb_array")
    pol = SDFNavigator()
    obs, info = env.reset(seed=ENV_SEED)
    start = info["goal_distance"]
    track, est = [info["robot_pose2d"][:2].copy()], [info["est_pose2d"][:2].copy()]
    progress.stage(f"envs: {ENV_ID.split('/')[1]} episode (SDFNavigator)", env.spec.max_episode_steps, "step")
    done, n = False, 0
    while not done:
        obs, r, term, trunc, info = env.step(pol(obs))
        track.append(info["robot_pose2d"][:2].copy())
        est.append(info["est_pose2d"][:2].copy())
        done, n = term or trunc, n + 1
        progress.update()
    x0, x1, y0, y1 = env.unwrapped.world.meta.bounds
    X, Y = np.meshgrid(np.linspace(x0 - 0.5, x1 + 0.5, 360), np.linspace(y0 - 0.5, y1 + 0.5, 360))
    sdf = env.unwrapped.world.sdf(np.stack([X.ravel(), Y.ravel()], 1)).reshape(X.shape)
    title = (f"{ENV_ID.split('/')[1]}, seed {ENV_SEED}: the SDFNavigator policy drives to the goal on a GPIS map "
             "built online from its noisy lidar, localised on that map")
    save_figure(env_figure(env.render(), X, Y, sdf, np.array(track), np.array(est), info, n, title,
                           size_m=(x1 - x0, y1 - y0)), out / "env_gpisnav.png")
    env.close()
    return [f"{ENV_ID.split('/')[1]} (online GPIS map, pose from ICP-G on it): goal {start:.1f} m away, "
            f"{'reached' if info['is_success'] else 'not reached'} in {n} steps, path {info['path_length']:.1f} m, "
            f"collision {info['collision']}, final pose error {100 * info['pose_error']:.1f} cm (env_gpisnav.png)"]


DEMOS = [("scenes", demo_scenes), ("gpis", demo_gpis), ("ground", demo_ground), ("tracking", demo_tracking),
         ("envs", demo_env)]

# The parts that use the GPIS kernels run in one process, so that its kernels compile once there
# (numba compiles per process); the others in the second.
_LANES = (("gpis", "envs"), ("scenes", "ground", "tracking"))


def _kernels_cached() -> bool:
    """True when numba's cache already holds the GPIS kernels (``$NUMBA_CACHE_DIR`` if set, else the
    package's ``__pycache__``): a first run compiles them, which takes most of its time."""
    import os

    import polar_sim.gpis as gpis

    root = os.environ.get("NUMBA_CACHE_DIR")
    folder = Path(root) if root else Path(gpis.__file__).parent / "__pycache__"
    return folder.is_dir() and any(folder.rglob("_distance*.nbi"))


# -- running the parts, in this process or in two worker lanes ----------------------------------
_worker = {}   # in a lane's worker process: its event queue and lane index (set by _init_lane)


def _init_lane(queue, lane):
    _worker.update(queue=queue, lane=lane)


def _run_part(name, fn, out, emit):
    """Run one part with its progress events to ``emit``: (name, lines, seconds, error message or
    None). A failure is reported, not raised, so that the other parts carry on."""
    t0 = time.perf_counter()
    try:
        lines = fn(Path(out), Progress(emit))
    except Exception as exc:  # report and carry on with the other parts
        return name, [], time.perf_counter() - t0, f"{type(exc).__name__}: {exc}"
    return name, lines, time.perf_counter() - t0, None


def _run_in_lane(name, fn, out):
    """:func:`_run_part` in a lane's worker process: progress events go to the lane's queue,
    tagged with the lane's index."""
    q, lane = _worker["queue"], _worker["lane"]
    return _run_part(name, fn, out, lambda event: q.put((lane,) + event))


class _Bars:
    """One tqdm bar per lane on stderr (line ``lane``), shown from its lane's first stage and driven
    by the parts' progress events; nothing when ``enabled`` is false."""

    def __init__(self, enabled):
        self.enabled, self.bars = enabled, {}

    def event(self, lane, kind, *args):
        from tqdm import tqdm

        if not self.enabled:
            return
        if kind == "stage":
            label, total, unit = args
            unit += "s" if total != 1 else ""
            if lane not in self.bars:
                self.bars[lane] = tqdm(total=total, desc=label, unit=unit, position=lane, leave=False, file=sys.stderr,
                                       dynamic_ncols=True, bar_format="{desc}: {n_fmt}/{total_fmt} {unit} {bar} [{elapsed}]")
            bar = self.bars[lane]
            bar.unit = unit
            bar.set_description_str(label, refresh=False)
            bar.reset(total=total)
        bar = self.bars.get(lane)
        if bar is not None:
            bar.n = args[0] if kind == "to" else 0
            bar.refresh()

    def write(self, line):
        from tqdm import tqdm

        tqdm.write(line, file=sys.stdout)

    def close(self):
        for bar in self.bars.values():
            bar.close()


def _run_lanes(parts, lanes, out, bars, report):
    """Each lane of part names in its own spawned worker process, the parts of a lane one after
    the other; their progress events drawn on ``bars``; ``report(name, lines, seconds, error)``
    as each part ends."""
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from queue import Empty

    ctx = mp.get_context("spawn")  # a fresh interpreter: no forked MuJoCo/EGL or numba state
    q = ctx.Queue()
    pools = [ProcessPoolExecutor(1, mp_context=ctx, initializer=_init_lane, initargs=(q, i)) for i in range(len(lanes))]

    def drain():
        while True:
            try:
                bars.event(*q.get_nowait())
            except Empty:
                return

    try:
        pending = {pool.submit(_run_in_lane, name, dict(parts)[name], str(out)) for pool, lane in zip(pools, lanes)
                   for name in lane}
        while pending:
            done, pending = wait(pending, timeout=0.1, return_when=FIRST_COMPLETED)
            drain()
            for f in done:
                report(*f.result())
    finally:
        for pool in pools:
            pool.shutdown()
        drain()


def run_demo(out: Path, workers=None, *, progress=True, parts=None, lanes=None):
    """Run every demo part; returns the process exit code (0, or 1 when a part failed).

    ``workers``: 1 runs the parts one after the other in this process; 2 (the default when the
    machine has two or more cores) runs them in two worker processes, the GPIS parts (``gpis``,
    ``envs``) in one and the rest in the other, so that a first run's numba compiles overlap the
    other parts. Each part is seeded, so its numbers and pictures do not depend on ``workers``.
    ``progress``: bars on stderr (only when stderr is a terminal). ``parts`` (name, function)
    pairs and ``lanes`` (tuples of names) replace :data:`DEMOS` and the two lanes.
    """
    import os

    if workers is None:
        workers = 2 if (os.cpu_count() or 1) >= 2 else 1
    if isinstance(workers, bool) or workers not in (1, 2):
        raise ValueError(f"workers must be 1 or 2, got {workers!r}")
    parts = list(DEMOS if parts is None else parts)
    lanes = _LANES if lanes is None else lanes
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    shown = bool(progress) and sys.stderr.isatty()
    print(f"polar_sim demo: writing pictures to {out}/")
    if shown and not _kernels_cached():
        print("first run: numba compiles the GPIS, ground and tracking kernels once (about a minute "
              "on 2 cores); later runs load them from numba's cache", file=sys.stderr)
    bars = _Bars(shown)
    failed = []

    def report(name, lines, dt, err):
        if err is not None:
            failed.append(name)
            bars.write(f"[{name}] FAILED: {err}")
            return
        for line in lines:
            bars.write(f"[{name}] {line}")
        bars.write(f"[{name}] done in {dt:.1f} s")

    try:
        if workers == 1:
            for name, fn in parts:
                report(*_run_part(name, fn, out, lambda event: bars.event(0, *event)))
        else:
            _run_lanes(parts, lanes, out, bars, report)
    finally:
        bars.close()
    print(f"wrote {len(sorted(out.glob('*.png')))} PNGs to {out}/")
    return 1 if failed else 0
