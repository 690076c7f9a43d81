"""Speed (and a sanity check of accuracy) of polar_sim.tracking on synthetic 640x480 RGB-D frames.

    python benchmarks/bench_tracking.py [--quick] [--objects mug,box] [--variants h,ww,...]

Single-threaded: OpenCV, numba and the BLAS are limited to one thread before anything runs.
Frames are rendered first (not timed); each tracker's first frame (JIT and cache warm-up) is left
out of the timings. Prints a markdown table per object: per-frame time (median, mean, p95), frames
per second from the median, the ratio to ICG's 1.3 ms/frame, the per-stage split, and ADD / IoU /
hand-pixel figures of the same run. Results are recorded in benchmarks/results/tracking.md.
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
from polar_sim.tracking import ObjectTracker  # noqa: E402
from polar_sim.tracking.synthetic import make_sequence  # noqa: E402

ICG_MS = 1.3
VARIANTS = {
    "h": dict(appearance="h"),
    "su": dict(appearance="su"),
    "sw": dict(appearance="sw"),
    "wu": dict(appearance="wu"),
    "ww": dict(appearance="ww"),
    "shape-only": dict(appearance="none"),
    "plain-icp": dict(appearance="none", registration="plain"),
}
STAGES = ("validate", "predict_attention", "depth_likelihood", "appearance", "registration", "labels",
          "learning", "output")


def run(seq, frames, P, N, kw, symmetric=False):
    tr = ObjectTracker(P, seq.K, seq.poses[0], model_normals=N, **kw)
    res = [tr.process(f["rgb"], f["depth"]) for f in frames]
    t = np.array([r.time_s for r in res[1:]]) * 1000.0
    st = {k: 1000.0 * np.median([r.stage_times.get(k, 0.0) for r in res[1:]]) for k in STAGES}
    d = metrics.object_diameter(P)
    G = np.stack([f["pose"] for f in frames])
    E = np.stack([r.pose for r in res])
    err = metrics.adds(P, G, E) if symmetric else metrics.add(P, G, E)  # ADD-S for the cylinder
    masks = np.stack([r.mask for r in res])
    ious = metrics.iou(masks, np.stack([f["mask"] for f in frames]))
    hand = metrics.occluder_as_target(masks, np.stack([f["hand"] for f in frames]))
    return dict(t=t, stages=st, add_ok=metrics.add_success(err, d, 0.1), add_mm=1000 * float(np.mean(err)),
                auc=metrics.pose_auc(err, 0.1), iou_ok=metrics.iou_success(ious, 0.5),
                iou=float(np.mean(ious)), hand=hand, lost=int(sum(r.lost for r in res)),
                roi=float(np.mean([(r.roi[2] - r.roi[0]) * (r.roi[3] - r.roi[1]) for r in res])))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="30 frames, mug only (CI size)")
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--objects", default=None, help="comma list of mug, box, cylinder")
    ap.add_argument("--variants", default=None, help="comma list of " + ", ".join(VARIANTS))
    ap.add_argument("--speed", type=float, default=1.0, help="motion speed factor of the sequence")
    a = ap.parse_args(argv)
    cv2.setNumThreads(1)
    n = a.frames or (30 if a.quick else 120)
    objects = (a.objects or ("mug" if a.quick else "mug,box,cylinder")).split(",")
    variants = (a.variants or ",".join(VARIANTS)).split(",")
    print(f"# bench_tracking: {n} frames 640x480, objects {objects}, speed x{a.speed}")
    print(f"# {platform.processor() or platform.machine()}, python {platform.python_version()}, "
          f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} at start")
    for obj in objects:
        seq = make_sequence(n, obj, speed=a.speed)
        P, N = seq.model(3000)
        t0 = time.perf_counter()
        frames = [seq.frame(i) for i in range(n)]
        print(f"\n## {obj} (diameter {100 * metrics.object_diameter(P):.1f} cm; rendering {1000 * (time.perf_counter() - t0) / n:.0f} ms/frame, not timed)\n")
        print("| variant | median ms | mean ms | p95 ms | fps (median) | x ICG | ADD<0.1d | mean ADD mm | AUC | IoU>0.5 | mean IoU | hand as target | lost | ROI px |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        split = {}
        for v in variants:
            r = run(seq, frames, P, N, VARIANTS[v], symmetric=obj == "cylinder")
            t = r["t"]
            med = float(np.median(t))
            split[v] = r["stages"]
            print(f"| {v} | {med:.1f} | {t.mean():.1f} | {np.percentile(t, 95):.1f} | {1000 / med:.0f} | "
                  f"{med / ICG_MS:.0f} | {r['add_ok']:.3f} | {r['add_mm']:.2f} | {r['auc']:.3f} | {r['iou_ok']:.3f} | "
                  f"{r['iou']:.3f} | {r['hand']:.3f} | {r['lost']} | {r['roi']:.0f} |", flush=True)
        print("\nmedian ms per stage:\n")
        print("| variant | " + " | ".join(STAGES) + " |")
        print("|---" * (len(STAGES) + 1) + "|")
        for v, st in split.items():
            print(f"| {v} | " + " | ".join(f"{st[k]:.2f}" for k in STAGES) + " |")
    print(f"\n# load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} at end")


if __name__ == "__main__":
    main()
