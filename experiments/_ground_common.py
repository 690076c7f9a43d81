"""Shared helpers of the ground-chapter experiments (``ground_success``, ``ground_scale``,
``ground_odometry``, ``ground_appearance``); not an experiment itself (the leading underscore keeps it
out of the registry).

- :func:`route` loads a route recording (``polar_sim.sim.rover_sequences``; cached, regenerated
  deterministically when absent) and :func:`route_truth` derives the scoring truth from it.
- :func:`run_vo` runs :class:`polar_sim.ground.GroundVO` over a recording and keeps, per frame, what
  the experiments score (no probability maps unless asked, so a 3000-frame route fits in memory).
- :func:`integrate` re-integrates poses from per-frame speeds and rates exactly as ``GroundVO`` does
  (planar unicycle arcs or 3-D), so that one run gives the planar and the 3-D trajectory and the
  oracle-scale bound (true step lengths) with the estimator's own rotation.
- :func:`candidate_set` is the spec §8.2 protocol: one online w6 pass per route collects the RANSAC
  candidates (u, v, d̄), the learned P_G that weights them and the true ground label of each, so all
  RANSAC conditions are re-fitted on the same candidates.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from polar_sim.geometry import so3_exp

#: The four conditions of the issue: ground model x RANSAC sampling.
CONDITIONS = {
    "u2": dict(model="2param", sampling="uniform"),
    "w2": dict(model="2param", sampling="weighted"),
    "u6": dict(model="6param", sampling="uniform"),
    "w6": dict(model="6param", sampling="weighted"),
}

#: Route and length of the CI (``--quick``) size: short enough to record inside the CI run (about 20 s),
#: shared by all four experiments so it is recorded once per cache.
QUICK_ROUTE, QUICK_FRAMES = "terrain_00", 120

ALL_ROUTES = ("terrain_00", "terrain_01", "terrain_02", "terrain_03", "terrain_04", "terrain_05",
              "flat_00", "flat_01", "flat_02", "flat_03")


def single_thread():
    """Run OpenCV on one thread (the per-frame timing is single-threaded, and parallel trials do not
    oversubscribe the cores)."""
    import cv2

    cv2.setNumThreads(1)


_ROUTE_MEMO = {}


class _Lock:
    """An advisory file lock (``fcntl.flock``) around work that parallel workers should do once: the
    second worker waits, then finds the first one's result in the cache. Without ``fcntl`` it is a no-op."""

    def __init__(self, path):
        self.path = Path(path)

    def __enter__(self):
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fh = open(self.path, "w")
        try:
            import fcntl

            fcntl.flock(self.fh, fcntl.LOCK_EX)
        except ImportError:
            pass
        return self

    def __exit__(self, *exc):
        self.fh.close()  # closing releases the lock


def route(name, frames=None):
    """The recording of route ``name`` (its first ``frames`` frames if given), from the route cache
    (``$POLAR_SIM_CACHE``) or recorded now (deterministic from the route's seed). The last one loaded is
    kept in memory, so consecutive trials on one route in a worker decode it once."""
    from polar_sim.sim.rover_sequences import cache_dir, load_route  # imports MuJoCo only when recording

    key = (name, frames)
    if key not in _ROUTE_MEMO:
        _ROUTE_MEMO.clear()
        # Parallel trials or test workers that need the same missing route wait for one recorder.
        with _Lock(cache_dir() / f".{name}_{frames or 'full'}.lock"):
            _ROUTE_MEMO[key] = load_route(name, max_frames=frames, progress=False)
    return _ROUTE_MEMO[key]


def route_truth(rec):
    """Scoring truth of a recording: a dict with ``gt`` (n, 4, 4) camera k in camera 0's frame (KITTI),
    ``t`` (n,), ``speed`` (n,) instantaneous camera speed, ``speed_cd`` (n,) central-difference speed
    ‖p_{k+1} − p_{k−1}‖ / (t_{k+1} − t_{k−1}) (one-sided at the ends), ``step`` (n,) length of the step
    k−1 → k (0 for k = 0), ``yaw_rate`` (n,) ``w_cam[1]``, ``K``, ``h``, ``dt``, ``length_m``
    (path length) and the recording's meta."""
    T = rec.stack("T_world_cam")
    gt = np.linalg.inv(T[0]) @ T
    p = T[:, :3, 3]
    t = rec.stack("t").astype(np.float64)
    step = np.r_[0.0, np.linalg.norm(np.diff(p, axis=0), axis=1)]
    n = len(p)
    lo = np.maximum(np.arange(n) - 1, 0)
    hi = np.minimum(np.arange(n) + 1, n - 1)
    speed_cd = np.linalg.norm(p[hi] - p[lo], axis=1) / np.maximum(t[hi] - t[lo], 1e-9)
    return dict(gt=gt, t=t, speed=rec.stack("speed").astype(np.float64), speed_cd=speed_cd, step=step,
                yaw_rate=rec.stack("w_cam")[:, 1].astype(np.float64), K=np.array(rec.meta["K"]),
                h=float(rec.meta["camera_height"]), dt=float(rec.meta["dt"]), length_m=float(step.sum()),
                meta=dict(rec.meta))


def candidate_labels(mask, xy):
    """True ground label of candidates at pixel positions ``xy`` (m, 2) (column, row) of ``mask``."""
    if len(xy) == 0:
        return np.zeros(0, dtype=bool)
    H, W = mask.shape
    c = np.clip(np.rint(xy[:, 0]).astype(np.intp), 0, W - 1)
    r = np.clip(np.rint(xy[:, 1]).astype(np.intp), 0, H - 1)
    return mask[r, c]


def run_vo(rec, cond, seed=0, *, keep_candidates=False, iou=False, keep_prob=(), **kw):
    """Run ``GroundVO`` (condition ``cond`` of :data:`CONDITIONS`, or a dict of keyword arguments) over a
    recording at its own resolution (``downsample=1``).

    Returns a dict of per-frame arrays: ``speed``, ``yaw_rate`` (filtered), ``speed_raw``, ``yaw_rate_raw``,
    ``rates_raw`` (n, 3), ``status`` (n,) str, ``middle`` (n,) middle-frame index, ``n_candidates``,
    ``n_inliers``, ``cpu_ms`` (n,) ``process`` CPU time; ``poses`` (the estimator's own trajectory) and
    ``times``; with ``iou`` the classifier IoU against the true ground mask of the same frame (n,); with
    ``keep_candidates`` a list of per-frame dicts (u, v, dbar, prob, label, inlier) of the RANSAC
    candidates; ``prob`` {frame: ground_prob} for the frames in ``keep_prob``.
    """
    from polar_sim.ground import GroundVO
    from polar_sim.metrics.ground import classifier_iou

    args = dict(CONDITIONS[cond]) if isinstance(cond, str) else dict(cond)
    args.update(kw)
    K, h = np.array(rec.meta["K"]), float(rec.meta["camera_height"])
    vo = GroundVO(K, h, downsample=1, seed=seed, **args)
    n = len(rec)
    out = {k: np.full(n, np.nan) for k in ("speed", "yaw_rate", "speed_raw", "yaw_rate_raw", "cpu_ms", "iou")}
    out["rates_raw"] = np.full((n, 3), np.nan)
    out["status"] = np.empty(n, dtype=object)
    for k in ("middle", "n_candidates", "n_inliers"):
        out[k] = np.zeros(n, dtype=np.int64)
    cands, probs = [], {}
    for i in range(n):
        f = rec[i]
        c0 = time.process_time()
        e = vo.process(f["rgb"], float(f["t"]))
        out["cpu_ms"][i] = (time.process_time() - c0) * 1e3
        out["speed"][i], out["yaw_rate"][i] = e.speed, e.yaw_rate
        out["speed_raw"][i], out["yaw_rate_raw"][i] = e.speed_raw, e.yaw_rate_raw
        out["rates_raw"][i] = e.rates_raw
        out["status"][i] = e.status
        out["middle"][i] = e.diagnostics["middle_index"]
        out["n_candidates"][i] = e.diagnostics["n_candidates"]
        out["n_inliers"][i] = e.diagnostics["n_inliers"]
        if iou:
            out["iou"][i] = classifier_iou(e.ground_prob, f["ground_mask"])
        if i in keep_prob:
            probs[i] = e.ground_prob.copy()
        if keep_candidates:
            m = int(e.diagnostics["middle_index"])
            lab = (candidate_labels(rec[m]["ground_mask"], e.candidates) if m >= 0 and len(e.candidates)
                   else np.zeros(0, dtype=bool))
            cands.append(dict(u=e.candidate_uv[:, 0].copy(), v=e.candidate_uv[:, 1].copy(),
                              dbar=e.candidate_dbar.copy(), prob=e.candidate_prob.copy(), label=lab,
                              inlier=e.inlier_mask.copy(), middle=m))
    out["poses"] = vo.trajectory()
    out["times"] = vo.timestamps()
    out["status"] = out["status"].astype(str)
    if keep_candidates:
        out["candidates"] = cands
    if keep_prob:
        out["prob"] = probs
    return out


def step_rates(run):
    """Per-frame rates (n, 3) the estimator integrates: measured pitch/roll rates where the motion was
    solved (0 otherwise) and the filtered yaw rate (what ``GroundVO`` uses for its poses)."""
    r = np.where(np.isfinite(run["rates_raw"]), run["rates_raw"], 0.0)
    r[:, 1] = run["yaw_rate"]
    return r


def integrate(times, speeds, rates, mode="3d"):
    """Poses (n, 4, 4) integrated as ``GroundVO`` does (spec §6.1 with the B27 fix).

    ``speeds`` (n,) and ``rates`` (n, 3) are the values the estimator reports when image k arrives
    (they describe the middle frame k − 1): the step k − 1 → k uses those of image k, and the step
    0 → 1 reuses those of image 2. ``mode`` "planar": exact unicycle arcs with the yaw rate (rates[:, 1]);
    "3d": R ← R exp([Ω] dt), t ← t + R exp([Ω] dt/2) (0, 0, V dt).
    """
    n = len(times)
    P = np.tile(np.eye(4), (n, 1, 1))
    for k in range(1, n):
        j = max(k, 2) if n > 2 else k
        dt = times[k] - times[k - 1]
        V, w = float(speeds[j]), rates[j]
        S = np.eye(4)
        if mode == "3d":
            S[:3, :3] = so3_exp(w * dt)
            S[:3, 3] = so3_exp(w * dt / 2) @ np.array([0.0, 0.0, V * dt])
        else:
            a = float(w[1]) * dt
            ca, sa = np.cos(a), np.sin(a)
            S[:3, :3] = [[ca, 0.0, sa], [0.0, 1.0, 0.0], [-sa, 0.0, ca]]
            if abs(a) < 1e-9:
                S[:3, 3] = [V * dt * a / 2, 0.0, V * dt]
            else:
                S[:3, 3] = [V / w[1] * (1.0 - ca), 0.0, V / w[1] * sa]
        P[k] = P[k - 1] @ S
    return P


def oracle_speeds(truth, n):
    """Per-image speeds for :func:`integrate` that make every step exactly as long as the true step:
    the step k − 1 → k uses ``speeds[k]`` (and the step 0 → 1 ``speeds[2]``, which :func:`integrate`
    reuses), so ``speeds[k] = |p_k − p_{k−1}| / dt_k``; the step 0 → 1 then has the length of step 1 → 2
    (the only compromise of the B27 convention, one frame out of thousands)."""
    dt = np.r_[1.0, np.diff(truth["t"][:n])]
    return truth["step"][:n] / dt


def write_trajectories(out_dir, name, times, poses, gt=None):
    """KITTI and TUM files of a trajectory (and of the truth once per folder) for ``evo``."""
    from polar_sim import metrics

    out_dir = Path(out_dir)
    metrics.write_kitti(out_dir / f"{name}_kitti.txt", poses)
    metrics.write_tum(out_dir / f"{name}_tum.txt", times, poses)
    if gt is not None and not (out_dir / "gt_kitti.txt").exists():
        metrics.write_kitti(out_dir / "gt_kitti.txt", gt)
        metrics.write_tum(out_dir / "gt_tum.txt", times, gt)


# ---------------------------------------------------------------------------------------------------
# The candidate sets of the RANSAC experiments (spec §8.2)

#: Warm-up frames skipped before candidate frames are taken (the rover starts from standstill and the
#: classifier has not learned the ground yet).
WARMUP_FRAMES = 30
_CANDIDATE_FORMAT = 1
_MEMO = {}


def _frames_of(run_c, n_pick):
    """Indices of the frames used: after the warm-up, a fitted frame with >= 20 candidates and weights,
    ``n_pick`` equally spaced ones (all of them if ``n_pick`` is None)."""
    ok = [i for i, c in enumerate(run_c) if i >= WARMUP_FRAMES and len(c["u"]) >= 20
          and np.isfinite(c["prob"]).all() and c["middle"] >= 0]
    if n_pick is None or len(ok) <= n_pick:
        return ok
    pick = np.unique(np.rint(np.linspace(0, len(ok) - 1, n_pick)).astype(int))
    return [ok[i] for i in pick]


def _source_tag():
    """Short hash of the sources a candidate set depends on (the ground module, the route recorder and
    this file), so a cached set is never replayed after any of them changed."""
    import hashlib

    import polar_sim

    root = Path(polar_sim.__file__).parent
    files = sorted((root / "ground").glob("*.py")) + [root / "sim" / "rover_sequences.py", root / "control.py",
                                                       Path(__file__)]
    h = hashlib.sha256()
    for f in files:
        h.update(f.read_bytes())
    return h.hexdigest()[:12]


def candidate_set(routes, frames=None, n_pick=None):
    """RANSAC candidates of one online w6 pass (seed 0) over each route, with their P_G weights, true
    ground labels and the true speed of their middle frame, for re-fitting every RANSAC condition on
    the same data (spec §8.2).

    ``routes``: route names; ``frames``: recording length (None = the full route); ``n_pick``: frames
    kept per route (equally spaced after :data:`WARMUP_FRAMES`; None = all). Memoised per process and
    cached as ``.npz`` beside the route cache (``ground_candidates/``, keyed by a hash of the sources it
    depends on), so the trials of the RANSAC experiments share one pass.
    Returns a list of per-frame dicts (route, frame, u, v, dbar, prob, label, speed_cd, speed, h).
    """
    from polar_sim.sim.rover_sequences import cache_dir

    key = (tuple(routes), frames, n_pick)
    if key in _MEMO:
        return _MEMO[key]
    tag = "-".join(routes) if len(routes) <= 3 else f"{len(routes)}routes"
    path = (cache_dir().parent / "ground_candidates"
            / f"{tag}_{frames or 'full'}_{n_pick or 'all'}_{_source_tag()}.npz")
    with _Lock(path.with_suffix(".lock")):
        if not path.is_file():
            _save_candidates(path, _collect(routes, frames, n_pick), key)
    _MEMO[key] = _load_candidates(path, key)
    return _MEMO[key]


def _collect(routes, frames, n_pick):
    out = []
    for name in routes:
        rec = route(name, frames)
        tr = route_truth(rec)
        r = run_vo(rec, "w6", 0, keep_candidates=True)
        for i in _frames_of(r["candidates"], n_pick):
            c = r["candidates"][i]
            m = c["middle"]
            out.append(dict(route=name, frame=i, u=c["u"], v=c["v"], dbar=c["dbar"], prob=c["prob"],
                            label=c["label"], speed_cd=float(tr["speed_cd"][m]), speed=float(tr["speed"][m]),
                            h=tr["h"]))
        del rec, r
    return out


def _save_candidates(path, data, key):
    path.parent.mkdir(parents=True, exist_ok=True)
    lens = np.array([len(d["u"]) for d in data], dtype=np.int64)
    arrays = {k: np.concatenate([d[k] for d in data]) if data else np.zeros(0) for k in ("u", "v", "dbar", "prob", "label")}
    head = dict(format=_CANDIDATE_FORMAT, key=[list(key[0]), key[1], key[2]],
                routes=[d["route"] for d in data], frames=[d["frame"] for d in data])
    tmp = path.with_name(path.name + f".{os.getpid()}.part")
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, lens=lens, speed_cd=np.array([d["speed_cd"] for d in data]),
                            speed=np.array([d["speed"] for d in data]), h=np.array([d["h"] for d in data]),
                            header=np.frombuffer(json.dumps(head).encode(), dtype=np.uint8), **arrays)
    tmp.replace(path)


def _load_candidates(path, key):
    with np.load(path, allow_pickle=False) as z:
        head = json.loads(bytes(z["header"]).decode())
        if head.get("format") != _CANDIDATE_FORMAT or head.get("key") != [list(key[0]), key[1], key[2]]:
            raise ValueError(f"{path}: candidate file of another format or data set")
        lens = z["lens"]
        cuts = np.r_[0, np.cumsum(lens)]
        cols = {k: z[k] for k in ("u", "v", "dbar", "prob", "label")}
        out = []
        for j in range(len(lens)):
            sl = slice(cuts[j], cuts[j + 1])
            d = {k: cols[k][sl] for k in cols}
            d["label"] = d["label"].astype(bool)
            d.update(route=head["routes"][j], frame=head["frames"][j], speed_cd=float(z["speed_cd"][j]),
                     speed=float(z["speed"][j]), h=float(z["h"][j]))
            out.append(d)
    return out


def refit(data, *, model, sampling, n_iter, lam, seed):
    """Re-fit every frame of a candidate set with one RANSAC condition.

    The random stream depends only on (seed, n_iter, model), not on the sampling, so uniform and
    weighted draws use the same uniform numbers (a paired comparison). Returns per-frame lists of
    (labels, inlier masks) and the raw speeds (NaN where no model was found).
    """
    from polar_sim.ground import fit_ground

    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(n_iter), 2 if model == "2param" else 6,
                                                        int(round(lam * 1e6))]))
    labels, inliers, speeds = [], [], np.full(len(data), np.nan)
    for j, d in enumerate(data):
        w = d["prob"] if sampling == "weighted" else None
        f = fit_ground(d["u"], d["v"], d["dbar"], d["h"], model=model, weights=w, n_iter=n_iter, rng=rng, lam=lam)
        labels.append(d["label"])
        inliers.append(f.inliers)
        if f.ok:
            speeds[j] = f.speed
    return labels, inliers, speeds


#: Candidate data sets of the RANSAC experiments: (routes, recording length, frames kept per route).
#: "routes10": 100 equally spaced frames of each of the ten routes (the dissertation used 100 KITTI
#: images); "quick": every frame after the warm-up of the CI route.
DATASETS = {"routes10": (ALL_ROUTES, None, 100), "quick": ((QUICK_ROUTE,), QUICK_FRAMES, None)}

#: Iteration grids of the RANSAC experiments (spec §8.2, dissertation Fig. 4.7).
ITERATIONS = {"2param": (1, 2, 4, 8, 16), "6param": (5, 11, 25, 55, 125)}

#: RANSAC configurations: (model, lambda); lambda only matters for 6param.
CONFIGS = {"2p": ("2param", 0.1), "6p_lam1": ("6param", 1.0), "6p_lam0.1": ("6param", 0.1),
           "6p_lam0.01": ("6param", 0.01)}
