"""tracking_segmentation: 2D target segmentation, the hand under touch, and the calibration of P(target).

Segmentation success by IoU (thesis Fig. 5.7: the fraction of frames whose mask IoU with the truth
exceeds a threshold, headline 0.5) for the colour baseline ``h``, the four feature variants and the
shape-only reference (appearance term off); the direct measure of "occlusion by touch": the
fraction of hand pixels (within 15 px of the object's full silhouette, at 640 wide) labelled target
while the hand touches it; and the calibration of ``TrackResult.prob``, P(target), against the true
visible mask over the ROI pixels: expected calibration error (15 bins) and a reliability diagram,
for the calibrated map and for the raw prediction map (``prob_raw``). The calibration is learned
from the tracker's own labels, never from truth. These runs are ``tracking_variants``' (memoised).
"""

from __future__ import annotations

import numpy as np

from polar_sim import metrics
from polar_sim.runner import Check, Experiment, Finding
from polar_sim.runner.pictures_calibration import plot_reliability
from polar_sim.runner.report import markdown_table, percent, savefig, write_csv_table

from polar_sim.experiments import _tracking_common as C
from polar_sim.experiments import _tracking_tables as T
from polar_sim.experiments import _tracking_pictures as pictures

ORDER = C.VARIANTS + ["shape-only"]
HAND_MAX, ECE_MAX = 0.05, 0.05


def _bins(rows, ctx, key):
    return np.sum([ctx.arrays(r)[key].sum(axis=0) for r in rows], axis=0)


def _ref(table):
    """The method the checks, the reliability plot and the finding are about: ww, or the first run."""
    methods = list(dict.fromkeys(r["method"] for r in table))
    return "ww" if "ww" in methods else next((m for m in ORDER if m in methods), methods[0])


def _rows(table, ctx):
    out = []
    methods = list(dict.fromkeys(r["method"] for r in table))
    for r in T.rate_rows(table, "method", ORDER + [m for m in methods if m not in ORDER]):
        rs = T.by(table, "method", r["method"])
        worst = max((x for x in rs if x["hand_px_touch"]), key=lambda x: x["hand_as_target"], default=None)
        out.append({**{k: r[k] for k in ("method", "sequences", "frames", "iou_ok", "iou_mean", "occl_frames",
                                         "occl_iou_ok", "hand_as_target")},
                    "precision": T.pooled(rs, "precision"), "recall": T.pooled(rs, "recall"),
                    "hand_worst": f"{worst['sequence']} {100 * worst['hand_as_target']:.1f} %" if worst else "",
                    "ece": metrics.pooled_ece(_bins(rs, ctx, "cal_bins")), "ece_raw": metrics.pooled_ece(_bins(rs, ctx, "raw_bins"))})
    return out


def summarize(table, ctx):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    head, ref = T.group(table, ctx.split), _ref(table)
    rows = _rows(head, ctx)
    cols = list(rows[0])
    write_csv_table(rows, cols, ctx.out_dir / "tracking_segmentation_table.csv")
    seqs = list(dict.fromkeys(r["sequence"] for r in table))
    hrows = [{"sequence": s, "touch_frames": T.by(table, "sequence", s)[0]["touch_frames"],
              **{r["method"]: r["hand_as_target"] for r in T.by(table, "sequence", s)},
              **{f"ece_{r['method']}": r["ece"] for r in T.by(table, "sequence", s)}} for s in seqs]
    hcols = ["sequence", "touch_frames"] + [r["method"] for r in rows] + [f"ece_{ref}"]
    write_csv_table(hrows, hcols, ctx.out_dir / "tracking_segmentation_sequences.csv")
    lines = [f"Split **{ctx.split}**, pooled over {len({r['sequence'] for r in head})} sequences. `iou_ok`: IoU > 0.5; "
             f"`occl_iou_ok`: the same on the frames of occlusion by touch (the hand touches the object and hides "
             f"more than {100 * T.TOUCH_OCCLUSION:.0f} % of it); `hand_as_target`: hand pixels labelled target while "
             "touching; `ece`: expected calibration error (15 bins) of P(target) over the ROI pixels against the "
             "true visible mask, `ece_raw` the same for the uncalibrated prediction map. `shape-only` is a "
             "reference, not a variant.", "", markdown_table(rows, cols), "",
             "### Hand labelled target while touching, and ECE, per sequence", "", markdown_table(hrows, hcols), ""]
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.4))
    run = [r["method"] for r in rows]
    pictures.success_curves(head, ctx, run, ax_iou=ax[0])
    w = 0.8 / len(run)
    for k, v in enumerate(run):
        ax[1].bar(np.arange(len(hrows)) + (k - len(run) / 2 + 0.5) * w, [100 * (h.get(v) or np.nan) for h in hrows],
                  w, label=v)
    ax[1].axhline(100 * HAND_MAX, color="k", lw=0.8, ls=":")
    ax[1].set_xticks(range(len(hrows)), [h["sequence"] for h in hrows], rotation=70, ha="right", fontsize=6)
    ax[1].set(ylabel="% of hand pixels labelled target", title="the hand while touching")
    ax[1].legend(fontsize=7, ncol=2)
    ww = T.by(head, "method", ref)
    rels = [_bins(ww, ctx, k) for k in ("cal_bins", "raw_bins")]
    if all(b[0].sum() for b in rels):   # a method without a P(target) map has no reliability diagram
        plot_reliability([metrics.pooled_reliability(*b) for b in rels],
                         ["P(target), calibrated", "raw prediction map"], ax=ax[2],
                         title=f"{ref}, ROI pixels ({ctx.split})")
    fig.tight_layout()
    return "\n".join(lines + [savefig(fig, ctx.out_dir, "tracking_segmentation")])


def checks(table, ctx):
    m = _ref(table)
    r = next(x for x in _rows(T.group(table, ctx.split), ctx) if x["method"] == m)
    return [Check(f"{m}: IoU > 0.5 on >= 95 % of frames", r["iou_ok"] >= 0.95, f"{100 * r['iou_ok']:.1f} %"),
            Check(f"{m}: <= 5 % of hand pixels labelled target while touching", r["hand_as_target"] <= HAND_MAX,
                  f"{100 * r['hand_as_target']:.2f} % (worst sequence {r['hand_worst']})"),
            Check(f"{m}: ECE of P(target) <= 0.05 (ROI pixels, 15 bins)", r["ece"] <= ECE_MAX,
                  f"{r['ece']:.3f} (raw prediction map {r['ece_raw']:.3f})")]


def findings(table, ctx):
    rows = {r["method"]: r for r in _rows(T.group(table, ctx.split), ctx)}
    if "ww" not in rows:
        return []   # the finding is about the thesis's Ww
    w, s = rows["ww"], rows.get("shape-only")
    ours = (f"Ww under touch: IoU > 0.5 on {percent(w['occl_iou_ok'])} of {w['occl_frames']} frames, hand labelled "
            f"target {percent(w['hand_as_target'])}" + (f" (shape only: {percent(s['occl_iou_ok'])}, "
                                                          f"{percent(s['hand_as_target'])})" if s else ""))
    ok = w["occl_iou_ok"] >= 0.9 and w["hand_as_target"] <= HAND_MAX
    return [Finding("Ch. 1-2, Ch. 5 (Fig. 5.7)", "accurate segmentation under occlusion by touch", ours,
                    "held" if ok else "partly held", "a scripted simulated hand; IoU success at 0.5",
                    n=int(w["occl_frames"]), n_of="frames under touch")]


EXPERIMENT = Experiment(
    name="tracking_segmentation",
    description="2D segmentation success by IoU, the hand labelled target under touch, and the calibration "
                "(ECE, reliability) of P(target)",
    grid={"sequence": C.DEV, "method": ORDER},
    methods={"method": "tracker"},
    choices=C.CHOICES,
    params=C.PARAMS,
    splits=C.SPLITS,
    sizes=C.SIZES,
    trial=C.trial, summarize=summarize, checks=checks, findings=findings,
)
