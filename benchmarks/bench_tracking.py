"""Speed (and a sanity check of accuracy) of polar_sim.tracking on synthetic 640x480 RGB-D frames.

    python benchmarks/bench_tracking.py [--quick] [--objects mug,box] [--variants h,ww,...]
    python benchmarks/bench_tracking.py --tabletop touch,push --seeds 1,2 --frames 200   # simulator
    python benchmarks/bench_tracking.py --sequences test --seed 10000    # the recorded randomised sequences
    python benchmarks/bench_tracking.py --sequences dev+test --frames 150  # both splits side by side

``--sequences`` (a split name, "dev" or "test", or a comma list of sequence names; parts joined by
"+" run side by side in one process, each split at its own seed) times the tracker
on the cached 640x480 recordings of :mod:`polar_sim.sim.recorders.tabletop_sequences` (recorded first if
missing, not timed) and asks where the cost comes from: per sequence the CPU time per frame, the
object's image size (amodal pixels) and the ROI; pooled over all frames, a linear fit of CPU time on
the object's pixels and the Spearman correlations with the object's and the ROI's pixels, and the
per-stage times in terciles of the object's image size (issue 13 item 7).

Single-threaded: OpenCV, numba and the BLAS are limited to one thread before anything runs.
Frames are rendered first (not timed); each tracker's first frame (JIT and cache warm-up) is left
out of the timings. Each variant runs ``--repeats`` times and each frame keeps its fastest run
(the machine is shared; the fastest run is the best estimate of the unloaded cost). The primary
figure is the process CPU time per ``process()`` call: everything runs on one thread, so it is
what the wall time would be on an idle core, and unlike wall time it does not grow with other
jobs' load. Prints a markdown table per object: CPU time per frame (median, mean, p95), frames
per second from the median, the ratio to ICG's 1.3 ms/frame, the median wall time, the
per-stage split (wall time, fastest run), and ADD / IoU / hand-pixel figures
of the same run. Results are recorded in benchmarks/results/tracking.md.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from polar_sim import metrics  # noqa: E402
from polar_sim.tracking import ObjectTracker, RegistrationConfig  # noqa: E402
from polar_sim.tracking.synthetic import make_sequence  # noqa: E402

ICG_MS = 1.3
VARIANTS = {
    "h": dict(appearance="h"),
    "su": dict(appearance="su"),
    "sw": dict(appearance="sw"),
    "wu": dict(appearance="wu"),
    "ww": dict(appearance="ww"),
    "shape-only": dict(appearance="none"),
    "plain-icp": dict(appearance="none", registration=RegistrationConfig(method="plain")),
}
STAGES = ("validate", "predict_attention", "depth_likelihood", "appearance", "registration", "labels",
          "learning", "output")


def run(seq, frames, P, N, kw, symmetric=False, repeats=1):
    """Track the frames ``repeats`` times (deterministic: the same work each time) and keep, per
    frame and per stage, the fastest repeat: on a shared machine that is the closest estimate of
    the unloaded cost. The accuracy figures come from the (identical) results."""
    times, cpu, stages = [], [], []
    for _ in range(repeats):
        tr = ObjectTracker(P, seq.K, seq.poses[0], model_normals=N, **kw)
        res, c = [], []
        for f in frames:
            c0 = time.process_time()
            res.append(tr.process(f["rgb"], f["depth"]))
            c.append(time.process_time() - c0)
        times.append([r.time_s for r in res[1:]])
        cpu.append(c[1:])
        stages.append([[r.stage_times.get(k, 0.0) for k in STAGES] for r in res[1:]])
    t = np.min(times, axis=0) * 1000.0
    tc = np.min(cpu, axis=0) * 1000.0
    st = dict(zip(STAGES, 1000.0 * np.median(np.min(stages, axis=0), axis=0)))
    d = metrics.object_diameter(P)
    G = np.stack([f["pose"] for f in frames])
    E = np.stack([r.pose for r in res])
    err = metrics.adds(P, G, E) if symmetric else metrics.add(P, G, E)  # ADD-S for the cylinder
    masks = np.stack([r.mask for r in res])
    ious = metrics.iou(masks, np.stack([f["mask"] for f in frames]))
    hand = metrics.occluder_as_target(masks, np.stack([f["hand"] for f in frames]))
    return dict(t=t, cpu=tc, stages=st, add_ok=metrics.add_success(err, d, 0.1), add_mm=1000 * float(np.mean(err)),
                auc=metrics.pose_auc(err, 0.1), iou_ok=metrics.iou_success(ious, 0.5),
                iou=float(np.mean(ious)), hand=hand, lost=int(sum(r.lost for r in res)),
                roi=float(np.mean([(r.roi[2] - r.roi[0]) * (r.roi[3] - r.roi[1]) for r in res])))


def tabletop(scripts, seeds, n, variants):
    """Spot check on the simulator's ``tabletop`` scene (imports polar_sim.sim, i.e. MuJoCo).

    Per (script, seed): the seeded target, GT initial pose, ADD / ADD-S success at 0.1 d, IoU against
    the rendered target label, and hand pixels labelled target among the hand pixels inside the
    target's dilated silhouette (visible target pixels dilated by 15 px)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    from polar_sim.sim import LABELS, World

    print("| script | seed | target | variant | ADD<0.1d | ADD-S<0.1d | mean ADD mm | IoU>0.5 | mean IoU | "
          "hand as target (near object) | lost | CPU ms median |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    ker = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (31, 31))
    for script in scripts:
        for seed in seeds:
            w = World("tabletop", seed=seed, script=script)
            w.reset(seed=seed)
            name = w.truth()["target"]
            P, N = w.object_points(name, 3000)
            d = metrics.object_diameter(P)
            frames = []
            for i in range(n):
                if i:
                    w.step()
                f = w.camera("rgbd")
                T = np.linalg.inv(f.T_world_cam) @ w.truth()["objects"][name]
                tgt = f.labels == LABELS["target"]
                near = cv2.dilate(tgt.astype(np.uint8), ker) > 0
                frames.append((f.rgb, f.depth, f.K, T, tgt, (f.labels == LABELS["occluder"]) & near))
            w.close()
            for v in variants:
                kw = VARIANTS[v]
                tr = ObjectTracker(P, frames[0][2], frames[0][3], model_normals=N, **kw)
                res, cpu = [], []
                for rgb, depth, *_ in frames:
                    c0 = time.process_time()
                    res.append(tr.process(rgb, depth))
                    cpu.append(time.process_time() - c0)
                G = np.stack([fr[3] for fr in frames])
                E = np.stack([r.pose for r in res])
                e, es = metrics.add(P, G, E), metrics.adds(P, G, E)
                masks = np.stack([r.mask for r in res])
                ious = metrics.iou(masks, np.stack([fr[4] for fr in frames]))
                hand = metrics.occluder_as_target(masks, np.stack([fr[5] for fr in frames]))
                print(f"| {script} | {seed} | {name} | {v} | {metrics.add_success(e, d):.3f} | "
                      f"{metrics.add_success(es, d):.3f} | {1000 * e.mean():.1f} | "
                      f"{metrics.iou_success(ious):.3f} | "
                      f"{ious.mean():.3f} | {hand:.3f} | {sum(r.lost for r in res)} | "
                      f"{1000 * np.median(cpu[1:]):.1f} |", flush=True)


def _model(obj, how):
    """3000 model points and normals: area-uniform, or 1000 per part (``parts``: the atlas tiles, e.g.
    blocks' body, post and small block), which leaves a large part sparse (issue 13 item 4)."""
    import trimesh

    from polar_sim.sim.builders import objects

    mesh = objects.load_mesh(obj)
    if how == "uniform":
        P, face = trimesh.sample.sample_surface(mesh, 3000, seed=0)
        return np.asarray(P), np.asarray(mesh.face_normals[face])
    tiles = objects._face_tiles(obj, mesh)
    Ps, Ns = [], []
    for k in np.unique(tiles):
        sub = mesh.submesh([np.flatnonzero(tiles == k)], append=True)
        p, f = trimesh.sample.sample_surface(sub, 3000 // len(np.unique(tiles)), seed=0)
        Ps.append(np.asarray(p)), Ns.append(np.asarray(sub.face_normals[f]))
    return np.vstack(Ps), np.vstack(Ns)


def _part_recall(obj, f, T, K, mask):
    """Recall of the mask on each atlas part of the object's visible pixels (blocks: body, post, block)."""
    from polar_sim.sim.builders import objects

    v, u = np.nonzero(f["mask_visible"])
    z = f["depth_clean"][v, u]
    X = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], 1)
    Y = (X - T[:3, 3]) @ T[:3, :3]
    mesh = objects.load_mesh(obj)
    _, _, tri = mesh.nearest.on_surface(Y)
    part = objects._face_tiles(obj, mesh)[tri]
    return {int(k): (float(mask[v, u][part == k].mean()), int((part == k).sum())) for k in np.unique(part)}


def sequences(names, seed, variants, repeats, max_frames=None, model="uniform"):
    """Item 7: CPU per frame on recorded 640x480 sequences against the object's image size and the scene.
    With ``model="parts"`` also the mask's recall per part of the object (item 4)."""
    from scipy.stats import spearmanr

    from polar_sim.sim.recorders.tabletop_sequences import SPLIT_SEEDS, cached_sequence, list_sequences

    runs = []   # (name, seed, split): splits joined by "+" run side by side, each at its own seed
    for part in names.split("+"):
        if part in ("dev", "test", "dev_appearance"):
            runs += [(n, SPLIT_SEEDS[part][0], part) for n in list_sequences(part)]
        else:
            runs += [(n, seed, "given") for n in part.split(",")]
    print("| sequence | appearance | variant | frames | CPU ms median | p95 | frames/s | object px median | ROI px median |"
          " mask recall per part (part: recall, pixels) |")
    print("|---|---|---|---|---|---|---|---|---|")
    pooled = {v: {"cpu": [], "tgt": [], "roi": [], "st": [], "fam": [], "split": []} for v in variants}
    for name, seed, split in runs:
        rec = cached_sequence(name, seed)
        n = len(rec) if max_frames is None else min(len(rec), max_frames)
        frames = [f for _, f in rec.frames(0, n, keys=("rgb", "depth", "mask_full", "mask_visible", "depth_clean"))]
        G, ts = rec.stack("T_cam_obj"), rec.stack("t")
        P, N = _model(rec.meta["object"], model)
        K = np.array(rec.meta["K"])
        fam = (rec.meta.get("appearance") or {}).get("family", "default")
        tgt = np.array([f["mask_full"].sum() for f in frames])
        for v in variants:
            best = None
            for _ in range(repeats):
                tr = ObjectTracker(P, K, G[0], model_normals=N, **VARIANTS[v])
                cpu, roi, st, parts = [], [], [], {}
                for i, f in enumerate(frames):
                    c0 = time.process_time()
                    r = tr.process(f["rgb"], f["depth"], float(ts[i]))
                    cpu.append(1000 * (time.process_time() - c0))
                    if model == "parts" and i % 10 == 0:
                        for k, (rc, npx) in _part_recall(rec.meta["object"], f, G[i], K, r.mask).items():
                            parts.setdefault(k, []).append((rc * npx, npx))
                    roi.append((r.roi[2] - r.roi[0]) * (r.roi[3] - r.roi[1]))
                    st.append([1000 * r.stage_times.get(k, 0.0) for k in STAGES])
                cpu = np.array(cpu)
                best = cpu if best is None else np.minimum(best, cpu)
            c, R = best[1:], np.array(roi)[1:]
            for k, x in (("cpu", c), ("tgt", tgt[1:]), ("roi", R), ("st", np.array(st)[1:])):
                pooled[v][k].append(x)
            pooled[v]["fam"] += [fam] * len(c)
            pooled[v]["split"] += [split] * len(c)
            print(f"| {name} | {fam} | {v} | {len(c)} | {np.median(c):.1f} | {np.percentile(c, 95):.1f} | "
                  f"{1000 / np.median(c):.0f} | {np.median(tgt):.0f} | {np.median(R):.0f} | "
                  + ", ".join(f"{k}: {sum(a for a, _ in x) / max(sum(b for _, b in x), 1):.2f} ({sum(b for _, b in x)})"
                              for k, x in sorted(parts.items())) + " |", flush=True)
    for v, d in pooled.items():
        c, t, R, st = (np.concatenate(d[k]) for k in ("cpu", "tgt", "roi", "st"))
        fam, spl = np.array(d["fam"]), np.array(d["split"])
        b, a0 = np.polyfit(t / 1e4, c, 1)
        r2 = 1 - np.var(c - (a0 + b * t / 1e4)) / np.var(c)
        print(f"\n{v}: {len(c)} frames, CPU ms median {np.median(c):.1f} ({1000 / np.median(c):.0f} frames/s), p95 "
              f"{np.percentile(c, 95):.1f}; fit CPU = {a0:.1f} ms + {b:.2f} ms per 10,000 object px (R^2 {r2:.2f}); "
              f"Spearman with object px {spearmanr(t, c).statistic:.2f}, with ROI px {spearmanr(R, c).statistic:.2f}")
        q = np.quantile(t, [1 / 3, 2 / 3])
        print("\n| object px tercile | frames | object px median | CPU ms median | " + " | ".join(STAGES) + " |")
        print("|---" * (len(STAGES) + 4) + "|")
        for k, m in enumerate([t <= q[0], (t > q[0]) & (t <= q[1]), t > q[1]]):
            if not m.any():
                continue
            print(f"| {k + 1} | {m.sum()} | {np.median(t[m]):.0f} | {np.median(c[m]):.1f} | "
                  + " | ".join(f"{x:.2f}" for x in np.median(st[m], axis=0)) + " |")
        # the scene at equal object size: the residual of the size fit per family and per split
        res = c - (a0 + b * t / 1e4)
        for key, lab in ((fam, "appearance family"), (spl, "split")):
            print(f"\n| {lab} | frames | CPU ms median | object px median | CPU ms per 10,000 object px | "
                  "median residual of the size fit, ms |")
            print("|---|---|---|---|---|---|")
            for f in sorted(set(key)):
                m = key == f
                print(f"| {f} | {m.sum()} | {np.median(c[m]):.1f} | {np.median(t[m]):.0f} | "
                      f"{np.median(c[m] / np.maximum(t[m], 1) * 1e4):.2f} | {np.median(res[m]):+.1f} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="30 frames, mug only (CI size)")
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--objects", default=None, help="comma list of mug, box, cylinder")
    ap.add_argument("--variants", default=None, help="comma list of " + ", ".join(VARIANTS))
    ap.add_argument("--speed", type=float, default=1.0, help="motion speed factor of the sequence")
    ap.add_argument("--hand-color", default="225,170,140", help="R,G,B of the hand (e.g. the object's colour)")
    ap.add_argument("--brightness", default="1,1", help="first,last image gain (a lighting ramp)")
    ap.add_argument("--tabletop", default=None,
                    help="comma list of tabletop scripts: spot check on the simulator instead (needs MuJoCo)")
    ap.add_argument("--seeds", default="1,2", help="tabletop seeds (with --tabletop)")
    ap.add_argument("--sequences", default=None,
                    help="a split (dev, test, dev_appearance) or comma list of recorded sequences, parts joined by + "
                         "(dev+test: both splits side by side, each at its seed; item 7)")
    ap.add_argument("--seed", type=int, default=10000, help="seed of sequences given by name (with --sequences; a split uses its own)")
    ap.add_argument("--model", default="uniform", choices=("uniform", "parts"),
                    help="model points: area-uniform, or 1000 per part (with --sequences; prints recall per part)")
    ap.add_argument("--repeats", type=int, default=None,
                    help="runs per variant; per-frame times are the fastest run (default 3, quick 2)")
    a = ap.parse_args(argv)
    cv2.setNumThreads(1)
    n = a.frames or (30 if a.quick else 120)
    if a.sequences:
        print(f"# bench_tracking --sequences {a.sequences} --seed {a.seed}: 640x480, one thread, "
              f"best of {a.repeats or 1} runs per frame; {platform.processor() or platform.machine()}, load average "
              f"{os.getloadavg()[0]:.2f} at start")
        sequences(a.sequences, a.seed, (a.variants or "ww").split(","), a.repeats or 1, a.frames, a.model)
        print(f"# load average {os.getloadavg()[0]:.2f} at end")
        return
    if a.tabletop:
        print(f"# bench_tracking --tabletop: {n} frames per sequence, load average "
              f"{os.getloadavg()[0]:.2f} at start")
        tabletop(a.tabletop.split(","), [int(x) for x in a.seeds.split(",")], n,
                 (a.variants or "ww").split(","))
        print(f"# load average {os.getloadavg()[0]:.2f} at end")
        return
    objects = (a.objects or ("mug" if a.quick else "mug,box,cylinder")).split(",")
    variants = (a.variants or ",".join(VARIANTS)).split(",")
    repeats = a.repeats or (2 if a.quick else 3)
    print(f"# bench_tracking: {n} frames 640x480, objects {objects}, speed x{a.speed}, hand {a.hand_color}, "
          f"brightness {a.brightness}, best of {repeats} runs per frame")
    print(f"# {platform.processor() or platform.machine()}, python {platform.python_version()}, "
          f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} at start")
    for obj in objects:
        seq = make_sequence(n, obj, speed=a.speed, hand_color=tuple(int(c) for c in a.hand_color.split(",")),
                            brightness=tuple(float(b) for b in a.brightness.split(",")))
        P, N = seq.model(3000)
        t0 = time.perf_counter()
        frames = [seq.frame(i) for i in range(n)]
        render_ms = 1000 * (time.perf_counter() - t0) / n
        print(f"\n## {obj} (diameter {100 * metrics.object_diameter(P):.1f} cm; "
              f"rendering {render_ms:.0f} ms/frame, not timed)\n")
        print("| variant | CPU ms median | CPU ms mean | CPU ms p95 | fps (CPU median) | x ICG | wall ms median | "
              "ADD<0.1d | mean ADD mm | AUC | IoU>0.5 | mean IoU | hand as target | lost | ROI px |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        split = {}
        for v in variants:
            r = run(seq, frames, P, N, VARIANTS[v], symmetric=obj == "cylinder", repeats=repeats)
            t = r["cpu"]
            med = float(np.median(t))
            split[v] = r["stages"]
            print(f"| {v} | {med:.1f} | {t.mean():.1f} | {np.percentile(t, 95):.1f} | {1000 / med:.0f} | "
                  f"{med / ICG_MS:.0f} | {np.median(r['t']):.1f} | {r['add_ok']:.3f} | {r['add_mm']:.2f} | "
                  f"{r['auc']:.3f} | {r['iou_ok']:.3f} | "
                  f"{r['iou']:.3f} | {r['hand']:.3f} | {r['lost']} | {r['roi']:.0f} |", flush=True)
        print("\nmedian ms per stage:\n")
        print("| variant | " + " | ".join(STAGES) + " |")
        print("|---" * (len(STAGES) + 1) + "|")
        for v, st in split.items():
            print(f"| {v} | " + " | ".join(f"{st[k]:.2f}" for k in STAGES) + " |")
    print(f"\n# load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} at end")


if __name__ == "__main__":
    main()
