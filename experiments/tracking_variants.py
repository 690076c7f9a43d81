"""tracking_variants: pose and mask success of the appearance variants, per sequence and object; speed.

The colour Naive Bayes ``h`` and the four feature heads (S/W x u/w, spec 4) on every sequence of the
split, 640x480 with Kinect-like depth noise, started from the true first pose and never
re-initialised (spec 7.3). A frame succeeds if ADD(-S) < 0.1 x the object's diameter (ADD-S for the
revolved can and bottle; the strict ADD is reported beside it) and if IoU(mask, true visible mask)
> 0.5. ``dev`` pools the 16 tuning sequences (the 4 ``dev_appearance`` ones are listed beside them);
``test`` is the held-out suite. Speed: process CPU time per ``process()`` call, single-threaded,
first frame left out; its dependence on the object's image size is fitted over all frames.
"""

from __future__ import annotations

import numpy as np

from polar_sim import metrics
from polar_sim.runner import Check, Experiment, Finding
from polar_sim.runner.report import fmt, markdown_table, percent, write_csv_table

from polar_sim.experiments import _tracking_common as C
from polar_sim.experiments import _tracking_tables as T
from polar_sim.experiments import _tracking_pictures as pictures

#: ICG (Stoiber et al., CVPR 2022): 1.3 ms per frame on one CPU core.
ICG_MS = 1.3
#: distinct = asymmetric and non-convex; cuboid = flat faces; revolved = symmetric about an axis
SHAPE = {"drill": "distinct", "mug": "distinct", "bracket": "distinct", "blocks": "distinct", "box": "cuboid",
         "cube": "cuboid", "bottle": "revolved", "can": "revolved"}
SHAPE_NOT_TESTED = ("distinctness of shape is not measured (the summary's shape labels are set by hand; the objects "
                    "record only whether they are revolved, which makes the score ADD-S, so those groups are not "
                    "comparable)")


def _ref(table):
    """The method the checks and per-sequence figures are about: ww, or the only one run."""
    methods = list(dict.fromkeys(r["method"] for r in table))
    return "ww" if "ww" in methods else methods[0]


def _size_rows(table):
    """Fig. 5.8: one row per sequence of ww (not pooled over variants), with the object's size and
    shape, and the Spearman correlation of diameter with ADD(-S) AUC over them (NaN when undefined)."""
    rows = [{"sequence": r["sequence"], "object": r["object"], "diameter_cm": r["diameter_cm"],
             "shape": SHAPE.get(r["object"], "?"), "symmetry": r["symmetry"], "add_ok": r["add_ok"],
             "add_auc": r["add_auc"], "iou_ok": r["iou_ok"]} for r in T.by(table, "method", _ref(table))]
    rows = sorted(rows, key=lambda r: -r["diameter_cm"])
    return rows, metrics.spearman(T.col(rows, "diameter_cm"), T.col(rows, "add_auc"))


def summarize(table, ctx):
    head = T.group(table, ctx.split)
    methods = list(dict.fromkeys(r["method"] for r in table))
    vrows = T.rate_rows(head, "method", [m for m in C.VARIANTS if m in methods] + [m for m in methods if m not in C.VARIANTS])
    cols = ["method", "sequences", "frames", "add_ok", "add_ok_seqmin", "add_strict_ok", "add_auc", "s5cm5deg",
            "iou_ok", "iou_mean", "hand_as_target", "drift_deg_max", "lost", "cpu_ms_median"]
    write_csv_table(vrows, cols, ctx.out_dir / "tracking_variants_table.csv")
    seqs = list(dict.fromkeys(r["sequence"] for r in table))
    prow = [{"sequence": s, "object": T.by(table, "sequence", s)[0]["object"],
             "appearance": T.by(table, "sequence", s)[0]["appearance"],
             **{f"add_{r['method']}": r["add_ok"] for r in T.by(table, "sequence", s)},
             **{f"iou_{r['method']}": r["iou_ok"] for r in T.by(table, "sequence", s)}} for s in seqs]
    pcols = ["sequence", "object", "appearance"] + [f"{m}_{v}" for m in ("add", "iou") for v in C.VARIANTS
                                                    if any(f"{m}_{v}" in p for p in prow)]
    write_csv_table(prow, pcols, ctx.out_dir / "tracking_variants_sequences.csv")
    srows, rho = _size_rows(table)
    cost = T.cost_vs_size(table, ctx, _ref(table))
    lines = [f"Split **{ctx.split}**, {len(seqs)} sequences at {table[0]['width']} px wide, seeds "
             f"{sorted({r['seed'] for r in table})}. The pooled rows use {len({r['sequence'] for r in head})} "
             "sequences (on dev the 16 of every earlier run). `add_ok`: ADD(-S) < 0.1 d over all frames; "
             "`add_ok_seqmin`: the lowest sequence; `drift_deg_max`: the largest rotation drift of the object "
             "while at rest (300-frame windows).", "", markdown_table(vrows, cols), "",
             "### Per sequence", "", markdown_table(prow, pcols), "",
             "### Object size and shape (ww, one point per sequence, as Fig. 5.8)", "",
             markdown_table(srows, list(srows[0])), "",
             f"Spearman correlation of diameter with ADD(-S) AUC over the {len(srows)} sequences: {fmt(rho)}"
             + ("." if np.isfinite(rho) else " (undefined for fewer than 3 sequences or a constant input)."), "",
             "### Speed", "",
             f"{_ref(table)}, {cost['frames']} frames: CPU ms per frame median {cost['q'][0]:.1f}, 95th percentile "
             f"{cost['q'][1]:.1f} ({1000 / cost['q'][0]:.0f} frames/s; ICG takes {ICG_MS} ms). Spearman "
             f"correlation with the object's pixels {fmt(cost['rho_target'])}, with the ROI's {fmt(cost['rho_roi'])}; "
             f"fit {cost['icpt']:.1f} ms + {cost['slope']:.2f} ms per 10,000 object pixels.", ""]
    figs = pictures.variants_figures(head, ctx, [r["method"] for r in vrows], srows, cost, _ref(table))
    return "\n".join(lines + figs)


def checks(table, ctx):
    head, m = T.group(table, ctx.split), _ref(table)
    ww = next(r for r in T.rate_rows(head, "method", [m]))
    out = [Check(f"{m}: ADD(-S) < 0.1 d on >= 95 % of frames", ww["add_ok"] >= 0.95,
                 f"{100 * ww['add_ok']:.1f} % (lowest sequence {100 * ww['add_ok_seqmin']:.1f} %)"),
           Check(f"{m}: IoU > 0.5 on >= 95 % of frames", ww["iou_ok"] >= 0.95, f"{100 * ww['iou_ok']:.1f} %")]
    if ctx.params["span"] == "all":   # the 300-frame rests are in the whole sequences, not the CI cuts
        out.append(Check(f"{m}: an object at rest drifts <= 2 deg in rotation over 300 frames",
                         ww["drift_deg_max"] <= 2.0, f"largest drift {ww['drift_deg_max']:.2f} deg"))
        # met since issue 35 (benchmarks/RESULTS.md, test split): the rest-gated dead zone holds the mug under
        # the palm (4.52 -> 1.01 deg) and the confident gate keeps blocks_push_gloved through its push
    if (ctx.params["width"], ctx.params["height"]) == (640, 480):   # the speed target is set at 640x480
        ms = ww["cpu_ms_median"]
        out.append(Check(f"{m} >= 30 frames/s at 640x480 on one thread (CPU time)", 1000 / ms >= 30,
                         f"{1000 / ms:.0f} frames/s ({ms:.1f} ms, median of the sequences' medians)", timing=True))
    return out


def findings(table, ctx):
    vr = T.rate_rows(T.group(table, ctx.split), "method", ["su", "sw", "wu", "ww"])
    if len(vr) < 4:
        return []
    lo, hi = min(r["add_ok"] for r in vr), max(r["add_ok"] for r in vr)
    srows, rho = _size_rows(table)
    n, ok = len(srows), bool(np.isfinite(rho))
    size = f"Spearman(diameter, ADD(-S) AUC) = {fmt(rho)} over {n} sequences" if ok else (
        f"Spearman(diameter, ADD(-S) AUC) undefined over {n} sequences ({len(set(T.col(srows, 'diameter_cm')))} "
        f"diameters, {len(set(T.col(srows, 'add_auc')))} AUC values)")
    frames, seqs = vr[0]["frames"], vr[0]["sequences"]
    ceiling = f"every variant at {percent(hi)}" if lo >= 0.999 else f"every variant at {percent(lo)}" if hi <= 0.001 else ""
    return [Finding("Ch. 5, Fig. 5.6", "the four implementations perform similarly",
                    f"ADD(-S) < 0.1 d {percent(lo)} to {percent(hi)} over Su, Sw, Wu, Ww ({ctx.split})",
                    "held" if hi - lo <= 0.03 else "partly held",
                    "simulated tabletop sequences, hand-crafted multi-scale features instead of a CNN",
                    n=int(frames), n_of=f"frames of {seqs} sequence{'s' if seqs != 1 else ''}", saturated=ceiling),
            Finding("Ch. 5, Fig. 5.8", "larger objects of distinct shape show higher success rates",
                    f"Ww, one point per sequence: {size}; shape not tested",
                    ("held" if rho > 0.3 else "partly held" if rho > 0 else "not held") if ok
                    else "not tested the same way",
                    ("the verdict is on size alone; " if ok else "a rank correlation needs >= 3 sequences of "
                     "different diameters and AUCs, so this run does not test size; ") + SHAPE_NOT_TESTED +
                    "; per sequence for Ww, as in Fig. 5.8; simulated meshes")]


EXPERIMENT = Experiment(
    name="tracking_variants",
    description="pose and mask success of the appearance variants (H, Su, Sw, Wu, Ww) per sequence, object "
                "size and shape, and speed at 640x480",
    grid={"sequence": C.DEV, "method": C.VARIANTS},
    methods={"method": "tracker"},
    choices=C.CHOICES,
    params=C.PARAMS,
    splits=C.SPLITS,
    sizes=C.SIZES,
    trial=C.trial, summarize=summarize, checks=checks, findings=findings,
)
