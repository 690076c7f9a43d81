"""Shared pieces of the tracking experiments (variants, segmentation, ablation, strips): splits,
sizes, recordings and the tracker run. Not an experiment (the underscore keeps it out of the
registry); the result rows and pooled tables are in ``_tracking_tables``.

- Splits and sizes as data: ``dev`` is the 16 tabletop sequences at seed 0 (every earlier result was
  tuned on them) plus the 4 ``dev_appearance`` ones; ``test`` the held-out suite at seed 10,000.
  :data:`PARAMS`: ``span`` "all" tracks every frame, "ci" the CI cut (:data:`CI_CUTS`), at
  ``width`` x ``height``. The quick size tracks the CI cuts of ``mug_touch`` and ``drill_lift`` at 320x240.
- :func:`track` runs a ``tracker`` plug-in (:mod:`polar_sim.runner.methods`) over a recording from
  the one cache and scores every frame with :mod:`polar_sim.metrics`. Runs of built-in methods are
  memoised in the same cache (kind ``tracks``), keyed by the code of the tracker and the metrics,
  so the experiments that score the same runs run each tracker once.
"""

from __future__ import annotations

import functools
import hashlib
import os
import time
from pathlib import Path

import numpy as np

from polar_sim import metrics
from polar_sim.sim.recorders.tabletop_sequences import SPLIT_SEEDS, cached_sequence, list_sequences

from polar_sim.experiments._tracking_tables import summarize_run

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
#: Hand pixels within this many pixels (at 640 wide) of the target's full silhouette are counted.
HAND_RADIUS_PX = 15
VSD_EVERY = 10
N_MODEL = 3000
N_BINS = 15
SCORING_VERSION = 2


def single_thread():
    """One thread for OpenCV and numpy's BLAS: per-frame CPU time is single-threaded, and parallel
    trials do not oversubscribe the cores (the tracker's numba kernels are serial)."""
    import cv2
    from threadpoolctl import threadpool_limits

    cv2.setNumThreads(1)
    threadpool_limits(limits=1, user_api="blas")


def model(obj, n=N_MODEL):
    """(n, 3) points and outward normals on object ``obj``'s mesh, object frame (seed 0)."""
    import trimesh

    from polar_sim.sim.builders import objects

    mesh = objects.load_mesh(obj)
    P, face = trimesh.sample.sample_surface(mesh, n, seed=0)
    return np.asarray(P, float), np.asarray(mesh.face_normals[face], float)


def cut_of(name, params):
    """(first frame, end frame, width, height) tracked for sequence ``name`` under the run's
    ``params`` (:data:`PARAMS`)."""
    from polar_sim.sim.recorders.tabletop_sequences import sequence_spec

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


def track(name, seed, method, *, params, on_frame=None, stop=None, tracker_kw=None):
    """Run tracker ``method`` over the cut of sequence ``name`` (``params``: :data:`PARAMS`) and
    score every frame: (arrays, meta)."""
    from polar_sim.runner.methods import get_method
    from polar_sim.sim.recorders import sequences

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
    load = os.getloadavg()[0]
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
        if prob is not None and roi.any():   # reliability counts (3, N_BINS): count, sum of P, sum of truth per bin
            prob_raw = getattr(r, "prob_raw", None)
            for out, p in ((cal, prob), (raw, prob if prob_raw is None else prob_raw)):
                out[j] = np.stack(metrics.reliability_counts(p, vis, n_bins=N_BINS, valid=roi))
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
    d = meta["diameter"]
    e = a["adds"] if meta["symmetry"] != "none" else a["add"]
    ctx.save_arrays(err_d=e / d, iou=a["iou"], cpu_ms=a["cpu_ms"], roi_px=a["roi_px"], target_px=a["target_px"],
                    cal_bins=a["cal_bins"], raw_bins=a["raw_bins"], in_contact=a["in_contact"],
                    occlusion=a["occlusion"])
    return summarize_run(a, meta)
