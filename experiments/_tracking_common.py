"""Shared pieces of the tracking experiments (``tracking_variants``, ``tracking_segmentation``,
``tracking_ablation``, ``tracking_strips``); not an experiment (the underscore keeps it out of the
registry).

- Splits and sizes as data: ``dev`` is the 16 tabletop sequences at seed 0 (the ones every earlier
  result was tuned and recorded on) plus the 4 ``dev_appearance`` sequences; ``test`` is the
  held-out suite (:data:`polar_sim.sim.tabletop_sequences.TEST_SEQUENCES`) at seed 10,000. The
  protocol's params (:data:`PARAMS`): ``span`` "all" tracks every frame of a sequence, "ci" its
  CI cut (:data:`CI_CUTS`); ``width`` x ``height`` is the image size. The quick size tracks the
  40-50-frame CI cuts of ``mug_touch`` and ``drill_lift`` at 320x240 (seed 0 on dev, 10,000 on test).
- :func:`track` runs a ``tracker`` plug-in (:mod:`polar_sim.runner.methods`) over a recording from
  the one cache (:func:`polar_sim.sim.tabletop_sequences.cached_sequence`) and scores every frame
  with :mod:`polar_sim.metrics`. Runs of built-in methods are memoised in the same cache (kind
  ``tracks``), keyed by the code of the tracker and the metrics, so the experiments that score the
  same runs (variants, segmentation, ablation) run each tracker once.
- :func:`summarize_run` reduces the per-frame arrays to one result row with :mod:`polar_sim.metrics`.
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
#: The values the ``sequence`` axis accepts (``--set sequence=[...]``): every dev and test sequence.
CHOICES = {"sequence": functools.partial(list_sequences, "all")}
#: CI cuts (first frame, end frame): the palm coming down and resting on the mug, the drill grasped
#: and lifted (20-30 frames before the hand arrives, so the appearance is learned); other
#: sequences are cut to their first 40 frames.
CI_CUTS = {"mug_touch": (80, 125), "drill_lift": (90, 140)}
#: The protocol at the full size (``--set span=ci`` etc. overrides a run's).
PARAMS = {"span": "all", "width": 640, "height": 480}
QUICK_PARAMS = {"span": "ci", "width": 320, "height": 240}
SIZES = {"quick": {"n_seeds": 1, "grid": {"sequence": list(CI_CUTS)}, "params": QUICK_PARAMS}, "full": {}}
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


def cut_of(name, params):
    """(first frame, end frame, width, height) tracked for sequence ``name`` under the run's
    ``params`` (:data:`PARAMS`)."""
    from polar_sim.sim.tabletop_sequences import sequence_spec

    span = params["span"]
    if span not in ("all", "ci"):
        raise ValueError(f"span: expected 'all' (every frame) or 'ci' (the CI cut), got {span!r}")
    start, end = CI_CUTS.get(name, (0, 40)) if span == "ci" else (0, sequence_spec(name).frames)
    return start, end, int(params["width"]), int(params["height"])


def recording(name, seed, params):
    """The cached recording (a lazy reader, recorded up to the cut's end) and the cut of ``name``."""
    start, end, w, h = cut_of(name, params)
    return cached_sequence(name, seed, end, width=w, height=h), start, end


@functools.lru_cache(maxsize=1)
def _source_hash():
    """Hash of the code that decides a memoised run's numbers: the tracker, the metrics it is scored
    with and the run loop below (a built-in method's configuration is part of the key). Computed
    once per process, so it describes the code the process imported."""
    import inspect

    import polar_sim

    root = Path(polar_sim.__file__).parent
    code = inspect.getsource(_run) + inspect.getsource(metrics.reliability_counts)
    h = hashlib.sha1(f"{SCORING_VERSION}{code}".encode())
    files = [*(root / "tracking").glob("*.py"), *(root / "metrics" / f for f in ("pose.py", "segmentation.py",
                                                                                  "calibration.py"))]
    for p in sorted(files):
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


def _bins(prob, truth, valid):
    """Reliability counts (3, N_BINS) of one frame: count, sum of P, sum of truth per bin."""
    return np.stack(metrics.reliability_counts(prob, truth, n_bins=N_BINS, valid=valid))


def ece(bins):
    """Expected calibration error of reliability counts (..., 3, N_BINS) added over the leading
    axes (frames, runs); NaN without any pixel (no P(target) map)."""
    c, p, y = np.asarray(bins, dtype=np.float64).reshape(-1, 3, N_BINS).sum(axis=0)
    return metrics.pooled_reliability(c, p, y).ece if c.sum() else float("nan")


def track(name, seed, method, *, params, on_frame=None, stop=None, tracker_kw=None):
    """Run tracker ``method`` over the cut of sequence ``name`` (``params``: :data:`PARAMS`) and
    score every frame: (arrays, meta)."""
    from polar_sim.runner.methods import get_method
    from polar_sim.sim import sequences

    rec, start, end = recording(name, seed, params)
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


def trial(params, seed, ctx):
    """The trial of ``tracking_variants``, ``_segmentation`` and ``_ablation``: track the sequence
    with the method, save the per-frame arrays, return one row."""
    a, meta = track(params["sequence"], seed, params["method"], params=ctx.params)
    trial_arrays(ctx, a, meta)
    return summarize_run(a, meta)


def summarize_run(a, meta):
    """One result row from the per-frame arrays of :func:`track`."""
    d, iou = meta["diameter"], a["iou"]
    e = a["adds"] if meta["symmetry"] != "none" else a["add"]   # ADD(-S): ADD-S for revolved objects
    touch = a["in_contact"] & (a["occlusion"] > TOUCH_OCCLUSION)
    cpu = a["cpu_ms"][1:] if len(a["cpu_ms"]) > 1 else a["cpu_ms"]   # first frame: JIT and caches
    hn, ht = a["hand_near"][a["in_contact"]].sum(), a["hand_near_tgt"][a["in_contact"]].sum()
    precision, recall = metrics.pooled_precision_recall(a["n_tp"], a["n_pred"], a["n_gt"])
    drift = metrics.static_rotation_drift(a["pose_gt"], a["pose"])
    return {
        "object": meta["object"], "appearance": meta["appearance"], "diameter_cm": round(100 * d, 2),
        "symmetry": meta["symmetry"], "frames": int(len(e)),
        "add_ok": metrics.add_success_rate(e, d), "add_strict_ok": metrics.add_success_rate(a["add"], d),
        "add_mean_mm": float(1000 * np.mean(e)), "add_auc": float(metrics.pose_auc(e, 0.1)),
        "s5cm5deg": metrics.success_5cm5deg_rate(a["rot"], a["trans"]),
        "iou_ok": metrics.iou_success_rate(iou), "iou_mean": float(np.mean(iou)),
        "iou_auc": float(metrics.iou_success_curve(iou)[2]), "precision": precision, "recall": recall,
        "touch_frames": int(a["in_contact"].sum()), "hand_px_touch": int(hn), "hand_tgt_px_touch": int(ht),
        "hand_as_target": metrics.pooled_occluder_as_target(a["hand_near"], a["hand_near_tgt"], where=a["in_contact"]),
        "occl_frames": int(touch.sum()), "occl_add_ok": metrics.add_success_rate(e, d, where=touch),
        "occl_iou_ok": metrics.iou_success_rate(iou, where=touch), "occlusion_max": float(a["occlusion"].max()),
        "ece": ece(a["cal_bins"]), "ece_raw": ece(a["raw_bins"]),
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


def cost_vs_size(table, ctx, method):
    """CPU ms per frame of ``method`` (all frames of the table) against the object's and the ROI's pixels."""
    cpu, roi, tgt = [], [], []
    for r in by(table, "method", method):
        z = ctx.arrays(r)
        cpu.append(z["cpu_ms"][1:]), roi.append(z["roi_px"][1:]), tgt.append(z["target_px"][1:])
    cpu, roi, tgt = map(np.concatenate, (cpu, roi, tgt))
    slope, icpt = np.polyfit(tgt / 1e4, cpu, 1) if np.ptp(tgt) > 0 else (float("nan"), float(np.median(cpu)))
    return dict(frames=len(cpu), rho_target=metrics.spearman(tgt, cpu), rho_roi=metrics.spearman(roi, cpu),
                slope=slope, icpt=icpt, q=np.percentile(cpu, [50, 95]), cpu=cpu, tgt=tgt)


def by(table, key, value):
    return [r for r in table if r[key] == value]


def col(rows, key):
    """Column ``key`` of result rows as floats (an empty cell, None, as NaN)."""
    return np.array([np.nan if r[key] is None else r[key] for r in rows], float)


def pooled(rows, num, den="frames"):
    """A per-run rate pooled over rows, weighted by their frames (the rate over all frames)."""
    return metrics.pooled_rate(col(rows, num), col(rows, den))


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
        rows.append({
            key: v, "sequences": len(rs), "frames": int(sum(r["frames"] for r in rs)),
            "add_ok": pooled(rs, "add_ok"), "add_ok_seqmin": float(np.min([r["add_ok"] for r in rs])),
            "add_strict_ok": pooled(rs, "add_strict_ok"), "add_auc": pooled(rs, "add_auc"),
            "s5cm5deg": pooled(rs, "s5cm5deg"), "iou_ok": pooled(rs, "iou_ok"), "iou_mean": pooled(rs, "iou_mean"),
            "hand_as_target": metrics.pooled_occluder_as_target([r["hand_px_touch"] for r in rs],
                                                                [r["hand_tgt_px_touch"] for r in rs]),
            "occl_frames": int(sum(r["occl_frames"] for r in rs)),
            "occl_add_ok": pooled(rs, "occl_add_ok", "occl_frames"), "occl_iou_ok": pooled(rs, "occl_iou_ok", "occl_frames"),
            "drift_deg_max": float(np.nanmax([*col(rs, "drift_deg"), np.nan])), "lost": int(sum(r["lost"] for r in rs)),
            "cpu_ms_median": float(np.median([r["cpu_ms_median"] for r in rs])),
        })
    return rows
