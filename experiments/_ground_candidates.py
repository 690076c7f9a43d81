"""The RANSAC candidate sets of the ground success-rate and scale experiments (not an experiment: the
underscore keeps it out of the registry). One online w6 pass of ``GroundVO`` per route collects, per
frame, the RANSAC candidates, their learned P(ground) and their true ground label; every condition of
``ground_success`` and ``ground_scale`` re-fits RANSAC on exactly these (derived arrays cached through
``polar_sim.sim.recorders.sequences.cached_arrays``).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from polar_sim.experiments import _ground_common as G

#: RANSAC configurations: (model, lambda); lambda only matters for 6param.
CONFIGS = {"2p": ("2param", 0.1), "6p_lam1": ("6param", 1.0), "6p_lam0.1": ("6param", 0.1),
           "6p_lam0.01": ("6param", 0.01)}
#: Iteration counts (the dissertation's grids, 2p {1..16} and 6p {5..125}, run for every model).
ITERATIONS = (1, 2, 4, 5, 8, 11, 16, 25, 55, 125)
#: Warm-up frames skipped before candidate frames are taken (start from rest, empty classifier).
WARMUP_FRAMES = 30
#: Candidate data sets: (routes, recording length, frames kept per route). 100 equally spaced frames
#: per route, as the dissertation used 100 KITTI images; the quick sets keep every frame after the
#: warm-up of the quick route.
DATASETS = {"dev10": (G.DEV10, None, 100), "test12": (G.TEST_ROUTES, None, 100),
            "quick_dev": ((G.QUICK_ROUTE["dev"],), G.QUICK_FRAMES, None),
            "quick_test": ((G.QUICK_ROUTE["test"],), G.QUICK_FRAMES, None)}


def _source_tag():
    """Hash of the sources a candidate set depends on (the ground module, the route recorder, this
    file), part of its cache key, so a stale set is never replayed."""
    import polar_sim
    from polar_sim.sim.recorders import rover_sequences

    root = Path(polar_sim.__file__).parent
    files = sorted((root / "ground").glob("*.py")) + [Path(rover_sequences.__file__), Path(__file__)]
    h = hashlib.sha256()
    for f in files:
        h.update(f.read_bytes())
    return h.hexdigest()[:12]


def _route_frames(name, frames):
    """The candidate frames of one route's online w6 pass (seed 0), without the dense ground alignment
    (the dissertation's pipeline, whose RANSAC sampling Ch. 4 is about): every frame after the warm-up
    with >= 20 weighted candidates, with their u, v, d̄, P(ground), true label and middle frame index."""
    from polar_sim.ground import ClassifierConfig, DenseConfig, GroundVO
    from polar_sim.ground.replay import replay
    from polar_sim.metrics.ground import labels_at
    from polar_sim.sim.recorders.rover_sequences import load_route, route_truth

    rec = load_route(name, max_frames=frames)
    tr = route_truth(rec)
    found = []

    def keep(i, f, e, prev):
        m = int(e.diagnostics["middle_index"])
        if i < WARMUP_FRAMES or m < 0 or len(e.candidates) < 20 or not np.isfinite(e.candidate_prob).all():
            return
        found.append(dict(frame=i, u=e.candidate_uv[:, 0].copy(), v=e.candidate_uv[:, 1].copy(),
                          dbar=e.candidate_dbar.copy(), prob=e.candidate_prob.copy(),
                          label=labels_at(prev["ground_mask"], e.candidates), middle=m))

    # The dissertation's pipeline: no dense stage and no sky labels (neither is in the study), so the
    # candidates' P(ground) is the one its sampling experiments were about.
    vo = GroundVO(tr["K"], tr["h"], model="6param", sampling="weighted", downsample=1, seed=0,
                  dense=DenseConfig(enabled=False), classifier=ClassifierConfig(sky_labels=0))
    replay(vo, rec.frames(keys=("rgb", "t", "ground_mask")), on_frame=keep)
    return found, tr


def _collect(routes, frames, n_pick):
    """The candidate frames of every route (``n_pick`` equally spaced ones per route, None = all), with
    the middle frame's true speeds, as flat arrays."""
    cols = {k: [] for k in ("u", "v", "dbar", "prob", "label")}
    per = {k: [] for k in ("lens", "route", "frame", "speed_cd", "speed", "h")}
    for ri, name in enumerate(routes):
        found, tr = _route_frames(name, frames)
        pick = range(len(found)) if n_pick is None or len(found) <= n_pick else \
            np.unique(np.rint(np.linspace(0, len(found) - 1, n_pick)).astype(int))
        for j in pick:
            d = found[j]
            for k in cols:
                cols[k].append(d[k])
            per["lens"].append(len(d["u"]))
            per["route"].append(ri)
            per["frame"].append(d["frame"])
            per["speed_cd"].append(tr["speed_cd"][d["middle"]])
            per["speed"].append(tr["speed"][d["middle"]])
            per["h"].append(tr["h"])
    out = {k: np.concatenate(v) if v else np.zeros(0) for k, v in cols.items()}
    out["label"] = out["label"].astype(bool)
    out.update({k: np.asarray(v) for k, v in per.items()})
    return out


_MEMO = {}


def candidate_set(routes, frames=None, n_pick=None):
    """The RANSAC candidate sets over ``routes``: a list of per-frame dicts (route, frame,
    u, v, dbar, prob, label, speed_cd, speed, h), cached as derived arrays (kind
    ``"ground_candidates"``, keyed by the routes, length, frames per route and the sources' hash) and
    memoised per process, so every trial of the RANSAC experiments shares one pass."""
    from polar_sim.sim.recorders import sequences

    key = {"routes": list(routes), "frames": int(frames or 0), "n_pick": int(n_pick or 0), "code": _source_tag()}
    mk = repr(sorted(key.items()))
    if mk not in _MEMO:
        z = sequences.cached_arrays("ground_candidates", key, lambda: _collect(routes, frames, n_pick), version=2)
        cuts = np.r_[0, np.cumsum(z["lens"])].astype(int)
        _MEMO.clear()
        _MEMO[mk] = [dict(route=routes[int(z["route"][j])], frame=int(z["frame"][j]),
                          **{k: z[k][cuts[j]:cuts[j + 1]] for k in ("u", "v", "dbar", "prob", "label")},
                          speed_cd=float(z["speed_cd"][j]), speed=float(z["speed"][j]), h=float(z["h"][j]))
                     for j in range(len(z["lens"]))]
    return _MEMO[mk]


def data_of(params, ctx):
    """The candidate set of a trial: its ``data`` axis value, or the split's quick set for ``"quick"``."""
    return candidate_set(*DATASETS[f"quick_{ctx.split}" if params["data"] == "quick" else params["data"]])


def refit(data, *, config, sampling, n_iter, seed):
    """Re-fit RANSAC on every frame of a candidate set under one condition.

    The random stream depends on (seed, n_iter, model, lambda) only, not on the sampling, so uniform
    and weighted draws of one repetition use the same uniform numbers (a paired comparison).
    Returns (true labels per frame, inlier masks per frame, raw speeds (n,), NaN without a model).
    """
    from polar_sim.ground import fit_ground

    model, lam = CONFIGS[config]
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


def model_label(config):
    model, lam = CONFIGS[config]
    return "2-parameter" if model == "2param" else f"6-parameter, λ = {lam:g}"
