"""``polar-sim demo``: a short headless run of the simulator and the three modules on the
built-in scenes, printing a summary and writing PNGs. Each part is one function; the demo runs
them in order and reports which ran."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

__all__ = ["run_demo"]


def demo_scenes(out: Path):
    """Render the rover scenes' sensors: camera, depth, labels, lidar."""
    from polar_sim.sim import World
    from polar_sim.sim.pictures import render_scene_pictures

    lines = []
    for scene, action in (("rover_terrain", (6.0, 0.08)), ("office2d", (1.0, 0.0))):
        with World(scene, seed=0) as w:
            for _ in range(10):
                w.step(action)
            paths = render_scene_pictures(w, out, width=480, height=360)
            s = w.lidar("lidar")
            t = w.truth()
            n_ret = int(np.isfinite(s.ranges).sum())
            why = (" (open terrain: most beams pass the 30 m range without a hit)" if scene == "rover_terrain"
                   else "")
            lines.append(f"{scene}: robot at ({t['robot_pose2d'][0]:.1f}, {t['robot_pose2d'][1]:.1f}) m, "
                         f"speed {t['robot_twist'][0]:.2f} m/s; 2D lidar: {n_ret} of {len(s.ranges)} beams "
                         f"returned{why} ({', '.join(p.name for p in paths)})")
    return lines


def demo_gpis(out: Path):
    """Drive the indoor rover through office2d for 15 s and map it online with GPIS; compare the
    map's distance with the exact SDF."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from polar_sim.geometry import T_to_pose2d
    from polar_sim.gpis import GPISMap2D
    from polar_sim.sim import RangeNoise, World

    from polar_sim.control import PurePursuit

    m = GPISMap2D(sensor_offset=(0.0, 0.0))
    path = []
    # Along the corridor, through the west office's door, round its furniture.
    route = PurePursuit([(-13, 0), (-10.6, 0), (-10, 1.0), (-10, 3.0), (-9.5, 5.5), (-7.5, 7.0)], lookahead=0.8)
    with World("office2d", seed=0, kinematic=True, noise={"lidar": RangeNoise(sigma=0.01)}) as w:
        for k in range(150):
            pose = w.truth()["robot_pose2d"]
            w.step((0.8, float(np.clip(route.steer(pose, 0.8), -1.5, 1.5))))
            s = w.lidar("lidar")
            m.update(s.angles, s.ranges, T_to_pose2d(s.T_world_sensor))
            path.append(w.truth()["robot_pose2d"][:2])
        path = np.array(path)
        x0, y0 = path.min(0) - 4
        x1, y1 = path.max(0) + 4
        xs, ys = np.arange(x0, x1, 0.05), np.arange(y0, y1, 0.05)
        X, Y = np.meshgrid(xs, ys)
        P = np.stack([X.ravel(), Y.ravel()], 1)
        d, _, var = m.query(P)
        true = w.sdf(P)
    # Compare where the map has seen the surface (GP variance well below its prior of 1.01).
    known = var.reshape(X.shape) < 0.2
    near = known.ravel() & (true >= 0) & (true < 0.3)  # the free side, which the lidar sees
    free = known.ravel() & (true > 0.3) & (true < 2.0)
    # Where no ray has looked (behind walls, the far side of an object seen from one side) the map's
    # variance is its prior (1 + map_noise) and its distance only an extrapolation: drawn in colour it
    # reads as wedges and teardrops of "inside". Such cells are greyed out, as the variance says.
    unseen = var.reshape(X.shape) >= 1.0
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from polar_sim.sim.pictures import colorbar_beside, save_figure

    fig, ax = plt.subplots(1, 2, figsize=(12, 5.2), gridspec_kw={"wspace": 0.3})
    for a, field, title in ((ax[0], d, "online GPIS map: its signed distance"), (ax[1], true, "exact SDF of the scene")):
        im = a.imshow(field.reshape(X.shape), origin="lower", extent=[x0, x1, y0, y1], cmap="viridis",
                      vmin=-0.5, vmax=2.5)
        if a is ax[0]:
            a.imshow(np.where(unseen, 1.0, np.nan), origin="lower", extent=[x0, x1, y0, y1], cmap="Greys",
                     vmin=0.0, vmax=2.0, interpolation="nearest")
        shown = np.where(unseen, np.nan, field.reshape(X.shape)) if a is ax[0] else field.reshape(X.shape)
        a.contour(X, Y, shown, levels=[0.0], colors="w", linewidths=0.8)
        a.plot(path[:, 0], path[:, 1], color="orange", lw=1.5)
        a.plot(*path[0], "o", color="orange", ms=6)
        a.set_title(title)
        a.set_xlabel("x [m]")
        a.set_ylabel("y [m]")
        a.set_aspect("equal")
        colorbar_beside(fig, a, im, "signed distance [m] (clipped to -0.5..2.5)")
    fig.legend(handles=[Line2D([], [], color="orange", lw=1.5, marker="o", markevery=[0],
                               label="robot path (dot: start), 0.8 m/s, 150 scans"),
                        Line2D([], [], color="w", lw=1.5, path_effects=_outlined(), label="zero level: the surface"),
                        Patch(color="0.6", label="never observed (map variance at its prior): not scored")],
               loc="lower center", ncol=3, fontsize=9, frameon=False, bbox_to_anchor=(0.5, -0.06))
    fig.suptitle("office2d, simulated 2D lidar (1 cm noise): the GPIS map built online beside the exact SDF")
    save_figure(fig, out / "gpis_office2d.png")
    med = float(np.median(np.abs(d[near] - true[near])))
    mae = float(np.mean(np.abs(d[free] - true[free])))
    return [f"office2d, 150 scans: {len(m.samples()['points'])} surface samples; |SDF error| median "
            f"{100 * med:.1f} cm within 0.3 m of walls, mean {100 * mae:.1f} cm 0.3-2 m from walls "
            "(exact SDF from the scene; the gpis_accuracy experiment scores the observed area) (gpis_office2d.png)"]


def _outlined():
    """Path effects that draw a thin dark outline round a white line (so it shows on a white legend)."""
    from matplotlib import patheffects

    return [patheffects.Stroke(linewidth=3, foreground="0.3"), patheffects.Normal()]


def demo_ground(out: Path):
    """Run monocular VO with scale from the ground on 80 frames of a flat route."""
    from polar_sim.ground import GroundVO
    from polar_sim.metrics.ground import classifier_iou
    from polar_sim.sim.rover_sequences import record_route

    rec = record_route("flat_00", max_frames=80, progress=False)
    K, h = np.array(rec.meta["K"]), rec.meta["camera_height"]
    vo = GroundVO(K, h, model="6param", sampling="weighted", downsample=1, seed=0)
    errs, ious = [], []
    speeds = rec.stack("speed")
    for i, f in enumerate(rec):
        e = vo.process(f["rgb"], float(f["t"]))
        if i > 10 and e.status == "ok":
            # Frame k's estimate describes the middle frame k-1 of its triplet (spec §0).
            errs.append(e.speed_raw - float(speeds[i - 1]))
            ious.append(classifier_iou(e.ground_prob, f["ground_mask"]))
    last = rec[len(rec) - 1]
    _ground_figure(out / "ground_prob.png", last["rgb"], e.ground_prob, last["ground_mask"], len(rec) - 1,
                   float(np.mean(ious)))
    est = vo.trajectory()
    gt = rec.stack("T_world_cam")
    T0 = np.linalg.inv(gt[0])
    true_xyz = np.einsum("ij,njk->nik", T0, gt)[:, :3, 3]
    drift = float(np.linalg.norm(est[-1, :3, 3] - true_xyz[-1]))
    dist = float(np.sum(np.linalg.norm(np.diff(true_xyz, axis=0), axis=1)))
    return [f"flat_00, the first 80 frames ({dist:.0f} m, accelerating from rest): raw speed error "
            f"{np.mean(np.abs(errs)):.3f} m/s mean abs, ground IoU {np.mean(ious):.3f}, end drift {drift:.2f} m "
            f"({100 * drift / max(dist, 1e-9):.1f} % of the path; a short start-up cut: the filters converge over "
            "the first frames, so this is not the KITTI 100-800 m figure of the README's Results) (ground_prob.png)"]


def _ground_figure(path, rgb, prob, truth, index, mean_iou):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    from polar_sim.sim.pictures import colorbar_beside, save_figure

    fig, ax = plt.subplots(1, 3, figsize=(17, 2.9), gridspec_kw={"wspace": 0.42})
    ax[0].imshow(rgb)
    ax[0].set_title(f"camera, frame {index}")
    im = ax[1].imshow(prob, cmap="viridis", vmin=0, vmax=1)
    ax[1].set_title("learned P(ground | colour)")
    colorbar_beside(fig, ax[1], im, "probability")
    pred = prob > 0.5
    agree = np.zeros(rgb.shape, np.uint8)
    agree[pred & truth] = (60, 170, 60)
    agree[pred & ~truth] = (220, 60, 50)
    agree[~pred & truth] = (240, 200, 40)
    ax[2].imshow(agree)
    ax[2].set_title("P > 0.5 against the true ground mask")
    ax[2].legend(handles=[Patch(color=np.array(c) / 255, label=t) for c, t in
                          (((60, 170, 60), "ground, found"), ((220, 60, 50), "not ground, called ground"),
                           ((240, 200, 40), "ground, missed"))], fontsize=7, loc="upper right")
    for a in ax:
        a.set_xlabel("u [px]")
        a.set_ylabel("v [px]")
    fig.suptitle(f"rover on route flat_00 (simulated): GroundVO's ground classifier, learned online from its own "
                 f"RANSAC labels, after {index + 1} frames (mean IoU {mean_iou:.2f} after frame 10)")
    save_figure(fig, path)


def demo_tracking(out: Path):
    """Track the mug while the hand comes down and rests on it (tabletop ``mug_touch``, 320x240,
    Kinect-like depth noise), from the true first pose; score pose and mask against the truth."""
    import cv2
    import trimesh

    from polar_sim import metrics
    from polar_sim.sim import objects
    from polar_sim.sim.tabletop_sequences import record_sequence
    from polar_sim.tracking import ObjectTracker

    # The palm reaches the mug at about frame 100: start 20 frames before it (the physics and
    # the script need the recording from frame 0).
    start, end = 80, 125
    rec = record_sequence("mug_touch", seed=0, n_frames=end, width=320, height=240)
    obj = rec.meta["object"]
    mesh = objects.load_mesh(obj)
    P, face = trimesh.sample.sample_surface(mesh, 3000, seed=0)
    N = mesh.face_normals[face]
    G = rec.stack("T_cam_obj")
    tr = ObjectTracker(np.asarray(P, float), np.array(rec.meta["K"], float), G[start], model_normals=N)
    poses, ious, masks, hands, near = [], [], [], [], []
    for i in range(start, end):
        f = rec[i]
        r = tr.process(f["rgb"], f["depth"])
        poses.append(r.pose)
        ious.append(metrics.iou(r.mask, f["mask_visible"]))
        masks.append(r.mask)
        hands.append(f["mask_occluder"])
        # the hand pixels that touch or cover the mug: within 8 px of its full silhouette
        near.append(cv2.dilate(f["mask_full"].astype(np.uint8), np.ones((17, 17), np.uint8)) > 0)
    hand = metrics.occluder_as_target(np.stack(masks), np.stack(hands), within=np.stack(near))
    add = metrics.add(np.asarray(P, float), G[start:end], np.stack(poses))
    d = metrics.object_diameter(np.asarray(P, float))
    _tracking_figure(out / "tracking_mug.png", f, r, end - 1, start)
    return [f"tabletop mug_touch, frames {start}-{end - 1} as the hand comes down on the mug: ADD < 0.1 d on "
            f"{100 * metrics.add_success(add, d, 0.1):.0f}% of frames (mean {1000 * add.mean():.1f} mm), "
            f"IoU > 0.5 on {100 * metrics.iou_success(np.array(ious), 0.5):.0f}%, hand pixels as target "
            f"{100 * hand:.1f}% (tracking_mug.png)"]


def _tracking_figure(path, f, r, index, start):
    import cv2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    from polar_sim.sim.pictures import save_figure

    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    ax[0].imshow(f["rgb"])
    ax[0].set_title(f"camera, frame {index} (the hand touches the mug)")
    tint = f["rgb"].copy()
    tint[r.mask] = (0.45 * tint[r.mask] + [0, 0, 140]).astype(np.uint8)
    edge = cv2.morphologyEx(f["mask_visible"].astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
    tint[edge] = (255, 255, 0)
    ax[1].imshow(tint)
    ax[1].set_title("tracker's segmentation against the truth")
    ax[1].legend(handles=[Patch(color=(0.2, 0.2, 0.7), label="tracker mask"),
                          Patch(color=(1, 1, 0), label="true visible outline")], fontsize=8, loc="lower right")
    for a in ax:
        a.set_xlabel("u [px]")
        a.set_ylabel("v [px]")
    fig.suptitle(f"tabletop mug_touch (simulated RGB-D, 320x240): ObjectTracker from the true pose at frame {start}, "
                 f"learning the mug's appearance online")
    save_figure(fig, path)


def demo_env(out: Path):
    """One GPISNav-v0 episode: the SDF navigator drives to the goal on the online map."""
    import gymnasium as gym

    import polar_sim.envs  # noqa: F401  (registers the ids)
    from polar_sim.envs.policies import SDFNavigator

    rooms, room_size = 2, 4.0
    env = gym.make("polar_sim/GPISNav-v0", sdf_source="gpis", render_mode="rgb_array", rooms=rooms,
                   room_size=room_size, clutter=3)
    pol = SDFNavigator()
    obs, info = env.reset(seed=1)
    start = info["goal_distance"]
    track = [info["robot_pose2d"][:2].copy()]
    done, n = False, 0
    while not done:
        obs, r, term, trunc, info = env.step(pol(obs))
        track.append(info["robot_pose2d"][:2].copy())
        done, n = term or trunc, n + 1
    _env_figure(out / "env_gpisnav.png", env, np.array(track), info, n, rooms * room_size / 2)
    env.close()
    return [f"GPISNav-v0 (gpis map): goal {start:.1f} m away, {'reached' if info['is_success'] else 'not reached'} "
            f"in {n} steps, path {info['path_length']:.1f} m, collision {info['collision']} (env_gpisnav.png)"]


def _env_figure(path, env, track, info, n, half):
    """The episode in three panels: the scene rendered from above; the exact SDF of the world with
    the path; the online GPIS map around the robot at the end (the environment's own view)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D

    from polar_sim.envs.gpis_nav import RENDER_SDF_RANGE, RENDER_SPAN, RENDER_ZERO_BAND
    from polar_sim.envs.lidar_nav import GOAL_RADIUS
    from polar_sim.sim.pictures import colorbar_beside, save_figure

    frame = env.render()                      # (h, 2w, 3): the top-down render | the map around the robot
    w = frame.shape[1] // 2
    lo, hi = RENDER_SDF_RANGE
    norm = Normalize(lo, hi)
    goal, pose = info["goal"], info["robot_pose2d"]
    fig, ax = plt.subplots(1, 3, figsize=(18, 5.6), gridspec_kw={"wspace": 0.32})
    ax[0].imshow(frame[:, :w])
    ax[0].set_title("the scene from above\n(render; walls white)")
    ax[0].set_xticks([])
    ax[0].set_yticks([])
    ax[0].set_xlabel(f"{2 * half:.0f} x {2 * half:.0f} m: 2 x 2 rooms, doors, clutter; the robot is the small box")
    # the exact SDF of the whole world, with the path
    m = half + 0.5
    xs = np.linspace(-m, m, 360)
    X, Y = np.meshgrid(xs, xs)
    sdf = env.unwrapped.world.sdf(np.stack([X.ravel(), Y.ravel()], 1)).reshape(X.shape)
    im = ax[1].imshow(sdf, origin="lower", extent=[-m, m, -m, m], cmap="viridis", norm=norm)
    ax[1].contour(X, Y, sdf, levels=[0.0], colors="w", linewidths=0.8)
    ax[1].plot(track[:, 0], track[:, 1], color="orange", lw=1.5)
    ax[1].plot(*track[0], "s", color="orange", ms=7)
    ax[1].add_patch(plt.Circle(goal[:2], GOAL_RADIUS, fill=False, color=(0.24, 0.86, 0.24), lw=2))
    ax[1].plot(*pose[:2], "o", color=(1, 0.31, 0.31), ms=7)
    ax[1].set_title(f"exact SDF of the world and the path driven\n({n} steps, {info['path_length']:.1f} m)")
    colorbar_beside(fig, ax[1], im, f"exact signed distance [m] (clipped to {lo:g}..{hi:g})")
    # the map around the robot at the end, as the environment renders it
    ext = [pose[0] - RENDER_SPAN, pose[0] + RENDER_SPAN, pose[1] - RENDER_SPAN, pose[1] + RENDER_SPAN]
    ax[2].imshow(frame[:, w:], extent=ext, origin="upper")
    ax[2].set_title(f"the online GPIS map around the robot at the end (the env's\nrender; beyond the outer wall: never seen, extrapolated)")
    colorbar_beside(fig, ax[2], ScalarMappable(norm, "viridis"),
                    f"map signed distance [m] (clipped to {lo:g}..{hi:g};\nwhite: |d| < {100 * RENDER_ZERO_BAND:g} cm, "
                    "the mapped surface)")
    for a in ax[1:]:
        a.set_xlabel("x [m]")
        a.set_ylabel("y [m]")
        a.set_aspect("equal")
    fig.legend(handles=[Line2D([], [], color="orange", lw=1.5, marker="s", markevery=[0], label="path (square: start)"),
                        Line2D([], [], ls="", marker="o", color=(1, 0.31, 0.31), ms=8,
                               label="robot at the end"),
                        Line2D([], [], ls="", marker="o", mfc="none", mec=(0.24, 0.86, 0.24), mew=2, ms=10,
                               label=f"goal (success within {GOAL_RADIUS:g} m)"),
                        Line2D([], [], color="w", lw=1.5, path_effects=_outlined(), label="zero level: the surface")],
               loc="lower center", ncol=4, fontsize=9, frameon=False, bbox_to_anchor=(0.5, -0.03))
    fig.suptitle("GPISNav-v0, seed 1: the SDFNavigator policy drives to the goal on a GPIS map built online from its "
                 "lidar (true pose given)")
    save_figure(fig, path)


DEMOS = [("scenes", demo_scenes), ("gpis", demo_gpis), ("ground", demo_ground), ("tracking", demo_tracking),
         ("envs", demo_env)]


def _kernels_cached() -> bool:
    """True when numba's cache already holds the GPIS kernels (``$NUMBA_CACHE_DIR`` if set, else the
    package's ``__pycache__``): a first run compiles them, which takes most of its time."""
    import os

    import polar_sim.gpis as gpis

    root = os.environ.get("NUMBA_CACHE_DIR")
    folder = Path(root) if root else Path(gpis.__file__).parent / "__pycache__"
    return folder.is_dir() and any(folder.rglob("_distance*.nbi"))


# The parts that use the GPIS kernels run in one process, so that its kernels compile once there
# (numba compiles per process); the others in the second.
_LANES = (("gpis", "envs"), ("scenes", "ground", "tracking"))


def _run_part(name, out):
    """Run one part by name: (lines, seconds, error message or None). A failure is reported, not
    raised, so that the other parts carry on."""
    fn = dict(DEMOS)[name]
    t0 = time.perf_counter()
    try:
        lines = fn(Path(out))
    except Exception as exc:  # report and carry on with the other parts
        return [], time.perf_counter() - t0, f"{type(exc).__name__}: {exc}"
    return lines, time.perf_counter() - t0, None


def run_demo(out: Path, quick=True, workers=None):
    """Run every demo part; returns the process exit code.

    ``workers``: 1 runs the parts one after the other in this process; 2 (the default when the
    machine has two or more cores) runs them in two worker processes, the GPIS parts (``gpis``,
    ``envs``) in one and the rest in the other, so that a first run's numba compiles overlap the
    other parts. Each part is seeded, so its numbers and pictures do not depend on ``workers``.
    """
    import os

    from tqdm import tqdm

    if workers is None:
        workers = 2 if (os.cpu_count() or 1) >= 2 else 1
    if workers not in (1, 2):
        raise ValueError(f"workers must be 1 or 2, got {workers!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"polar_sim demo: writing pictures to {out}/")
    if not _kernels_cached():
        print("first run: numba compiles the GPIS, ground and tracking kernels once (about a minute "
              "on 2 cores); later runs load them from numba's cache")
    rc = 0
    bar = tqdm(total=len(DEMOS), desc="demo", unit="part")

    def report(name, lines, dt, err):
        nonlocal rc
        if err is not None:
            tqdm.write(f"[{name}] FAILED: {err}")
            rc = 1
        else:
            for line in lines:
                tqdm.write(f"[{name}] {line}")
            tqdm.write(f"[{name}] done in {dt:.1f} s")
        bar.update(1)

    if workers == 1:
        for name, _ in DEMOS:
            bar.set_postfix_str(name)
            report(name, *_run_part(name, out))
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = mp.get_context("spawn")  # a fresh interpreter: no forked MuJoCo/EGL or numba state
        pools = [ProcessPoolExecutor(1, mp_context=ctx) for _ in _LANES]
        try:
            futs = {pool.submit(_run_part, name, str(out)): name
                    for pool, lane in zip(pools, _LANES) for name in lane}
            bar.set_postfix_str(", ".join(lane[0] for lane in _LANES))
            for f in as_completed(futs):
                report(futs[f], *f.result())
        finally:
            for pool in pools:
                pool.shutdown()
    bar.close()
    pngs = sorted(out.glob("*.png"))
    print(f"wrote {len(pngs)} PNGs to {out}/")
    return rc
