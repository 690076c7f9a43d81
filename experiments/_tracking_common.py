"""Shared pieces of the tracking-chapter experiments (``tracking_variants``, ``tracking_segmentation``,
``tracking_ablation``, ``tracking_strips``); not an experiment itself (the leading underscore keeps it
out of the registry).

- :func:`recording_path` records a ``tabletop`` sequence once into the cache
  (``$POLAR_SIM_CACHE/tabletop``, default ``~/.cache/polar_sim/tabletop``) through
  :func:`polar_sim.sim.tabletop_sequences.record_sequence`, under a file lock so that parallel workers
  record it once; :class:`FrameStream` then reads it back frame by frame (a 600-frame 640x480
  recording is 2.5 GB decoded, so it is never held whole in memory).
- :func:`model` is the tracker's model: 3000 points and normals sampled on the object's true mesh
  (the same points as ``World.object_points(name, 3000)``).
- :func:`track` runs :class:`polar_sim.tracking.ObjectTracker` over a sequence and scores every frame
  against the truth (ADD, ADD-S, 5 cm / 5 deg, BOP errors, IoU, hand pixels labelled target, CPU
  time). Its per-frame arrays are memoised on disk under a key that includes a hash of the tracker's
  and the metrics' source, so the experiments that score the same runs (variants, segmentation,
  ablation) run each tracker once; any change to the tracker invalidates the memo.
- :func:`summarize_run` reduces the per-frame arrays to the flat metrics of a result row.

The CI size (``--quick``) tracks 40-frame cuts of two sequences at 320x240, chosen where the hand
touches and hides the object (:data:`QUICK_CUTS`).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["VARIANTS", "ABLATIONS", "SEQUENCE_ORDER", "QUICK_CUTS", "ICG_MS", "cache_dir", "recording_path",
           "FrameStream", "model", "track", "summarize_run", "single_thread", "load_now", "sequence_info",
           "cut_of", "pooled", "TOUCH_OCCLUSION", "save_frames", "load_frames", "rate_rows", "best_of", "by"]

#: The appearance variants of the chapter (spec 4): the colour baseline and the S/W x u/w heads.
VARIANTS = {
    "h": dict(appearance="h"),
    "su": dict(appearance="su"),
    "sw": dict(appearance="sw"),
    "wu": dict(appearance="wu"),
    "ww": dict(appearance="ww"),
}
#: The ablations of spec 7.4 (the full method's other settings stay at their defaults).
ABLATIONS = {
    "shape-only": dict(appearance="none"),                          # appearance term off (gamma = 0)
    "no-motion": dict(motion="none"),                               # motion prior off (last pose)
    "no-spatial-prior": dict(spatial_prior=False),                  # pi = 0.5 in the ROI
    "alpha-beta": dict(motion="alpha-beta"),                        # the spec's fallback filter
    "plain-icp": dict(appearance="none", registration="plain"),     # robust ICP on every ROI point
}
#: The full method that the ablations switch parts of (its appearance variant).
BASE = "ww"
CONFIGS = {**VARIANTS, **{k: dict(VARIANTS[BASE], **v) for k, v in ABLATIONS.items()}}

SEQUENCE_ORDER = ("mug_touch", "can_push", "box_push", "bottle_lift", "drill_lift", "mug_turn", "box_turn",
                  "bracket_turn", "can_fast", "drill_fast", "bottle_light", "box_pass", "cube_push",
                  "skin_box_lift", "mug_demo_sway", "drill_orbit")

#: CI cuts (first frame, end frame) at 320x240: the palm coming down and resting on the mug, the
#: drill grasped and lifted. The recording runs from frame 0 to the end frame (the physics and the
#: script need it). Each cut starts 20-30 frames before the hand arrives: a tracker started with
#: the hand already on the object has had no frame to learn the object's appearance (started at
#: frame 100 of mug_touch, every variant relocks onto the palm).
QUICK_CUTS = {"mug_touch": (80, 125), "drill_lift": (90, 140)}
QUICK_SIZE = (320, 240)
FULL_SIZE = (640, 480)

#: ICG (Stoiber et al., CVPR 2022): 1.3 ms per frame on one CPU core.
ICG_MS = 1.3
#: "Occlusion by touch": a frame where the hand touches or holds the target and hides part of it.
TOUCH_OCCLUSION = 0.05
#: Hand pixels counted for "hand labelled target": within this many pixels (at 640 wide) of the
#: target's full silhouette, i.e. the hand pixels that touch or cover the object.
HAND_RADIUS_PX = 15
#: VSD is computed on every this-many frames (two renders per frame).
VSD_EVERY = 10
N_MODEL = 3000
#: Bump when the scoring in :func:`track` changes (part of the memo key).
SCORING_VERSION = 1


def load_now():
    """1-minute load average (context for every timing)."""
    try:
        return float(os.getloadavg()[0])
    except OSError:  # pragma: no cover
        return float("nan")


def single_thread():
    """One thread for OpenCV and for numpy's OpenBLAS: the per-frame CPU time is single-threaded,
    and parallel trials do not oversubscribe the cores. (numba kernels of the tracker are serial.)"""
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


def cache_dir():
    """Where tabletop recordings and memoised tracker runs live: ``$POLAR_SIM_CACHE/tabletop``."""
    root = Path(os.environ.get("POLAR_SIM_CACHE", Path.home() / ".cache" / "polar_sim")).expanduser()
    return root / "tabletop"


class _Lock:
    """Advisory file lock (``fcntl.flock``): parallel workers that need the same missing recording
    wait for one recorder. Without ``fcntl`` it is a no-op."""

    def __init__(self, path):
        self.path = Path(path)

    def __enter__(self):
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fh = open(self.path, "w")
        try:
            import fcntl

            fcntl.flock(self.fh, fcntl.LOCK_EX)
        except ImportError:  # pragma: no cover
            pass
        return self

    def __exit__(self, *exc):
        self.fh.close()


def cut_of(name, quick):
    """(first frame, end frame, width, height) tracked for sequence ``name`` at the chosen size."""
    from polar_sim.sim.tabletop_sequences import sequence_spec

    if quick:
        if name in QUICK_CUTS:
            a, b = QUICK_CUTS[name]
        else:
            a, b = 0, 40
        return a, b, *QUICK_SIZE
    return 0, sequence_spec(name).frames, *FULL_SIZE


def recording_path(name, seed, n_frames, width, height):
    """Path of the cached recording (recorded now if missing; deterministic in name and seed)."""
    from polar_sim.sim.tabletop_sequences import _cache_name, sequence_spec

    n = sequence_spec(name).frames if n_frames is None else int(n_frames)
    d = cache_dir()
    path = d / _cache_name(name, seed, n, width, height, True)
    if path.is_file():
        return path
    with _Lock(d / f".{path.stem}.lock"):
        if not path.is_file():
            os.environ.setdefault("MUJOCO_GL", "egl")
            from polar_sim.sim.tabletop_sequences import record_sequence

            rec = record_sequence(name, seed=seed, n_frames=n, cache_dir=d, width=width, height=height)
            del rec
    return path


class FrameStream:
    """Frame-by-frame reader of a saved :class:`~polar_sim.sim.recording.Recording` (format 1).

    The recording stores images as PNG blobs and other per-frame arrays stacked; this reads the
    small per-frame values whole (``self.values[key]``, (n, ...)) and streams the images of frames
    ``start`` to ``stop`` in order, one frame in memory at a time.
    """

    IMAGES = ("rgb", "depth", "depth_clean", "mask_visible", "mask_full", "mask_occluder")

    def __init__(self, path, keys=("rgb", "depth", "mask_visible", "mask_full", "mask_occluder")):
        self.path = Path(path)
        self.keys = tuple(keys)
        with zipfile.ZipFile(self.path) as z:
            with z.open("header.npy") as fh:
                header = json.loads(bytes(np.lib.format.read_array(fh)).decode())
            if header.get("format") != "polar_sim.recording" or header.get("version") != 1:
                raise ValueError(f"path: {self.path} is not a polar_sim recording of format version 1")
            self.meta = header["meta"]
            self.n = int(header["n"])
            self.info = header["keys"]
            self.values = {}
            for k, inf in self.info.items():
                if k in self.IMAGES:
                    continue
                with z.open(f"raw/{k}.npy") as fh:
                    self.values[k] = np.lib.format.read_array(fh)

    def __len__(self):
        return self.n

    def frames(self, start=0, stop=None):
        """Yield ``(index, dict of the images in self.keys)`` for frames start..stop-1."""
        stop = self.n if stop is None else min(int(stop), self.n)
        with zipfile.ZipFile(self.path) as z:
            readers = {k: self._reader(z, k) for k in self.keys}
            try:
                for i in range(stop):
                    out = {k: r(i) for k, r in readers.items()}
                    if i >= start:
                        yield i, out
            finally:
                for r in readers.values():
                    r.close()

    def _reader(self, z, key):
        import cv2

        inf = self.info[key]
        shape, dtype = tuple(inf["shape"]), np.dtype(inf["dtype"])
        if inf["storage"] == "png":
            with z.open(f"png_offsets/{key}.npy") as fh:
                off = np.lib.format.read_array(fh)
            fh = z.open(f"png/{key}.npy")
            _npy_header(fh)

            def read(i):
                buf = np.frombuffer(fh.read(int(off[i + 1] - off[i])), np.uint8)
                img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
                if img.ndim == 3 and img.shape[2] == 3:
                    img = img[..., ::-1]
                return np.ascontiguousarray(img.reshape(shape).astype(dtype, copy=False))
        else:
            fh = z.open(f"raw/{key}.npy")
            full_shape, fortran, file_dtype = _npy_header(fh)
            if fortran or full_shape[1:] != shape:
                raise ValueError(f"path: {self.path}: unexpected layout of {key!r}")
            nbytes = int(np.prod(shape)) * file_dtype.itemsize

            def read(i):
                return np.frombuffer(fh.read(nbytes), file_dtype).reshape(shape).astype(dtype)

        read.close = fh.close
        return read


def _npy_header(fh):
    """Read the ``.npy`` header of an open stream: (shape, fortran_order, dtype)."""
    version = np.lib.format.read_magic(fh)
    if version == (1, 0):
        return np.lib.format.read_array_header_1_0(fh)
    return np.lib.format.read_array_header_2_0(fh)


_MODEL_MEMO = {}


def model(obj, n=N_MODEL):
    """(n, 3) points and (n, 3) outward normals on object ``obj``'s true mesh, object frame, metres
    (``trimesh.sample.sample_surface`` with seed 0, as ``World.object_points``)."""
    if (obj, n) not in _MODEL_MEMO:
        import trimesh

        from polar_sim.sim import objects

        mesh = objects.load_mesh(obj)
        P, face = trimesh.sample.sample_surface(mesh, n, seed=0)
        _MODEL_MEMO[(obj, n)] = (np.asarray(P, float), np.asarray(mesh.face_normals[face], float))
    return _MODEL_MEMO[(obj, n)]


def sequence_info(name):
    """Object, its diameter (m), symmetry and the sequence's script and length (no recording needed)."""
    from polar_sim.sim import objects
    from polar_sim.sim.tabletop_sequences import SEQUENCES

    s = SEQUENCES[name]
    obj = s.options.get("target") or s.options.get("object")
    info = objects.object_info(obj)
    return dict(object=obj, diameter=objects.diameter(objects.load_mesh(obj)), symmetry=info.symmetry,
                script=s.options.get("script", s.scene), frames=s.frames)


def _source_hash():
    """Hash of the code that decides a memoised run's numbers: the tracker, the metrics, this file."""
    import polar_sim

    root = Path(polar_sim.__file__).parent
    h = hashlib.sha1()
    for p in sorted(list((root / "tracking").glob("*.py")) + list((root / "metrics").glob("*.py"))):
        h.update(p.name.encode())
        h.update(p.read_bytes())
    h.update(str(SCORING_VERSION).encode())
    return h.hexdigest()[:16]


_DILATE = {}


def _dilate(mask, r):
    import cv2

    if r not in _DILATE:
        _DILATE[r] = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    return cv2.dilate(mask.astype(np.uint8), _DILATE[r]) > 0


def track(name, seed, config, *, quick, memo=True, on_frame=None, stop=None, tracker_kw=None):
    """Run one tracker configuration over sequence ``name`` (seed ``seed``) and score every frame.

    ``config`` is a key of :data:`CONFIGS`. Returns ``(arrays, meta)``: per-frame arrays (see the
    code: errors in metres, pixel counts, flags, CPU and wall ms) and the sequence's meta plus the
    load average and the frame size. ``on_frame(i, frame, result)`` (optional) sees every frame and
    result (used by the picture strips; it disables the memo, as do ``stop`` and ``tracker_kw``).
    """
    from polar_sim import metrics
    from polar_sim.tracking import ObjectTracker

    start, end, width, height = cut_of(name, quick)
    path = recording_path(name, seed, end if quick else None, width, height)
    if stop is not None:
        end = min(end, int(stop))
    kw = dict(CONFIGS[config], **(tracker_kw or {}))
    key = hashlib.sha1(json.dumps([path.name, start, end, kw, _source_hash()], sort_keys=True).encode()).hexdigest()[:20]
    memo_path = cache_dir() / "tracks" / f"{name}_s{seed}_{config}_{width}x{height}_{start}-{end}_{key}.npz"
    use_memo = memo and on_frame is None and tracker_kw is None and os.environ.get("POLAR_SIM_TRACK_MEMO", "1") != "0"
    if use_memo and memo_path.is_file():
        with np.load(memo_path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files if k != "meta"}
            meta = json.loads(bytes(z["meta"]).decode())
        return arrays, meta

    single_thread()
    stream = FrameStream(path)
    K = np.array(stream.meta["K"], float)
    obj = stream.meta["object"]
    P, N = model(obj)
    d = float(stream.meta["diameter"])
    symmetric = stream.meta["symmetry"] != "none"
    G = stream.values["T_cam_obj"].astype(float)
    r_hand = max(2, int(round(HAND_RADIUS_PX * width / 640)))
    tr = ObjectTracker(P, K, G[start], model_normals=N, **kw)
    n = end - start
    A = {k: np.full(n, np.nan) for k in ("iou", "cpu_ms", "wall_ms", "fitness", "gamma")}
    I = {k: np.zeros(n, np.int64) for k in ("n_pred", "n_gt", "n_tp", "hand_near", "hand_near_tgt",
                                           "hand_all", "hand_all_tgt", "roi_px", "n_points")}
    B = {k: np.zeros(n, bool) for k in ("lost", "accepted")}
    E = np.empty((n, 4, 4))
    vsd_rows, vsd_idx = [], []
    from scipy.spatial import cKDTree

    spacing = 2.0 * float(np.mean(cKDTree(P).query(P, k=2)[0][:, 1]))  # as metrics.render_depth's default

    def splat(T, shape):
        z = float(np.median(P @ T[2, :3] + T[2, 3]))
        r_px = max(1, int(np.ceil(K[0, 0] * spacing / (2.0 * z)))) if z > 0 else 1
        return metrics.render_depth(P, K, T, shape, radius_px=r_px)

    load0 = load_now()
    for i, fr in stream.frames(start, end):
        j = i - start
        c0, w0 = time.process_time(), time.perf_counter()
        r = tr.process(fr["rgb"], fr["depth"], t=float(stream.values["t"][i]))
        A["cpu_ms"][j] = 1000 * (time.process_time() - c0)
        A["wall_ms"][j] = 1000 * (time.perf_counter() - w0)
        E[j] = r.pose
        vis, full, hand = fr["mask_visible"], fr["mask_full"], fr["mask_occluder"]
        A["iou"][j] = metrics.iou(r.mask, vis)
        I["n_pred"][j], I["n_gt"][j] = int(r.mask.sum()), int(vis.sum())
        I["n_tp"][j] = int(np.logical_and(r.mask, vis).sum())
        near = hand & _dilate(full, r_hand) if full.any() else np.zeros_like(hand)
        I["hand_near"][j], I["hand_near_tgt"][j] = int(near.sum()), int(np.logical_and(r.mask, near).sum())
        I["hand_all"][j], I["hand_all_tgt"][j] = int(hand.sum()), int(np.logical_and(r.mask, hand).sum())
        x0, y0, x1, y1 = r.roi
        I["roi_px"][j] = max(0, x1 - x0) * max(0, y1 - y0)
        I["n_points"][j] = r.n_points
        A["fitness"][j], A["gamma"][j] = r.fitness, r.gamma
        B["lost"][j], B["accepted"][j] = r.lost, r.accepted
        if j % VSD_EVERY == 0 and vis.any():
            vsd_rows.append(metrics.vsd(splat(r.pose, vis.shape), splat(G[i], vis.shape), fr["depth"], K, d))
            vsd_idx.append(j)
        if on_frame is not None:
            on_frame(i, fr, r)
    # pose errors of all frames at once (one KD-tree for ADD-S)
    Gs = G[start:end]
    A.update(add=metrics.add(P, Gs, E), adds=metrics.adds(P, Gs, E), rot=metrics.rotation_error(Gs, E),
             trans=metrics.translation_error(Gs, E), mssd=metrics.mssd(P, Gs, E), mspd=metrics.mspd(P, K, Gs, E))
    arrays = {**A, **I, **B, "pose": E, "pose_gt": Gs,
              "in_contact": stream.values["in_contact"][start:end].astype(bool),
              "occlusion": stream.values["occlusion"][start:end].astype(float),
              "phase": stream.values["phase"][start:end].astype(np.int64),
              "vsd": np.array(vsd_rows, float).reshape(len(vsd_rows), -1), "vsd_idx": np.array(vsd_idx, np.int64)}
    meta = dict(object=obj, diameter=d, symmetric=bool(symmetric), symmetry=stream.meta["symmetry"],
                width=width, height=height, start=start, end=end, load_start=load0, load_end=load_now(),
                recording=path.name, kw=kw)
    if use_memo:
        memo_path.parent.mkdir(parents=True, exist_ok=True)
        tmp = memo_path.with_name(memo_path.name + ".part")
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, meta=np.frombuffer(json.dumps(meta).encode(), np.uint8), **arrays)
        tmp.replace(memo_path)
    return arrays, meta


def _rate(x):
    x = np.asarray(x)
    return float(x.mean()) if x.size else float("nan")


def summarize_run(a, meta):
    """Flat metrics of one run (per-frame arrays ``a`` from :func:`track`)."""
    from polar_sim import metrics

    d = meta["diameter"]
    e = a["adds"] if meta["symmetric"] else a["add"]  # ADD(-S): ADD-S for rotationally symmetric objects
    touch = a["in_contact"] & (a["occlusion"] > TOUCH_OCCLUSION)
    cpu = a["cpu_ms"][1:] if len(a["cpu_ms"]) > 1 else a["cpu_ms"]  # first frame: JIT and cache warm-up
    n_pred, n_gt, n_tp = a["n_pred"].sum(), a["n_gt"].sum(), a["n_tp"].sum()
    hn, ht = a["hand_near"][a["in_contact"]].sum(), a["hand_near_tgt"][a["in_contact"]].sum()
    out = {
        "object": meta["object"], "diameter_cm": round(100 * d, 2), "symmetry": meta["symmetry"],
        "frames": int(len(e)),
        "add_ok": _rate(e < 0.1 * d),                       # headline: ADD(-S) < 0.1 d
        "add_strict_ok": _rate(a["add"] < 0.1 * d),         # ADD for every object
        "adds_ok": _rate(a["adds"] < 0.1 * d),
        "add_mean_mm": float(1000 * np.mean(e)),
        "add_auc": float(metrics.pose_auc(e, 0.1)),
        "s5cm5deg": _rate((a["trans"] < 0.05) & (a["rot"] < np.deg2rad(5.0))),
        "iou_ok": _rate(a["iou"] > 0.5),
        "iou_mean": float(np.mean(a["iou"])),
        "iou_auc": float(metrics.iou_success_curve(a["iou"])[2]),
        "precision": float(n_tp / n_pred) if n_pred else 1.0,
        "recall": float(n_tp / n_gt) if n_gt else 1.0,
        "touch_frames": int(a["in_contact"].sum()),
        "hand_px_touch": int(hn), "hand_tgt_px_touch": int(ht),
        "hand_as_target": float(ht / hn) if hn else float("nan"),
        "hand_as_target_all": (float(a["hand_near_tgt"].sum() / a["hand_near"].sum())
                               if a["hand_near"].sum() else float("nan")),
        "occl_frames": int(touch.sum()),
        "occl_add_ok": _rate((e < 0.1 * d)[touch]),
        "occl_iou_ok": _rate((a["iou"] > 0.5)[touch]),
        "occlusion_max": float(a["occlusion"].max()),
        "occlusion_mean": float(a["occlusion"].mean()),
        "lost": int(a["lost"].sum()),
        "accepted": _rate(a["accepted"]),
        "first_loss": int(metrics.frames_until_loss(e, 0.3 * d)),
        "ar_mssd": float(metrics.ar_mssd(a["mssd"], d)),
        "ar_mspd": float(metrics.ar_mspd(a["mspd"], meta["width"])),
        "ar_vsd": float(metrics.ar_vsd(a["vsd"])) if len(a["vsd"]) else float("nan"),
        "cpu_ms_median": float(np.median(cpu)), "cpu_ms_mean": float(np.mean(cpu)),
        "cpu_ms_p95": float(np.percentile(cpu, 95)), "wall_ms_median": float(np.median(a["wall_ms"][1:])),
        "fps_cpu": float(1000.0 / np.median(cpu)),
        "roi_px": float(np.mean(a["roi_px"])),
        "width": int(meta["width"]), "height": int(meta["height"]),
        "load": float(meta["load_start"]),
    }
    return out


def pooled(rows, num, den="frames"):
    """Weighted mean of a per-run rate ``num`` over result rows, weights ``den`` (frames by default):
    the rate over all frames pooled."""
    w = np.array([r[den] for r in rows], float)
    v = np.array([r[num] for r in rows], float)
    ok = np.isfinite(v) & (w > 0)
    return float((v[ok] * w[ok]).sum() / w[ok].sum()) if ok.any() else float("nan")


def save_frames(ctx, name, config, a, meta):
    """Per-frame arrays a summary needs (errors, IoU, CPU ms, flags), in the trial's folder."""
    d = meta["diameter"]
    e = a["adds"] if meta["symmetric"] else a["add"]
    info = dict(sequence=name, config=config, object=meta["object"], diameter=d, width=meta["width"],
                load=meta["load_start"])
    np.savez_compressed(ctx.out_dir / "frames.npz", info=np.frombuffer(json.dumps(info).encode(), np.uint8),
                        err_d=e / d, add=a["add"], adds=a["adds"], iou=a["iou"], cpu_ms=a["cpu_ms"],
                        in_contact=a["in_contact"], occlusion=a["occlusion"], lost=a["lost"],
                        hand_near=a["hand_near"], hand_near_tgt=a["hand_near_tgt"])


def load_frames(out_dir):
    """{(sequence, config): dict of per-frame arrays + info} from a run's trial folders."""
    out = {}
    for p in sorted((out_dir / "trials").glob("*/frames.npz")):
        with np.load(p, allow_pickle=False) as z:
            info = json.loads(bytes(z["info"]).decode())
            out[(info["sequence"], info["config"])] = {**{k: z[k] for k in z.files if k != "info"}, **info}
    return out


def by(table, key, value):
    return [r for r in table if r[key] == value]


def rate_rows(table, key, order):
    """One row per value of ``key`` (in ``order``): pooled and per-sequence-mean rates."""
    rows = []
    for v in order:
        rs = by(table, key, v)
        if not rs:
            continue
        rows.append({
            key: v, "sequences": len(rs), "frames": int(sum(r["frames"] for r in rs)),
            "add_ok": pooled(rs, "add_ok"), "add_ok_seqmean": float(np.mean([r["add_ok"] for r in rs])),
            "add_ok_seqmin": float(np.min([r["add_ok"] for r in rs])),
            "add_strict_ok": pooled(rs, "add_strict_ok"), "add_auc": pooled(rs, "add_auc"),
            "s5cm5deg": pooled(rs, "s5cm5deg"),
            "iou_ok": pooled(rs, "iou_ok"), "iou_ok_seqmean": float(np.mean([r["iou_ok"] for r in rs])),
            "iou_mean": pooled(rs, "iou_mean"),
            "hand_as_target": (sum(r["hand_tgt_px_touch"] for r in rs) / max(1, sum(r["hand_px_touch"] for r in rs))),
            "occl_frames": int(sum(r["occl_frames"] for r in rs)),
            "occl_add_ok": pooled(rs, "occl_add_ok", "occl_frames"),
            "occl_iou_ok": pooled(rs, "occl_iou_ok", "occl_frames"),
            "lost": int(sum(r["lost"] for r in rs)),
            "ar_bop": float(np.nanmean([pooled(rs, "ar_vsd"), pooled(rs, "ar_mssd"), pooled(rs, "ar_mspd")])),
        })
    return rows


def best_of(vrows, key):
    """The variant whose worse headline rate (pooled ADD(-S) or IoU success) is highest."""
    return max(vrows, key=lambda r: (min(r["add_ok"], r["iou_ok"], r["add_ok_seqmean"], r["iou_ok_seqmean"]),
                                     r["add_auc"]))[key]
