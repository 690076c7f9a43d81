"""tracking_segmentation: 2D target segmentation of the tracker, and the hand under touch.

Issue 6, item 4: 2D segmentation success by IoU (thesis Fig. 5.7: the fraction of frames whose mask
IoU with the truth exceeds a threshold, headline 0.5) for the colour baseline ``h`` and the four
feature variants, on the 16 ``tabletop`` sequences (seed 0, 640x480, noisy depth); and the direct
measure of "occlusion by touch": the fraction of hand pixels the tracker labels as target while the
hand touches (or holds) the object. The shape-only tracker (appearance term off) is run beside them
as the reference for what the learned appearance adds.

The mask scored is ``TrackResult.mask`` (O = 1 plus undecided pixels without depth inside the
registered silhouette that the appearance model calls target); the truth is the rendered visible
mask. A frame where the tracker is lost has an empty mask. Hand pixels are counted within 15 px
(at 640 wide) of the object's full silhouette, so a large hand elsewhere in the image does not
dilute the figure; they are pooled over every frame in which the hand touches the object.

These runs are the same as ``tracking_variants``' (memoised: see ``_tracking_common.track``).
The CI size (``--quick``) uses the same 320x240 cuts of ``mug_touch`` and ``drill_lift``.
"""

from __future__ import annotations

import numpy as np

from polar_sim.runner import Check, Experiment
from polar_sim.runner.report import markdown_table, savefig, write_csv_table

try:  # the registry imports this module as polar_sim.experiments.tracking_segmentation
    from polar_sim.experiments import _tracking_common as C
except ImportError:  # pragma: no cover
    import _tracking_common as C

VARIANT_ORDER = ["h", "su", "sw", "wu", "ww"]
ORDER = VARIANT_ORDER + ["shape-only"]
#: Hand-pixel target of issue 6, while touching.
HAND_MAX = 0.05


def trial(params, seed, ctx):
    a, meta = C.track(params["sequence"], seed, params["variant"], quick=ctx.quick)
    C.save_frames(ctx, params["sequence"], params["variant"], a, meta)
    return C.summarize_run(a, meta)


def _seg_rows(table):
    rows = []
    for v in ORDER:
        rs = C.by(table, "variant", v)
        if not rs:
            continue
        hn = sum(r["hand_px_touch"] for r in rs)
        ht = sum(r["hand_tgt_px_touch"] for r in rs)
        worst = max((r for r in rs if r["hand_px_touch"]), key=lambda r: r["hand_as_target"] or 0.0, default=None)
        rows.append({"variant": v, "sequences": len(rs), "frames": int(sum(r["frames"] for r in rs)),
                     "iou_ok": C.pooled(rs, "iou_ok"), "iou_ok_seqmean": float(np.mean([r["iou_ok"] for r in rs])),
                     "iou_ok_seqmin": float(np.min([r["iou_ok"] for r in rs])),
                     "iou_mean": C.pooled(rs, "iou_mean"), "iou_auc": C.pooled(rs, "iou_auc"),
                     "precision": C.pooled(rs, "precision"), "recall": C.pooled(rs, "recall"),
                     "touch_frames": int(sum(r["touch_frames"] for r in rs)), "hand_px": int(hn),
                     "hand_as_target": ht / hn if hn else float("nan"),
                     "hand_worst_seq": f"{worst['sequence']} {100 * worst['hand_as_target']:.1f} %" if worst else "",
                     "occl_iou_ok": C.pooled(rs, "occl_iou_ok", "occl_frames"), "lost": int(sum(r["lost"] for r in rs))})
    return rows


def summarize(table, ctx):
    out_dir, quick = ctx.out_dir, ctx.quick
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = C.load_frames(out_dir)
    rows = _seg_rows(table)
    best = C.best_of(C.rate_rows(table, "variant", VARIANT_ORDER), "variant")
    cols = ["variant", "sequences", "frames", "iou_ok", "iou_ok_seqmean", "iou_ok_seqmin", "iou_mean", "iou_auc",
            "precision", "recall", "occl_iou_ok", "touch_frames", "hand_px", "hand_as_target", "hand_worst_seq", "lost"]
    write_csv_table(rows, cols, out_dir / "tracking_segmentation_table.csv")
    size = f"{table[0]['width']}x{table[0]['height']}"
    lines = [f"{len({r['sequence'] for r in table})} sequences at {size}, seed {sorted({r['seed'] for r in table})}. "
             "`iou_ok`: IoU > 0.5 over all frames pooled (`_seqmean`, `_seqmin`: mean and lowest per-sequence rate); "
             "`iou_auc`: mean of the IoU success curve over thresholds 0-1; precision and recall pooled over "
             "pixels; `occl_iou_ok`: IoU > 0.5 on the frames where the hand touches the object and hides more "
             f"than {100 * C.TOUCH_OCCLUSION:.0f} % of it; `hand_as_target`: hand pixels (within 15 px of the "
             "object) labelled target, pooled over the frames in which the hand touches the object; "
             "`hand_worst_seq`: the sequence where that fraction is highest. `shape-only` (appearance "
             f"term off) is a reference, not a variant. Best variant (as in `tracking_variants`): **{best}**.", "",
             markdown_table(rows, cols), ""]
    # hand pixels per touching sequence
    seqs = [s for s in C.SEQUENCE_ORDER if any(r["sequence"] == s and r["touch_frames"] for r in table)]
    hrows = []
    for s in seqs:
        d = {"sequence": s, "touch_frames": C.by(table, "sequence", s)[0]["touch_frames"]}
        for v in ORDER:
            r = next((r for r in C.by(table, "sequence", s) if r["variant"] == v), None)
            if r is not None:
                d[v] = r["hand_as_target"]
        hrows.append(d)
    hcols = ["sequence", "touch_frames"] + [v for v in ORDER if any(v in h for h in hrows)]
    write_csv_table(hrows, hcols, out_dir / "tracking_segmentation_hand.csv")
    lines += ["### Hand pixels labelled target while touching, per sequence", "", markdown_table(hrows, hcols), ""]
    irows = []
    for s in [s for s in C.SEQUENCE_ORDER if any(r["sequence"] == s for r in table)]:
        d = {"sequence": s}
        for v in ORDER:
            r = next((r for r in C.by(table, "sequence", s) if r["variant"] == v), None)
            if r is not None:
                d[f"iou_ok_{v}"], d[f"iou_mean_{v}"] = r["iou_ok"], r["iou_mean"]
        irows.append(d)
    icols = ["sequence"] + [f"iou_ok_{v}" for v in ORDER if any(f"iou_ok_{v}" in r for r in irows)]
    write_csv_table(irows, icols + [f"iou_mean_{v}" for v in ORDER], out_dir / "tracking_segmentation_sequences.csv")
    lines += ["### IoU > 0.5 per sequence", "", markdown_table(irows, icols), ""]
    # figure: IoU success curves; hand fraction per sequence
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    tt = np.linspace(0, 1, 101)
    for v in ORDER:
        u = [f["iou"] for (s, c), f in frames.items() if c == v]
        if u:
            u = np.concatenate(u)
            axes[0].plot(tt, [(u > t).mean() for t in tt], label=v, ls="--" if v == "shape-only" else "-")
    axes[0].axvline(0.5, color="k", lw=0.6, ls=":")
    axes[0].set(xlabel="IoU threshold", ylabel="fraction of frames with IoU > threshold",
                title="2D segmentation success, all frames")
    axes[0].legend(fontsize=8)
    axes[0].grid(alpha=0.3)
    ax = axes[1]
    wid = 0.8 / len(ORDER)
    for k, v in enumerate(ORDER):
        vals = [100 * (h.get(v) if h.get(v) is not None else np.nan) for h in hrows]
        ax.bar(np.arange(len(hrows)) + (k - len(ORDER) / 2 + 0.5) * wid, vals, wid, label=v)
    ax.axhline(100 * HAND_MAX, color="k", lw=0.8, ls=":")
    ax.set_xticks(range(len(hrows)), [h["sequence"] for h in hrows], rotation=60, ha="right", fontsize=7)
    ax.set(ylabel="% of hand pixels labelled target", title="hand labelled target while touching")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    lines += [savefig(fig, out_dir, "tracking_segmentation"), "",
              "Tables: `tracking_segmentation_table.csv`, `tracking_segmentation_hand.csv`, "
              "`tracking_segmentation_sequences.csv`."]
    return "\n".join(lines)


def checks(table, ctx):
    quick = ctx.quick
    rows = {r["variant"]: r for r in _seg_rows(table)}
    best = C.best_of(C.rate_rows(table, "variant", VARIANT_ORDER), "variant")
    b = rows[best]
    worst_v = max(VARIANT_ORDER, key=lambda v: rows[v]["hand_as_target"] if v in rows else -1)
    return [
        Check(f"best variant ({best}): IoU > 0.5 on >= 95 % of frames (pooled and per-sequence mean)",
              b["iou_ok"] >= 0.95 and b["iou_ok_seqmean"] >= 0.95,
              f"pooled {100 * b['iou_ok']:.1f} %, per-sequence mean {100 * b['iou_ok_seqmean']:.1f} %, "
              f"lowest sequence {100 * b['iou_ok_seqmin']:.1f} %"),
        Check(f"best variant ({best}): <= 5 % of hand pixels labelled target while touching",
              b["hand_as_target"] <= HAND_MAX,
              f"{100 * b['hand_as_target']:.2f} % of {b['hand_px']} hand pixels over {b['touch_frames']} touching "
              f"frames (worst sequence {b['hand_worst_seq']}); highest variant {worst_v} "
              f"{100 * rows[worst_v]['hand_as_target']:.2f} %"),
    ]


EXPERIMENT = Experiment(
    name="tracking_segmentation",
    description="2D segmentation success by IoU of the appearance variants on the tabletop sequences, and the "
                "hand pixels labelled target while touching",
    grid={"sequence": list(C.SEQUENCE_ORDER), "variant": ORDER},
    splits={"dev": {"seeds": [0]}},
    sizes={"quick": {"n_seeds": 1, "grid": {"sequence": list(C.QUICK_CUTS), "variant": ORDER}}, "full": {}},
    trial=trial,
    summarize=summarize,
    checks=checks,
)
