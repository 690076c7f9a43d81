"""Shared pieces of the tracking experiments (``tracking_variants``, ``tracking_segmentation``,
``tracking_ablation``, ``tracking_strips``); not an experiment (the underscore keeps it out of the
registry).

- Splits and sizes as data: ``dev`` is the 16 tabletop sequences at seed 0 (the ones every earlier
  result was tuned and recorded on) plus the 4 ``dev_appearance`` sequences of issue 13; ``test``
  is the held-out suite (:data:`polar_sim.sim.tabletop_sequences.TEST_SEQUENCES`) at seed 10,000.
  The quick size tracks 40-50-frame cuts of ``mug_touch`` and ``drill_lift`` at 320x240 (seed 0 on
  dev, 10,000 on test).
- :func:`track` runs a ``tracker`` plug-in (:mod:`polar_sim.runner.methods`) over a recording from
  the one cache (:func:`polar_sim.sim.tabletop_sequences.cached_sequence`) and scores every frame
  with :mod:`polar_sim.metrics`. Runs of built-in methods are memoised in the same cache (kind
  ``tracks``), keyed by the code of the tracker and the metrics, so the experiments that score the
  same runs (variants, segmentation, ablation) run each tracker once.
- :func:`summarize_run` reduces the per-frame arrays to one result row.
"""

from __future__ import annotations

import functools
import hashlib
import os
import time
from pathlib import Path

import numpy as np

from polar_sim import metrics
from polar_sim.sim.tabletop_sequences import SPLIT_SEEDS, cached_sequence, list_sequences

DEV = list_sequences("dev") + list_sequences("dev_appearance")
TEST = list_sequences("test")
SPLITS = {"dev": {"seeds": list(SPLIT_SEEDS["dev"]), "grid": {"sequence": DEV}},
          "test": {"seeds": list(SPLIT_SEEDS["test"]), "grid": {"sequence": TEST}}}
#: CI cuts (first frame, end frame) at 320x240: the palm coming down and resting on the mug, the
#: drill grasped and lifted (20-30 frames before the hand arrives, so the appearance is learned).
QUICK_CUTS = {"mug_touch": (80, 125), "drill_lift": (90, 140)}
QUICK_SIZE, FULL_SIZE = (320, 240), (640, 480)
SIZES = {"quick": {"n_seeds": 1, "grid": {"sequence": list(QUICK_CUTS)}}, "full": {}}
VARIANTS = ["h", "su", "sw", "wu", "ww"]
#: ICG (Stoiber et al., CVPR 2022): 1.3 ms per frame on one CPU core.
ICG_MS = 1.3
#: "Occlusion by touch": the hand touches or holds the target and hides more than 5 % of it.
TOUCH_OCCLUSION = 0.05
#: Hand pixels within this many pixels (at 640 wide) of the target's full silhouette are counted.
HAND_RADIUS_PX = 15
VSD_EVERY = 10
N_MODEL = 3000
N_BINS = 15
SCORING_VERSION = 2


def single_thread():
    """One thread for OpenCV and numpy's OpenBLAS: per-frame CPU time is single-threaded, and
    parallel trials do not oversubscribe the cores (the tracker's numba kernels are serial)."""
    import ctypes

    import cv2

    cv2.setNumThreads(1)
    try:
        with open("/proc/self/maps") as fh:
            libs = {ln.split()[-1] for ln in fh if "openblas" in ln.lower() and ln.strip().endswith(".so")}
    except OSError:  # pragma: no cover - not Linux
        libs = set()
    for path in libs:
        try:
            lib = ctypes.CDLL(path)
        except OSError:  # pragma: no cover
            continue
        for sym in ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
                    "openblas_set_num_threads64_", "openblas_set_num_threads"):
            if hasattr(lib, sym):
                getattr(lib, sym)(1)
                break


def load_now():
    try:
        return float(os.getloadavg()[0])
    except OSError:  # pragma: no cover
        return float("nan")


def model(obj, n=N_MODEL):
    """(n, 3) points and outward normals on object ``obj``'s mesh, object frame (seed 0)."""
    import trimesh

    from polar_sim.sim import objects

    mesh = objects.load_mesh(obj)
    P, face = trimesh.sample.sample_surface(mesh, n, seed=0)
    return np.asarray(P, float), np.asarray(mesh.face_normals[face], float)


def cut_of(name, quick):
    """(first frame, end frame, width, height) tracked for sequence ``name``."""
    from polar_sim.sim.tabletop_sequences import sequence_spec

    if quick:
        return (*QUICK_CUTS.get(name, (0, 40)), *QUICK_SIZE)
    return (0, sequence_spec(name).frames, *FULL_SIZE)


def recording(name, seed, quick):
    """The cached recording (a lazy reader) and the cut of ``name`` at the size."""
    start, end, w, h = cut_of(name, quick)
    return cached_sequence(name, seed, end if quick else None, width=w, height=h), start, end


@functools.lru_cache(maxsize=1)
def _source_hash():
    """Hash of the code that decides a memoised run's numbers: the tracker, the metrics it is scored
    with and the run loop below (a built-in method's configuration is part of the key). Computed
    once per process, so it describes the code the process imported."""
    import inspect

    import polar_sim

    root = Path(polar_sim.__file__).parent
    h = hashlib.sha1(f"{SCORING_VERSION}{inspect.getsource(_run)}{inspect.getsource(_bins)}".encode())
    files = [*(root / "tracking").glob("*.py"), *(root / "metrics" / f for f in ("pose.py", "segmentation.py",
                                                                                  "calibration.py"))]
    for p in sorted(files):
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


def _bins(prob, truth, valid):
    """Reliability sums per bin (3, N_BINS): count, sum of P, sum of truth (pooled ECE adds them)."""
    r = metrics.reliability(prob, truth, n_bins=N_BINS, valid=valid)
    return np.stack([r.count, r.count * np.nan_to_num(r.confidence), r.count * np.nan_to_num(r.frequency)])


def pooled_ece(bins):
    """ECE of reliability sums (..., 3, N_BINS) added over the leading axes."""
    b = np.asarray(bins).reshape(-1, 3, N_BINS).sum(axis=0)
    return float(np.abs(b[2] - b[1]).sum() / max(b[0].sum(), 1))


def track(name, seed, method, *, quick, on_frame=None, stop=None, tracker_kw=None):
    """Run tracker ``method`` over sequence ``name`` and score every frame: (arrays, meta)."""
    from polar_sim.runner.methods import get_method
    from polar_sim.sim import sequences

    rec, start, end = recording(name, seed, quick)
    end = end if stop is None else min(end, int(stop))
    memo = on_frame is None and tracker_kw is None and ":" not in method and os.environ.get("POLAR_SIM_TRACK_MEMO", "1") != "0"
    from polar_sim.runner.methods import TRACKERS

    key = {"recording": rec.path.name, "start": start, "end": end, "method": method,
           "config": TRACKERS.get(method, ({},))[0], "code": _source_hash()}

    def run():
        return _run(rec, start, end, get_method("tracker", method), tracker_kw or {}, on_frame)

    out = sequences.cached_arrays("tracks", key, run) if memo else run()
    meta = dict(object=rec.meta["object"], diameter=float(rec.meta["diameter"]), symmetry=rec.meta["symmetry"],
                width=int(rec.meta["width"]), start=start, end=end, load=float(out["load"]),
                appearance=(rec.meta.get("appearance") or {}).get("family", "default"))
    return out, meta


def _run(rec, start, end, factory, kw, on_frame):
    single_thread()
    K = np.array(rec.meta["K"], float)
    P, N = model(rec.meta["object"])
    d = float(rec.meta["diameter"])
    G = rec.stack("T_cam_obj").astype(float)
    ts = rec.stack("t")
    tr = factory(P, K, G[start], model_normals=N, random_state=0, **kw)
    r_hand = max(2, int(round(HAND_RADIUS_PX * rec.meta["width"] / 640)))
    n = end - start
    A = {k: np.zeros(n) for k in ("cpu_ms", "wall_ms", "roi_px", "target_px")}
    F = []
    E = np.empty((n, 4, 4))
    cal, raw, vsd, vsd_idx = np.zeros((n, 3, N_BINS)), np.zeros((n, 3, N_BINS)), [], []
    lost = np.zeros(n, bool)
    load = load_now()
    keys = ("rgb", "depth", "mask_visible", "mask_full", "mask_occluder")
    for i, fr in rec.frames(start, end, keys=keys):
        j = i - start
        c0, w0 = time.process_time(), time.perf_counter()
        r = tr.process(fr["rgb"], fr["depth"], float(ts[i]))
        A["cpu_ms"][j], A["wall_ms"][j] = 1000 * (time.process_time() - c0), 1000 * (time.perf_counter() - w0)
        E[j] = r.pose
        vis, full, hand = fr["mask_visible"], fr["mask_full"], fr["mask_occluder"]
        mask = getattr(r, "mask", None)
        mask = np.zeros_like(vis) if mask is None else mask
        F.append(metrics.mask_frame_scores(mask, vis, hand, within=metrics.near_mask(full, r_hand)))
        roi = np.ones_like(vis)
        if getattr(r, "roi", None) is not None:
            x0, y0, x1, y1 = r.roi
            roi = np.zeros_like(vis)
            roi[y0:y1, x0:x1] = True
        A["roi_px"][j], A["target_px"][j] = roi.sum(), full.sum()
        prob = getattr(r, "prob", None)
        if prob is not None and roi.any():
            cal[j] = _bins(prob, vis, roi)
            raw[j] = _bins(getattr(r, "prob_raw", None) if getattr(r, "prob_raw", None) is not None else prob, vis, roi)
        lost[j] = bool(getattr(r, "lost", False))
        if j % VSD_EVERY == 0 and vis.any():
            vsd.append(metrics.vsd(metrics.render_depth(P, K, r.pose, vis.shape), metrics.render_depth(P, K, G[i], vis.shape),
                                   np.nan_to_num(fr["depth"], posinf=0.0), K, d))
            vsd_idx.append(j)
        if on_frame is not None:
            on_frame(i, fr, r)
    out = {**A, **{k: np.array([f[k] for f in F]) for k in F[0]}, **metrics.pose_frame_errors(P, K, G[start:end], E)}
    out.update(pose=E, pose_gt=G[start:end], lost=lost, cal_bins=cal, raw_bins=raw, load=np.float64(load),
               in_contact=rec.stack("in_contact")[start:end].astype(bool), occlusion=rec.stack("occlusion")[start:end],
               vsd=np.array(vsd, float).reshape(len(vsd), -1), vsd_idx=np.array(vsd_idx, np.int64))
    return out


def _rate(x):
    x = np.asarray(x)
    return float(x.mean()) if x.size else float("nan")


def summarize_run(a, meta):
    """One result row from the per-frame arrays of :func:`track`."""
    d = meta["diameter"]
    e = a["adds"] if meta["symmetry"] != "none" else a["add"]   # ADD(-S): ADD-S for revolved objects
    touch = a["in_contact"] & (a["occlusion"] > TOUCH_OCCLUSION)
    cpu = a["cpu_ms"][1:] if len(a["cpu_ms"]) > 1 else a["cpu_ms"]   # first frame: JIT and caches
    hn, ht = a["hand_near"][a["in_contact"]].sum(), a["hand_near_tgt"][a["in_contact"]].sum()
    drift = metrics.static_rotation_drift(a["pose_gt"], a["pose"])
    return {
        "object": meta["object"], "appearance": meta["appearance"], "diameter_cm": round(100 * d, 2),
        "symmetry": meta["symmetry"], "frames": int(len(e)),
        "add_ok": _rate(e < 0.1 * d), "add_strict_ok": _rate(a["add"] < 0.1 * d),
        "add_mean_mm": float(1000 * np.mean(e)), "add_auc": float(metrics.pose_auc(e, 0.1)),
        "s5cm5deg": _rate((a["trans"] < 0.05) & (a["rot"] < np.deg2rad(5.0))),
        "iou_ok": _rate(a["iou"] > 0.5), "iou_mean": float(np.mean(a["iou"])),
        "iou_auc": float(metrics.iou_success_curve(a["iou"])[2]),
        "precision": float(a["n_tp"].sum() / a["n_pred"].sum()) if a["n_pred"].sum() else 1.0,
        "recall": float(a["n_tp"].sum() / a["n_gt"].sum()) if a["n_gt"].sum() else 1.0,
        "touch_frames": int(a["in_contact"].sum()), "hand_px_touch": int(hn), "hand_tgt_px_touch": int(ht),
        "hand_as_target": float(ht / hn) if hn else float("nan"),
        "occl_frames": int(touch.sum()), "occl_add_ok": _rate((e < 0.1 * d)[touch]),
        "occl_iou_ok": _rate((a["iou"] > 0.5)[touch]), "occlusion_max": float(a["occlusion"].max()),
        "ece": pooled_ece(a["cal_bins"]), "ece_raw": pooled_ece(a["raw_bins"]),
        "static_frames": int(drift.frames.sum()), "drift_deg": float(np.rad2deg(drift.max_drift)),
        "lost": int(a["lost"].sum()), "first_loss": int(metrics.frames_until_loss(e, 0.3 * d)),
        "ar_mssd": float(metrics.ar_mssd(a["mssd"], d)), "ar_mspd": float(metrics.ar_mspd(a["mspd"], meta["width"])),
        "ar_vsd": float(metrics.ar_vsd(a["vsd"])) if len(a["vsd"]) else float("nan"),
        "cpu_ms_median": float(np.median(cpu)), "cpu_ms_p95": float(np.percentile(cpu, 95)),
        "fps_cpu": float(1000.0 / np.median(cpu)), "roi_px": float(np.mean(a["roi_px"])),
        "width": int(meta["width"]), "load": float(meta["load"]),
    }


def trial_arrays(ctx, a, meta):
    """The per-frame arrays a summary needs, saved with the trial (``ctx.save_arrays``)."""
    d = meta["diameter"]
    e = a["adds"] if meta["symmetry"] != "none" else a["add"]
    ctx.save_arrays(err_d=e / d, iou=a["iou"], cpu_ms=a["cpu_ms"], roi_px=a["roi_px"], target_px=a["target_px"],
                    cal_bins=a["cal_bins"], raw_bins=a["raw_bins"], in_contact=a["in_contact"],
                    occlusion=a["occlusion"])


def spearman(x, y):
    """Spearman rank correlation (NaN for fewer than 3 values or a constant input)."""
    from scipy.stats import spearmanr

    if len(x) < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:   # undefined for constant inputs
        return float("nan")
    return float(spearmanr(x, y).statistic)


def cost_vs_size(table, ctx, method):
    """CPU ms per frame of ``method`` (all frames of the table) against the object's and the ROI's pixels."""
    cpu, roi, tgt = [], [], []
    for r in by(table, "method", method):
        z = ctx.arrays(r)
        cpu.append(z["cpu_ms"][1:]), roi.append(z["roi_px"][1:]), tgt.append(z["target_px"][1:])
    cpu, roi, tgt = map(np.concatenate, (cpu, roi, tgt))
    slope, icpt = np.polyfit(tgt / 1e4, cpu, 1) if np.ptp(tgt) > 0 else (float("nan"), float(np.median(cpu)))
    return dict(frames=len(cpu), rho_target=spearman(tgt, cpu), rho_roi=spearman(roi, cpu), slope=slope, icpt=icpt,
                q=np.percentile(cpu, [50, 95]), cpu=cpu, tgt=tgt)


def by(table, key, value):
    return [r for r in table if r[key] == value]


def pooled(rows, num, den="frames"):
    """Frame-weighted mean of a per-run rate over rows (the rate over all frames pooled)."""
    w = np.array([r[den] for r in rows], float)
    v = np.array([r[num] for r in rows], float)
    ok = np.isfinite(v) & (w > 0)
    return float((v[ok] * w[ok]).sum() / w[ok].sum()) if ok.any() else float("nan")


def group(table, split):
    """The rows headline figures pool: on dev the 16 sequences every earlier result used."""
    return [r for r in table if r["sequence"] in list_sequences("dev")] if split == "dev" else table


def rate_rows(table, key, order):
    """One row per value of ``key`` (in ``order``): pooled and per-sequence rates."""
    rows = []
    for v in order:
        rs = by(table, key, v)
        if not rs:
            continue
        hn = sum(r["hand_px_touch"] for r in rs)
        rows.append({
            key: v, "sequences": len(rs), "frames": int(sum(r["frames"] for r in rs)),
            "add_ok": pooled(rs, "add_ok"), "add_ok_seqmin": float(np.min([r["add_ok"] for r in rs])),
            "add_strict_ok": pooled(rs, "add_strict_ok"), "add_auc": pooled(rs, "add_auc"),
            "s5cm5deg": pooled(rs, "s5cm5deg"), "iou_ok": pooled(rs, "iou_ok"), "iou_mean": pooled(rs, "iou_mean"),
            "hand_as_target": sum(r["hand_tgt_px_touch"] for r in rs) / hn if hn else float("nan"),
            "occl_frames": int(sum(r["occl_frames"] for r in rs)),
            "occl_add_ok": pooled(rs, "occl_add_ok", "occl_frames"), "occl_iou_ok": pooled(rs, "occl_iou_ok", "occl_frames"),
            "drift_deg_max": float(np.nanmax([np.nan if r["drift_deg"] is None else r["drift_deg"] for r in rs] + [np.nan])), "lost": int(sum(r["lost"] for r in rs)),
            "cpu_ms_median": float(np.median([r["cpu_ms_median"] for r in rs])),
        })
    return rows
