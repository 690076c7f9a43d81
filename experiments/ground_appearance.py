"""ground_appearance: how the ground classifier follows the ground as its appearance changes along a route.

Every route crosses four ground zones (asphalt, gravel, grass, dirt; order seeded) in contiguous arcs
of the closed route. ``GroundVO`` runs over the route; every frame, its ground probability map (Naive
Bayes on quantised HSV, retrained online from the RANSAC inliers) is thresholded at 0.5 and scored
against the true ground mask of the same image (IoU over the whole image). The zone boundaries come
from the scene (``zone_of_route``): the camera's progress along the route, and its distance to the next
boundary, mark when a new texture comes into view.

"Settled" frames are those at least 5 s after the start (the rover starts from standstill and the
classifier from empty histograms) and outside the transition window around each boundary, from 40 m
before it (the new texture is visible on the far ground) to 10 m after it (it has passed under the
camera; the zones meet along the edges of 20 m ground tiles, so a boundary is only sharp to about
±10 m). The issue's target is IoU ≥ 0.85 on settled frames. Each trial also saves the IoU series, a
figure of IoU over time with the boundaries marked, and probability-map pictures in the middle of every
zone and on every approach to a boundary.

Full size: terrain_00, terrain_04 (hills) and flat_00, flat_02 (flat) with w6 and u6 (the sampling
changes which inliers train the classifier). Quick size: the first 120 frames of terrain_00 with w6
(one zone; the first boundary is about 130 m in).
"""

import json

import numpy as np

from polar_sim.experiments import _ground_common as G
from polar_sim.runner import Check, Experiment
from polar_sim.runner.report import markdown_table, savefig, write_csv_table

TARGET_IOU = 0.85
WARMUP_S = 5.0
BEFORE_M, AFTER_M = 40.0, 10.0


def zones_along(rec):
    """Per-frame zone geometry of a recorded route: a dict with ``progress`` (n,) arc length driven along
    the route (m, monotone over laps), ``zone`` (n,) index of the zone under the camera, ``names`` (zone
    names), ``boundaries`` (arc lengths where the zone changes, unwrapped over the laps driven) and
    ``boundary_zones`` ((from, to) per boundary)."""
    from polar_sim.control import PurePursuit
    from polar_sim.sim.world import World

    meta = rec.meta
    w = World(meta["scene"], seed=int(meta["seed"]))
    try:
        route, zor, names = np.array(w.meta["route"]), np.array(w.meta["zone_of_route"]), [str(z) for z in w.meta["zones"]]
    finally:
        w.close()
    pp = PurePursuit(route, lookahead=8.0, closed=True)
    L = pp.length
    T = rec.stack("T_world_cam")
    prog = np.array([pp.progress((p[0], p[1], 0.0)) for p in T[:, :3, 3]])
    s_wp = pp._s[:-1]  # arc length of every waypoint
    zone = zor[np.clip(np.searchsorted(s_wp, prog % L, side="right") - 1, 0, len(zor) - 1)]
    change = np.flatnonzero(np.diff(np.r_[zor, zor[:1]]) != 0) + 1  # first waypoint of the next zone
    b_s, b_z = [], []
    for lap in range(int(prog[-1] // L) + 2):
        for i in change:
            s = lap * L + (s_wp[i] if i < len(s_wp) else L)
            if prog[0] - BEFORE_M < s < prog[-1] + BEFORE_M:
                b_s.append(float(s))
                b_z.append((int(zor[i - 1]), int(zor[i % len(zor)])))
    return dict(progress=prog, zone=zone, names=names, boundaries=np.array(b_s), boundary_zones=b_z, lap_m=L)


def settled_mask(t, progress, boundaries):
    """Frames at least WARMUP_S after the start and outside [b − BEFORE_M, b + AFTER_M] of every boundary."""
    ok = (t - t[0]) >= WARMUP_S
    for b in boundaries:
        ok &= ~((progress >= b - BEFORE_M) & (progress <= b + AFTER_M))
    return ok


def _picture_frames(z, settled):
    """Frames to picture, as (frame, caption): the middle settled frame of each stretch of one zone, and
    the frame where each boundary is 15 m ahead."""
    progress, zone, names = z["progress"], z["zone"], z["names"]
    out = []
    idx = np.flatnonzero(settled)
    if len(idx):
        runs = np.split(idx, np.flatnonzero((np.diff(idx) > 1) | (np.diff(zone[idx]) != 0)) + 1)
        out += [(int(r[len(r) // 2]), names[zone[r[0]]]) for r in runs if len(r) >= 10]
    for b, (za, zb) in zip(z["boundaries"], z["boundary_zones"]):
        j = np.flatnonzero(progress >= b - 15.0)
        if len(j) and j[0] > 0:
            out.append((int(j[0]), f"{names[za]} → {names[zb]}\n15 m ahead"))
    return sorted(dict(out).items())


def trial(params, seed, ctx):
    G.single_thread()
    name, method = params["route"], params["method"]
    rec = G.route(name, G.QUICK_FRAMES if ctx.quick else None)
    z = zones_along(rec)
    t = rec.stack("t").astype(np.float64)
    settled = settled_mask(t, z["progress"], z["boundaries"])
    pics = _picture_frames(z, settled)
    run = G.run_vo(rec, method, seed, iou=True, keep_prob={i for i, _ in pics})
    iou = run["iou"]
    np.savez_compressed(ctx.out_dir / "iou.npz", t=t, iou=iou, progress=z["progress"], zone=z["zone"],
                        settled=settled, boundaries=z["boundaries"])
    _figures(ctx.out_dir, rec, run.get("prob", {}), pics, z, t, iou, settled, name, method)
    out = {"frames": len(rec), "length_m": float(z["progress"][-1] - z["progress"][0]),
           "n_boundaries": int(np.sum((z["boundaries"] > z["progress"][0]) & (z["boundaries"] < z["progress"][-1]))),
           "n_settled": int(settled.sum()),
           "iou_settled_mean": float(np.mean(iou[settled])) if settled.any() else float("nan"),
           "iou_settled_p10": float(np.percentile(iou[settled], 10)) if settled.any() else float("nan"),
           "iou_settled_min": float(np.min(iou[settled])) if settled.any() else float("nan"),
           "share_settled_ge_target": float(np.mean(iou[settled] >= TARGET_IOU)) if settled.any() else float("nan"),
           "n_settled_below_half": int(np.sum(iou[settled] < 0.5))}
    after = (t - t[0]) >= WARMUP_S
    out["iou_all_mean"] = float(np.mean(iou[after]))
    out["iou_all_min"] = float(np.min(iou[after]))
    trans = after & ~settled
    out["iou_transition_mean"] = float(np.mean(iou[trans])) if trans.any() else float("nan")
    out["iou_transition_min"] = float(np.min(iou[trans])) if trans.any() else float("nan")
    per_zone = {}
    for k, zn in enumerate(z["names"]):
        m = settled & (z["zone"] == k)
        if m.sum() >= 10:
            per_zone[zn] = float(np.mean(iou[m]))
    for zn in ("asphalt", "gravel", "grass", "dirt"):
        out[f"iou_{zn}"] = per_zone.get(zn, float("nan"))
    # Recovery: frames after a boundary passes under the camera until IoU is back at the target.
    rec_s = []
    for b in z["boundaries"]:
        j = np.flatnonzero(z["progress"] >= b)
        if len(j) and z["progress"][-1] > b + AFTER_M:
            k = j[0]
            back = np.flatnonzero(iou[k:] >= TARGET_IOU)
            rec_s.append(float(t[k + back[0]] - t[k]) if len(back) else float("inf"))
    out["recovery_s_max"] = float(max(rec_s)) if rec_s else float("nan")
    (ctx.out_dir / "zones.json").write_text(json.dumps({"names": z["names"], "boundaries_m": z["boundaries"].tolist(),
                                                        "boundary_zones": z["boundary_zones"], "pictures": pics,
                                                        "recovery_s": rec_s}))
    return out


def _figures(out_dir, rec, probs, pics, z, t, iou, settled, name, method):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # IoU over time with the boundaries and transition windows.
    fig, ax = plt.subplots(figsize=(10, 3.0))
    tt = t - t[0]
    ax.plot(tt, iou, lw=0.8, color="k")
    ax.plot(tt[~settled], np.where(settled, np.nan, iou)[~settled], ".", ms=1.5, color="tab:orange",
            label="warm-up / transition")
    prog = z["progress"]
    for b, (za, zb) in zip(z["boundaries"], z["boundary_zones"]):
        j = np.flatnonzero(prog >= b)
        if len(j) and b <= prog[-1]:
            ax.axvline(tt[j[0]], color="tab:red", lw=0.8)
            ax.text(tt[j[0]], 0.02, f" {z['names'][za]} → {z['names'][zb]}", fontsize=7, rotation=90, va="bottom")
        j0 = np.flatnonzero(prog >= b - BEFORE_M)
        if len(j0):
            ax.axvspan(tt[j0[0]], tt[j[0]] if len(j) else tt[-1], color="tab:red", alpha=0.08)
    ax.axhline(TARGET_IOU, color="tab:green", ls="--", lw=0.8, label=f"target {TARGET_IOU}")
    for i, _ in pics:
        ax.plot(tt[i], iou[i], "o", ms=4, mfc="none", color="tab:blue")
    ax.set_ylim(0, 1)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("classifier IoU")
    ax.set_title(f"{name}, {method}: ground-probability IoU against the true ground mask (red: zone boundary "
                 "under the camera; shaded: 40 m approach)", fontsize=8)
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_dir / "iou_over_time.png", dpi=110)
    plt.close(fig)
    # Probability maps: image | P(ground) | errors of the thresholded map.
    if not pics:
        return
    fig, axes = plt.subplots(len(pics), 3, figsize=(13, 1.45 * len(pics) + 0.4), squeeze=False)
    for row, (i, caption) in zip(axes, pics):
        f = rec[i]
        p = probs[i]
        gtm = f["ground_mask"]
        err = np.zeros(gtm.shape + (3,))
        err[(p > 0.5) & gtm] = (0.75, 0.75, 0.75)
        err[(p > 0.5) & ~gtm] = (0.85, 0.1, 0.1)
        err[(p <= 0.5) & gtm] = (0.1, 0.3, 0.9)
        row[0].imshow(f["rgb"])
        row[1].imshow(p, vmin=0, vmax=1, cmap="viridis")
        row[2].imshow(err)
        row[0].set_ylabel(f"t = {t[i] - t[0]:.0f} s\n{caption}", fontsize=7)
        row[2].set_ylabel(f"IoU {iou[i]:.2f}", fontsize=7)
        for a in row:
            a.set_xticks([])
            a.set_yticks([])
    axes[0, 0].set_title("camera image", fontsize=8)
    axes[0, 1].set_title("P(ground | colour)", fontsize=8)
    axes[0, 2].set_title("P > 0.5 vs truth: grey hit, red false ground, blue missed ground", fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "probability_maps.png", dpi=100)
    plt.close(fig)


COLS = ["route", "method", "frames", "length_m", "n_boundaries", "n_settled", "iou_settled_mean", "iou_settled_p10",
        "iou_settled_min", "share_settled_ge_target", "n_settled_below_half", "iou_transition_mean", "iou_transition_min", "iou_all_mean", "iou_asphalt", "iou_gravel",
        "iou_grass", "iou_dirt", "recovery_s_max"]


def summarize(table, ctx):
    out_dir, quick = ctx.out_dir, ctx.quick
    rows = sorted(table, key=lambda r: (r["route"], r["method"]))
    write_csv_table(rows, COLS, out_dir / "ground_appearance_table.csv")
    lines = [f"Classifier IoU (P(ground) > 0.5 against the true ground mask, whole image) on settled frames (≥ {WARMUP_S:.0f} s "
             f"after the start, outside [−{BEFORE_M:.0f} m, +{AFTER_M:.0f} m] of each zone boundary), in the transition "
             "windows, per zone (settled), and the longest time after a boundary passes under the camera until IoU is "
             f"back at {TARGET_IOU}.", "", markdown_table(rows, COLS), "",
             "Figures per trial: `trials/*/iou_over_time.png`, `trials/*/probability_maps.png`. "
             "Table: `ground_appearance_table.csv`."]
    return "\n".join(lines)


def checks(table, ctx):
    quick = ctx.quick
    out = []
    for r in sorted(table, key=lambda r: (r["route"], r["method"])):
        if r["method"] != "w6":
            continue
        v = r["iou_settled_mean"]
        out.append(Check(f"w6 classifier IoU ≥ {TARGET_IOU} once settled ({r['route']}" + (", quick" if quick else "") + ")",
                         bool(v >= TARGET_IOU), f"mean {v:.3f}, p10 {r['iou_settled_p10']:.3f} over {r['n_settled']} frames"))
    return out


EXPERIMENT = Experiment(
    name="ground_appearance",
    description="ground classifier IoU over time as the ground texture changes along the route (4 zones)",
    grid={"route": ["terrain_00", "terrain_04", "flat_00", "flat_02"], "method": ["w6", "u6"]},
    splits={"dev": {"seeds": [0]}},
    sizes={"quick": {"n_seeds": 1, "grid": {"route": [G.QUICK_ROUTE], "method": ["w6"]}}, "full": {}},
    trial=trial,
    summarize=summarize,
    checks=checks,
)
