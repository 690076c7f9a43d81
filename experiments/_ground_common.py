"""Shared declarations of the ground-chapter experiments (not an experiment: the underscore keeps it
out of the registry). The work is in the library: routes are recordings from the one cache
(``polar_sim.sim.rover_sequences.load_route``), VOs are ``vo`` plug-ins
(``polar_sim.runner.methods``) replayed by ``polar_sim.ground.replay``, integration is
``polar_sim.ground.integration``, scores are ``polar_sim.metrics``. What stays here is the protocol:
the route lists per split, the size-dependent protocol values (``ROUTE_PARAMS``, ``QUICK_PARAMS``),
and the RANSAC candidate sets of the success-rate and scale experiments (derived arrays through
``polar_sim.sim.sequences.cached_arrays``).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

#: The ten routes every pre-protocol figure was measured on (the dev split's default-appearance routes).
DEV10 = ("terrain_00", "terrain_01", "terrain_02", "terrain_03", "terrain_04", "terrain_05",
         "flat_00", "flat_01", "flat_02", "flat_03")
DEV_FAMILY_ROUTES = ("dev_speckle", "dev_gravel", "dev_grass", "dev_blotches", "dev_uniform")
TEST_ROUTES = ("test_speckle", "test_gravel", "test_grass", "test_uniform", "test_stripes", "test_checker",
               "test_blotches", "test_random_0", "test_random_1", "test_random_2", "test_default_0", "test_default_1")

#: The CI (``quick``) routes: the first 120 frames (54 m on dev, 65 m on test) of one route per split,
#: shared by all experiments so each is recorded once per cache (about 20 s). The ``route`` axis
#: value ``"quick"`` names the split's quick route.
QUICK_FRAMES = 120
QUICK_ROUTE = {"dev": "terrain_00", "test": "test_random_0"}

#: Protocol parameters of the experiments that drive a route (``Experiment.params``, overridable with
#: ``--set``): ``max_frames``, the frames of each route replayed (null = the whole route). The quick
#: size cuts every route to ``QUICK_FRAMES`` (``QUICK_PARAMS``, its ``sizes["quick"]["params"]``).
ROUTE_PARAMS = {"max_frames": None}
QUICK_PARAMS = {"max_frames": QUICK_FRAMES}

#: RANSAC configurations of the candidate-set experiments: (model, lambda); lambda only matters for 6param.
CONFIGS = {"2p": ("2param", 0.1), "6p_lam1": ("6param", 1.0), "6p_lam0.1": ("6param", 0.1),
           "6p_lam0.01": ("6param", 0.01)}
#: Iteration counts (the dissertation's grids, 2p {1..16} and 6p {5..125}, run for every model).
ITERATIONS = (1, 2, 4, 5, 8, 11, 16, 25, 55, 125)
#: Warm-up frames skipped before candidate frames are taken (start from rest, empty classifier).
WARMUP_FRAMES = 30


def single_thread():
    """OpenCV on one thread: per-frame CPU times are single-threaded and parallel trials do not
    oversubscribe the cores."""
    import cv2

    cv2.setNumThreads(1)


def _source_tag():
    """Hash of the sources a candidate set depends on (the ground module, the route recorder, this
    file), part of its cache key, so a stale set is never replayed."""
    import polar_sim

    root = Path(polar_sim.__file__).parent
    files = sorted((root / "ground").glob("*.py")) + [root / "sim" / "rover_sequences.py", Path(__file__)]
    h = hashlib.sha256()
    for f in files:
        h.update(f.read_bytes())
    return h.hexdigest()[:12]


def _collect(routes, frames, n_pick):
    """One online w6 pass (seed 0) per route: the RANSAC candidates of every frame after the warm-up
    with >= 20 weighted candidates (``n_pick`` equally spaced ones per route, None = all), their
    learned P_G, their true ground label at the middle frame, and the middle frame's true speeds."""
    from polar_sim.ground import GroundVO
    from polar_sim.ground.replay import replay
    from polar_sim.metrics.ground import labels_at
    from polar_sim.sim.rover_sequences import load_route, route_truth

    cols = {k: [] for k in ("u", "v", "dbar", "prob", "label")}
    per = {k: [] for k in ("lens", "route", "frame", "speed_cd", "speed", "h")}
    for ri, name in enumerate(routes):
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

        vo = GroundVO(tr["K"], tr["h"], model="6param", sampling="weighted", downsample=1, seed=0)
        replay(vo, rec.frames(keys=("rgb", "t", "ground_mask")), on_frame=keep)
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
    from polar_sim.sim import sequences

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


#: Candidate data sets: (routes, recording length, frames kept per route). 100 equally spaced frames
#: per route, as the dissertation used 100 KITTI images; the quick sets keep every frame after the
#: warm-up of the quick route.
DATASETS = {"dev10": (DEV10, None, 100), "test12": (TEST_ROUTES, None, 100),
            "quick_dev": ((QUICK_ROUTE["dev"],), QUICK_FRAMES, None),
            "quick_test": ((QUICK_ROUTE["test"],), QUICK_FRAMES, None)}


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


def route_choices():
    """The values the ``route`` axis accepts: ``"quick"`` (the split's quick route) and every dev and
    test route (``polar_sim.sim.rover_sequences.SPLITS``)."""
    from polar_sim.sim.rover_sequences import SPLITS

    return ["quick", *SPLITS["dev"], *SPLITS["test"]]


def route_of(params, ctx):
    """The route name of a trial: the axis value, or the split's quick route for ``"quick"``."""
    return QUICK_ROUTE[ctx.split] if params["route"] == "quick" else params["route"]


def max_frames(ctx):
    """The run's ``max_frames`` param: None (the whole route) or a positive int."""
    n = ctx.params["max_frames"]
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
        raise ValueError(f"max_frames: expected a positive number of frames or null (the whole route), got {n!r}")
    return n


def load(params, ctx):
    """The trial's recording (its first ``max_frames`` frames, a run param) and its truth."""
    from polar_sim.sim.rover_sequences import load_route, route_truth

    rec = load_route(route_of(params, ctx), max_frames=max_frames(ctx))
    return rec, route_truth(rec)


def table(rows, cols, why=None):
    """A markdown table without the columns that are empty (None, "" or NaN) in every row, followed by
    one line naming the columns left out and why (``why``: {column: reason}; a column without one is
    "empty in every row"). A route under 100 m, for example, has no 100 m KITTI segment."""
    from polar_sim.runner.report import markdown_table, nonempty_columns

    rows, cols = list(rows), list(cols)
    keep, _ = nonempty_columns(rows, cols)
    gone = [c for c in cols if c not in keep]
    out = markdown_table(rows, keep, drop_empty=False)
    if rows and gone:
        reasons = {}
        for c in gone:
            reasons.setdefault((why or {}).get(c, "empty in every row"), []).append(f"`{c}`")
        out += "\n\nNot shown: " + "; ".join(f"{', '.join(cs)} ({r})" for r, cs in reasons.items()) + "."
    return out


def family_names(rec):
    """Family label of each zone of a route: the appearance family, or ``default <type>`` for the
    default look (whose asphalt/gravel/grass/dirt textures are not the families of the same name)."""
    zones = [str(z) for z in rec.meta["zones"]]
    return zones if rec.meta.get("appearance") else [f"default {z}" for z in zones]


def plot_probability_maps(path, rec, probs, captions, iou):
    """Rows of camera image | P(ground) | thresholded errors for the frames in ``probs`` ({frame: map})."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = sorted(probs)
    if not frames:
        return
    fig, axes = plt.subplots(len(frames), 3, figsize=(13, 1.5 * len(frames) + 0.5), squeeze=False,
                             gridspec_kw={"wspace": 0.3})   # room for the colour bar's ticks before the third column
    rows = {i: f for i, f in rec.frames(stop=frames[-1] + 1, keys=("rgb", "ground_mask")) if i in probs}
    for row, i in zip(axes, frames):
        p, gt = probs[i], rows[i]["ground_mask"]
        err = np.zeros(gt.shape + (3,))
        err[(p > 0.5) & gt], err[(p > 0.5) & ~gt], err[(p <= 0.5) & gt] = (0.75,) * 3, (0.85, 0.1, 0.1), (0.1, 0.3, 0.9)
        row[0].imshow(rows[i]["rgb"])
        im = row[1].imshow(p, vmin=0, vmax=1, cmap="viridis")
        row[2].imshow(err)
        row[0].set_ylabel(f"frame {i}\n{captions.get(i, '')}", fontsize=7)
        row[2].set_ylabel(f"IoU {iou[i]:.2f}", fontsize=7)
        row[2].yaxis.set_label_position("right")     # clear of the colour bar on its left
        for a in row:
            a.set_xticks([])
            a.set_yticks([])
    axes[0, 0].set_title("camera image (simulated)", fontsize=8)
    axes[0, 1].set_title("calibrated P(ground)", fontsize=8)
    axes[0, 2].set_title("P > 0.5 vs truth:\ngrey hit, red false ground, blue missed ground", fontsize=8)
    fig.colorbar(im, ax=axes[:, 1], fraction=0.02, label="P(ground)")
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)


def plot_per_route(table, key, target, ylabel, title):
    """A bar chart of ``key`` per route, one bar per method, with the target as a dashed line;
    returns the figure. Errors span decades (1 % to 200 %), so the axis is logarithmic with plain
    1-2-5 tick labels; the legend sits beside the axes, never over a bar."""
    import textwrap

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    routes, meths = sorted({r["route"] for r in table}), sorted({r["method"] for r in table})
    fig, ax = plt.subplots(figsize=(max(6, 0.9 * len(routes) + 3), 3.6))
    w = 0.8 / len(meths)
    vals = [target]
    for j, m in enumerate(meths):
        v = [next((r[key] for r in table if r["route"] == rt and r["method"] == m), np.nan) for rt in routes]
        vals += [x for x in v if np.isfinite(x) and x > 0]
        ax.bar(np.arange(len(routes)) + (j - (len(meths) - 1) / 2) * w, v, w, label=m)
    ax.axhline(target, color="k", ls="--", lw=0.8, label=f"target {target} %")
    ax.set_xticks(np.arange(len(routes)), routes, rotation=30, ha="right", fontsize=8)
    lo, hi = min(vals) / 1.5, max(vals) * 1.5
    ax.set_yscale("log")
    ax.set_ylim(lo, hi)
    ticks = [m * 10.0 ** e for e in range(int(np.floor(np.log10(lo))), int(np.ceil(np.log10(hi))) + 1)
             for m in (1, 2, 5) if lo <= m * 10.0 ** e <= hi]
    ax.yaxis.set_major_locator(FixedLocator(ticks))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.set_ylabel(textwrap.fill(ylabel, 28), fontsize=9)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    ax.grid(alpha=0.3, axis="y")
    return fig
