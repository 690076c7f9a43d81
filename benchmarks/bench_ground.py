"""Benchmark of polar_sim.ground.GroundVO: per-frame time at 640x480 (single thread) and accuracy on
synthetic frames rendered by :mod:`polar_sim.ground.synthetic` (textured ground + corridor walls).

    python benchmarks/bench_ground.py                 # 120 frames, prints a markdown report
    python benchmarks/bench_ground.py --frames 40     # quicker
    python benchmarks/bench_ground.py --write benchmarks/results/ground.md
    python benchmarks/bench_ground.py --route flat_00 --route-frames 300   # a simulator route (MuJoCo)

Timing covers ``GroundVO.process`` only (rendering excluded), with OpenCV and BLAS on one thread. CPU
time (``time.process_time``) is the single-thread cost; wall time also counts waiting for the CPU when
other jobs load the machine (the report records the load average).
Accuracy on a short synthetic route is not the KITTI-segment score of the issue (that needs the
simulator's 500–2000 m routes); the drift and ΔV_mean here are sanity figures of the same pipeline.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from polar_sim import metrics  # noqa: E402
from polar_sim.ground import CalibrationConfig, ClassifierConfig, DenseConfig, GroundVO  # noqa: E402
from polar_sim.ground.synthetic import make_sequence  # noqa: E402
from polar_sim.metrics.ground import classifier_auc, classifier_iou, ground_success, laplace_scale  # noqa: E402

CONDITIONS = {"u2": dict(model="2param", sampling="uniform"), "w2": dict(model="2param", sampling="weighted"),
              "u6": dict(model="6param", sampling="uniform"), "w6": dict(model="6param", sampling="weighted"),
              # w6 as before issue 13 (no calibration of ground_prob, the spec's classifier training): the cost
              # of the calibration is the difference to w6.
              "w6 nocal": dict(model="6param", sampling="weighted", calibration=CalibrationConfig(method="none"),
                               classifier=ClassifierConfig(train_depth=None, decay_samples=None)),
              # w6 without the dense ground alignment (issue 35): its cost is the difference to w6.
              "w6 no dense": dict(model="6param", sampling="weighted", dense=DenseConfig(enabled=False))}


def build(K, h, kw, seed=0):
    """GroundVO of a condition: keyword arguments, with ``published=True`` for ``GroundVO.published()``."""
    kw = dict(kw)
    make = GroundVO.published if kw.pop("published", False) else GroundVO
    return make(K, h, seed=seed, **kw)


def run_condition(seq, name, kw, seed=0):
    vo = build(seq["K"], seq["camera_height"], kw, seed)
    times, cpu, es = [], [], []
    for i in range(len(seq["times"])):
        t0, c0 = time.perf_counter(), time.process_time()
        e = vo.process(seq["rgb"][i], seq["times"][i])
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        es.append(e)
    times = np.array(times[2:]) * 1e3  # the first two frames only detect
    cpu = np.array(cpu[2:]) * 1e3
    V, w = seq["speed"], seq["yaw_rate"]
    raw = np.array([e.speed_raw for e in es])
    ok = np.isfinite(raw)
    traj = vo.trajectory()
    gt = seq["poses"]
    dist = np.sum(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1))
    g_masks, i_masks = [], []
    for e in es[2:]:
        m = seq["ground_mask"][e.diagnostics["middle_index"]]
        c = np.rint(e.candidates).astype(int)
        g_masks.append(m[c[:, 1], c[:, 0]] if len(c) else np.zeros(0, bool))
        i_masks.append(e.inlier_mask)
    succ = ground_success(g_masks, i_masks)
    settled = es[len(es) // 2:]
    iou = np.mean([classifier_iou(e.ground_prob, seq["ground_mask"][e.index]) for e in settled])
    auc = np.mean([classifier_auc(e.ground_prob, seq["ground_mask"][e.index]) for e in settled[-5:]])
    L = metrics.scaled_lengths(gt) if dist > 20 else None
    t_err, r_err = metrics.kitti_errors(gt, traj, lengths=L, step=1) if L else (np.nan, np.nan)
    return dict(name=name, ms_median=np.median(times), ms_p90=np.percentile(times, 90), ms_max=times.max(),
                cpu_median=np.median(cpu), cpu_p90=np.percentile(cpu, 90), cpu_mean=cpu.mean(),
                dv_mean=laplace_scale(raw[ok] - V), v_bias=np.mean(raw[ok] - V),
                w_err=np.mean(np.abs(np.array([e.yaw_rate for e in es[10:]]) - w)),
                drift=np.linalg.norm(traj[-1][:3, 3] - gt[-1][:3, 3]) / dist * 100, t_err=t_err, r_err=r_err,
                ate=metrics.ate(gt, traj), ps=succ.ps, precision=succ.precision, iou=iou, auc=auc,
                fit_frac=ok[2:].mean(), dist=dist)


def time_condition(seq, kw, repeat):
    """Per-frame CPU ms, the minimum over ``repeat`` identical passes (the estimator is deterministic), so
    that CPU contention from other jobs inflates it less; returns (median, p90) over frames."""
    best = None
    for _ in range(repeat):
        vo = build(seq["K"], seq["camera_height"], kw)
        cpu = []
        for i in range(len(seq["times"])):
            c0 = time.process_time()
            vo.process(seq["rgb"][i], seq["times"][i])
            cpu.append(time.process_time() - c0)
        cpu = np.array(cpu[2:]) * 1e3
        best = cpu if best is None else np.minimum(best, cpu)
    return float(np.median(best)), float(np.percentile(best, 90))


def run_route(name, frames, conditions):
    """Score conditions on a cached simulator route (``polar_sim.sim.recorders.rover_sequences``; 621x188, already
    reduced, so ``downsample=1``). Returns report lines."""
    from polar_sim.sim.recorders.rover_sequences import load_route  # imports mujoco: benchmark only

    rec = load_route(name, max_frames=frames, progress=False)
    K, h = np.array(rec.meta["K"]), rec.meta["camera_height"]
    T = rec.stack("T_world_cam")
    gt = np.linalg.inv(T[0]) @ T
    speed, yaw = rec.stack("speed"), rec.stack("w_cam")[:, 1]
    masks = rec.stack("ground_mask")
    dist = float(np.sum(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1)))
    lines = [f"Route `{name}`, first {len(rec)} frames ({dist:.0f} m, {rec.meta['scene']}, 621x188, "
             f"h = {h} m), `downsample=1`:", "",
             "| condition | CPU ms/frame median | ΔV_mean (m/s) | V bias (%) | mean ω err (rad/s) "
             "| KITTI t % (100 m segs) "
             "| r (deg/m) | t % (scaled segs) | r (deg/m) | ps | precision | IoU (settled, mean) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for cname, kw in conditions.items():
        vo = build(K, h, {"downsample": 1, **kw})
        es, cpu = [], []
        for _, f in rec.frames(keys=("rgb", "t")):
            c0 = time.process_time()
            es.append(vo.process(f["rgb"], f["t"]))
            cpu.append(time.process_time() - c0)
        est = vo.trajectory()
        mid = np.array([max(e.diagnostics["middle_index"], 0) for e in es])
        raw = np.array([e.speed_raw for e in es])
        ok = np.isfinite(raw) & (np.arange(len(es)) >= 2)
        wraw = np.array([e.yaw_rate_raw for e in es])
        okw = np.isfinite(wraw) & (np.arange(len(es)) >= 2)
        g_masks, i_masks = [], []
        for e in es[2:]:
            c = np.rint(e.candidates).astype(int)
            g_masks.append(masks[e.diagnostics["middle_index"]][c[:, 1], c[:, 0]] if len(c) else np.zeros(0, bool))
            i_masks.append(e.inlier_mask)
        succ = ground_success(g_masks, i_masks)
        iou = np.mean([classifier_iou(e.ground_prob, masks[e.index]) for e in es[len(es) // 2:]])
        t_std, r_std = metrics.kitti_errors(gt, est)
        t_sc, r_sc = metrics.kitti_errors(gt, est, lengths=metrics.scaled_lengths(gt))
        lines.append(f"| {cname} | {np.median(cpu[2:]) * 1e3:.1f} | {laplace_scale(raw[ok] - speed[mid][ok]):.3f} "
                     f"| {100 * np.median(raw[ok] / speed[mid][ok] - 1):+.2f} "
                     f"| {np.mean(wraw[okw] - yaw[mid][okw]):+.5f} | {t_std:.2f} | {r_std:.4f} | {t_sc:.2f} "
                     f"| {r_sc:.4f} | {succ.ps:.3f} | {succ.precision:.3f} | {iou:.3f} |")
    return lines + ["", "KITTI t/r with 100..800 m segments use only the segments that fit in the route "
                    "(here 100 m ones); the scaled variant (L_j = j·L_max/8) is non-standard. ω err is the "
                    "mean signed raw yaw-rate error against `w_cam[1]` at the middle frame.", ""]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--speed", type=float, default=6.0)
    ap.add_argument("--yaw-rate", type=float, default=0.05)
    ap.add_argument("--height", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--full-res", action="store_true", help="also time downsample=1 (processing at 640x480)")
    ap.add_argument("--repeat", type=int, default=3, help="passes for the min-of-repeats CPU timing")
    ap.add_argument("--route", action="append", default=[], help="also score this simulator route (repeatable)")
    ap.add_argument("--route-frames", type=int, default=300)
    ap.add_argument("--write", help="write the markdown report to this file")
    args = ap.parse_args(argv)
    cv2.setNumThreads(1)

    t0 = time.perf_counter()
    seq = make_sequence(args.frames, width=640, height=480, fovy_deg=60.0, speed=args.speed, yaw_rate=args.yaw_rate,
                        dt=0.1, camera_height=args.height, seed=args.seed)
    t_render = time.perf_counter() - t0
    GroundVO(seq["K"], seq["camera_height"]).process(seq["rgb"][0], 0.0)  # compile the numba kernel first

    rows = [run_condition(seq, n, kw) for n, kw in CONDITIONS.items()]
    # The published code started its filters from the true speed and yaw rate (B21); do the same here,
    # otherwise its adaptive speed filter (P0 = 2q, r = innovation²) barely leaves a wrong prior.
    rows.append(run_condition(seq, "w6 code (B21 prior)", dict(model="6param", sampling="weighted", published=True,
                                                               filters__speed_prior=args.speed,
                                                               filters__yaw_prior=args.yaw_rate)))
    if args.full_res:
        rows.append(run_condition(seq, "w6 full-res", dict(model="6param", downsample=1)))

    load = os.getloadavg()
    try:
        cpu = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
        cpu = next((ln.split(":", 1)[1].strip() for ln in cpu.splitlines() if ln.startswith("Model name")), "?")
    except OSError:
        cpu = platform.processor() or "?"
    cmd = "python " + " ".join([os.path.relpath(__file__)] + sys.argv[1:])
    out = [
        "# GroundVO benchmark (synthetic frames)",
        "",
        f"Command: `{cmd}`  ",
        f"Machine: {cpu}, {os.cpu_count()} cores; cv2.setNumThreads(1), BLAS/OMP 1 thread; "
        f"load average during the run {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (other jobs share the CPU).  ",
        f"Scene: 640x480, fovy 60°, camera {args.height} m above a textured ground between textured corridor "
        f"walls, V = {args.speed} m/s, ω = {args.yaw_rate} rad/s, 10 Hz, {args.frames} frames "
        f"({rows[0]['dist']:.0f} m); rendering {t_render:.1f} s (excluded).",
        "",
        "| condition | CPU ms/frame median | CPU p90 | CPU mean | wall ms median | wall p90 | ΔV_mean (m/s) "
        "| V bias (m/s) | mean abs ω err (rad/s) "
        "| end drift (% of dist.) | t err % (scaled segs) | r err (deg/m) | ATE (m) | ps | precision | IoU | AUC |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        out.append(f"| {r['name']} | {r['cpu_median']:.1f} | {r['cpu_p90']:.1f} | {r['cpu_mean']:.1f} "
                   f"| {r['ms_median']:.1f} | {r['ms_p90']:.1f} | {r['dv_mean']:.3f} "
                   f"| {r['v_bias']:+.3f} | {r['w_err']:.4f} | {r['drift']:.2f} | {r['t_err']:.2f} | {r['r_err']:.4f} "
                   f"| {r['ate']:.3f} | {r['ps']:.3f} | {r['precision']:.3f} | {r['iou']:.3f} | {r['auc']:.3f} |")
    out += ["", f"Min-of-{args.repeat}-passes CPU time per frame (median / p90 over frames, ms): "
            + "; ".join(f"{n} {m:.1f} / {p:.1f}" for n, m, p in
                        [(n,) + time_condition(seq, kw, args.repeat) for n, kw in
                         [("w6", CONDITIONS["w6"]), ("w6 nocal", CONDITIONS["w6 nocal"]), ("w2", CONDITIONS["w2"])]
                         + ([("w6 full-res", dict(model="6param", downsample=1))] if args.full_res else [])]) + "."]
    out += ["", "t err / r err use non-standard segment lengths L_j = j·L_max/8 (route shorter than 800 m, "
            "spec §8.1), start every frame. IoU: mean over the second half of the sequence (threshold 0.5); "
            "AUC: last 5 frames. ps/precision: RANSAC inliers vs the true ground mask at the candidates (§8.2)."]
    route_conditions = dict(CONDITIONS)
    route_conditions["w6 3d"] = dict(model="6param", sampling="weighted", integration="3d")
    for name in args.route:
        out += [""] + run_route(name, args.route_frames, route_conditions)
    text = "\n".join(out) + "\n"
    print(text)
    if args.write:
        with open(args.write, "w") as fh:
            fh.write(text)


if __name__ == "__main__":
    main()
