"""tracking_ablation: what each part of the tracker buys, and the plain-ICP baseline under touch.

The full method (``ww``, every default) beside configurations that switch one part (spec 7.4):
``shape-only`` (appearance off), ``no-motion`` (the prediction is the last pose), ``spatial-prior``
(the blurred predicted silhouette as the prior pi, the spec's form with epsilon 0.02; off by default,
as chosen on dev) and ``spatial-prior-0.1`` (the same prior softened to epsilon 0.1),
``alpha-beta`` (the spec's fallback filter), ``no-hold`` (velocity integrated along directions the
points do not constrain, the tracker's earlier behaviour) and ``plain-icp`` (robust ICP on every ROI point, no
appearance, no label weighting). Not run: oracle-mask ICP, appearance without shape and learned
visibility (no such switch), and ICG/M3T (not installable here).

The headline check: **under occlusion by touch every variant beats plain ICP** (frames where the
hand touches or holds the object and hides more than 5 % of it; pooled ADD(-S) < 0.1 d and IoU > 0.5
success both higher). The variants' runs are shared with ``tracking_variants`` (memoised).
"""

from __future__ import annotations

import numpy as np

from polar_sim.runner import Check, Experiment, Finding
from polar_sim.runner.report import markdown_table, percent, savefig, write_csv_table

from polar_sim.experiments import _tracking_common as C
from polar_sim.experiments import _tracking_tables as T

ABLATIONS = ["shape-only", "no-motion", "spatial-prior", "spatial-prior-0.1", "alpha-beta", "no-hold", "plain-icp"]
ORDER = C.VARIANTS + ABLATIONS


def trial(params, seed, ctx):
    return {**C.trial(params, seed, ctx), "what": "ablation" if params["method"] in ABLATIONS else "variant"}


def summarize(table, ctx):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    head = T.group(table, ctx.split)
    methods = list(dict.fromkeys(r["method"] for r in table))
    rows = T.rate_rows(head, "method", ORDER + [m for m in methods if m not in ORDER])
    cols = ["method", "frames", "add_ok", "add_auc", "iou_ok", "iou_mean", "occl_frames", "occl_add_ok", "occl_iou_ok",
            "hand_as_target", "drift_deg_max", "lost", "cpu_ms_median"]
    write_csv_table(rows, cols, ctx.out_dir / "tracking_ablation_table.csv")
    prow = []
    for s in dict.fromkeys(r["sequence"] for r in table):
        rs = T.by(table, "sequence", s)
        prow.append({"sequence": s, "occl_frames": rs[0]["occl_frames"],
                     **{r["method"]: f"{100 * r['add_ok']:.0f} / {100 * r['iou_ok']:.0f}" for r in rs}})
    pcols = ["sequence", "occl_frames"] + [r["method"] for r in rows]
    write_csv_table(prow, pcols, ctx.out_dir / "tracking_ablation_sequences.csv")
    lines = [f"Split **{ctx.split}**, pooled over {len({r['sequence'] for r in head})} sequences. `occl_*`: rates on "
             f"the {rows[0]['occl_frames']} frames of occlusion by touch; `drift_deg_max`: the largest rotation drift "
             "of the object at rest; `cpu_ms_median`: the median of the sequences' median CPU ms per frame.", "",
             markdown_table(rows, cols), "", "### Per sequence: ADD(-S) < 0.1 d % / IoU > 0.5 %", "",
             markdown_table(prow, pcols), ""]
    fig, ax = plt.subplots(figsize=(11, 3.8))
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [100 * r["occl_add_ok"] for r in rows], 0.4, label="ADD(-S) < 0.1 d")
    ax.bar(x + 0.2, [100 * r["occl_iou_ok"] for r in rows], 0.4, label="IoU > 0.5")
    ax.set_xticks(x, [r["method"] for r in rows], rotation=30, ha="right")
    ax.set(ylabel="% of frames", title=f"success under occlusion by touch ({ctx.split}, all sequences pooled)",
           ylim=(0, 105))
    ax.axvline(sum(r["method"] in C.VARIANTS for r in rows) - 0.5, color="k", lw=0.6)
    ax.legend(fontsize=8, loc="lower left")
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    return "\n".join(lines + [savefig(fig, ctx.out_dir, "tracking_ablation")])


def _beats(table, ctx):
    """Whether each variant run beats plain ICP under touch; None without plain ICP or any variant."""
    rows = {r["method"]: r for r in T.rate_rows(T.group(table, ctx.split), "method", ORDER)}
    if "plain-icp" not in rows or not any(v in rows for v in C.VARIANTS):
        return rows, None, ""
    p = rows["plain-icp"]
    beat = {v: rows[v]["occl_add_ok"] > p["occl_add_ok"] and rows[v]["occl_iou_ok"] > p["occl_iou_ok"]
            for v in C.VARIANTS if v in rows}
    pair = lambda r: f"{percent(r['occl_add_ok'])} / {percent(r['occl_iou_ok'])}"  # noqa: E731
    detail = ", ".join(f"{v} {pair(rows[v])}" for v in beat)
    return rows, beat, f"{detail}; plain ICP {pair(p)} ({p['occl_frames']} frames)"


def checks(table, ctx):
    _, beat, detail = _beats(table, ctx)
    if beat is None:
        return []   # a run without plain ICP or without a variant has nothing to compare
    which = "every variant" if len(beat) == len(C.VARIANTS) else f"every variant run ({', '.join(beat)})"
    return [Check(f"under occlusion by touch {which} beats plain ICP (ADD(-S) < 0.1 d and IoU > 0.5, %)",
                  all(beat.values()), detail)]


def findings(table, ctx):
    rows, beat, detail = _beats(table, ctx)
    if beat is None or "ww" not in rows or "shape-only" not in rows:
        return []
    w, s = rows["ww"], rows["shape-only"]
    top = min(w["occl_add_ok"], w["occl_iou_ok"], s["occl_add_ok"], s["occl_iou_ok"]) >= 0.999
    return [Finding("Ch. 1-2 (the learned appearance handles touch)", "the online appearance model is what keeps "
                    "the track under occlusion by touch",
                    f"under touch ADD / IoU success: ww {percent(w['occl_add_ok'])} / {percent(w['occl_iou_ok'])}, "
                    f"shape only {percent(s['occl_add_ok'])} / {percent(s['occl_iou_ok'])}; {detail}",
                    "held" if all(beat.values()) and w["occl_iou_ok"] > s["occl_iou_ok"] else "partly held",
                    "our ablation; the thesis gives no ablation numbers", n=int(w["occl_frames"]),
                    n_of="frames under touch", saturated="ww and shape only both at 100 %" if top else "")]


EXPERIMENT = Experiment(
    name="tracking_ablation",
    description="ablations of the tracker (appearance off, motion prior off, the silhouette prior on, alpha-beta, "
                "no hold of unobserved directions, plain ICP) against the variants, under occlusion by touch",
    grid={"sequence": C.DEV, "method": ORDER},
    methods={"method": "tracker"},
    choices=C.CHOICES,
    params=C.PARAMS,
    splits=C.SPLITS,
    sizes=C.SIZES,
    trial=trial, summarize=summarize, checks=checks, findings=findings,
)
