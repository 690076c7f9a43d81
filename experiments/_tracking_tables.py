"""Tables of the tracking experiments: one result row per tracked run, and rows pooled over runs.

Not an experiment (the underscore keeps it out of the registry). :func:`summarize_run` reduces the
per-frame arrays of :func:`_tracking_common.track` to one row with :mod:`polar_sim.metrics`;
:func:`rate_rows` pools such rows (per method, say) into the rates over all their frames;
:func:`cost_vs_size` fits the CPU time per frame against the object's image size.
"""

from __future__ import annotations

import numpy as np

from polar_sim import metrics
from polar_sim.sim.recorders.tabletop_sequences import list_sequences

#: "Occlusion by touch": the hand touches or holds the target and hides more than 5 % of it.
TOUCH_OCCLUSION = 0.05


def summarize_run(a, meta):
    """One result row from the per-frame arrays ``a`` of a run and its ``meta`` (object, diameter, ...)."""
    d, iou = meta["diameter"], a["iou"]
    e = a["adds"] if meta["symmetry"] != "none" else a["add"]   # ADD(-S): ADD-S for revolved objects
    touch = a["in_contact"] & (a["occlusion"] > TOUCH_OCCLUSION)
    cpu = a["cpu_ms"][1:] if len(a["cpu_ms"]) > 1 else a["cpu_ms"]   # first frame: JIT and caches
    hn, ht = a["hand_near"][a["in_contact"]].sum(), a["hand_near_tgt"][a["in_contact"]].sum()
    precision, recall = metrics.pooled_precision_recall(a["n_tp"], a["n_pred"], a["n_gt"])
    drift = metrics.static_rotation_drift(a["pose_gt"], a["pose"])
    return {
        "object": meta["object"], "appearance": meta["appearance"], "diameter_cm": round(100 * d, 2),
        "symmetry": meta["symmetry"], "frames": int(len(e)),
        "add_ok": metrics.add_success_rate(e, d), "add_strict_ok": metrics.add_success_rate(a["add"], d),
        "add_mean_mm": float(1000 * np.mean(e)), "add_auc": float(metrics.pose_auc(e, 0.1)),
        "s5cm5deg": metrics.success_5cm5deg_rate(a["rot"], a["trans"]),
        "iou_ok": metrics.iou_success_rate(iou), "iou_mean": float(np.mean(iou)),
        "iou_auc": float(metrics.iou_success_curve(iou)[2]), "precision": precision, "recall": recall,
        "touch_frames": int(a["in_contact"].sum()), "hand_px_touch": int(hn), "hand_tgt_px_touch": int(ht),
        "hand_as_target": metrics.pooled_occluder_as_target(a["hand_near"], a["hand_near_tgt"], where=a["in_contact"]),
        "occl_frames": int(touch.sum()), "occl_add_ok": metrics.add_success_rate(e, d, where=touch),
        "occl_iou_ok": metrics.iou_success_rate(iou, where=touch), "occlusion_max": float(a["occlusion"].max()),
        "ece": metrics.pooled_ece(a["cal_bins"]), "ece_raw": metrics.pooled_ece(a["raw_bins"]),
        "static_frames": int(drift.frames.sum()), "drift_deg": float(np.rad2deg(drift.max_drift)),
        "lost": int(a["lost"].sum()), "first_loss": int(metrics.frames_until_loss(e, 0.3 * d)),
        "ar_mssd": float(metrics.ar_mssd(a["mssd"], d)), "ar_mspd": float(metrics.ar_mspd(a["mspd"], meta["width"])),
        "ar_vsd": float(metrics.ar_vsd(a["vsd"])) if len(a["vsd"]) else float("nan"),
        "cpu_ms_median": float(np.median(cpu)), "cpu_ms_p95": float(np.percentile(cpu, 95)),
        "fps_cpu": float(1000.0 / np.median(cpu)), "roi_px": float(np.mean(a["roi_px"])),
        "width": int(meta["width"]), "load": float(meta["load"]),
    }


def by(table, key, value):
    return [r for r in table if r[key] == value]


def col(rows, key):
    """Column ``key`` of result rows as floats (an empty cell, None, as NaN)."""
    return np.array([np.nan if r[key] is None else r[key] for r in rows], float)


def pooled(rows, num, den="frames"):
    """A per-run rate pooled over rows, weighted by their frames (the rate over all frames)."""
    return metrics.pooled_rate(col(rows, num), col(rows, den))


def group(table, split):
    """The rows headline figures pool: on dev the 16 sequences every earlier result used."""
    return [r for r in table if r["sequence"] in list_sequences("dev")] if split == "dev" else table


def rate_rows(table, key, order):
    """One row per value of ``key`` (in ``order``): pooled and per-sequence rates."""
    rows = []
    for v in order:
        rs = by(table, key, v)
        if not rs:
            continue
        rows.append({
            key: v, "sequences": len(rs), "frames": int(sum(r["frames"] for r in rs)),
            "add_ok": pooled(rs, "add_ok"), "add_ok_seqmin": float(np.min([r["add_ok"] for r in rs])),
            "add_strict_ok": pooled(rs, "add_strict_ok"), "add_auc": pooled(rs, "add_auc"),
            "s5cm5deg": pooled(rs, "s5cm5deg"), "iou_ok": pooled(rs, "iou_ok"), "iou_mean": pooled(rs, "iou_mean"),
            "hand_as_target": metrics.pooled_occluder_as_target([r["hand_px_touch"] for r in rs],
                                                                [r["hand_tgt_px_touch"] for r in rs]),
            "occl_frames": int(sum(r["occl_frames"] for r in rs)),
            "occl_add_ok": pooled(rs, "occl_add_ok", "occl_frames"), "occl_iou_ok": pooled(rs, "occl_iou_ok", "occl_frames"),
            "drift_deg_max": float(np.nanmax([*col(rs, "drift_deg"), np.nan])), "lost": int(sum(r["lost"] for r in rs)),
            "cpu_ms_median": float(np.median([r["cpu_ms_median"] for r in rs])),
        })
    return rows


def cost_vs_size(table, ctx, method):
    """CPU ms per frame of ``method`` (all frames of the table) against the object's and the ROI's pixels."""
    cpu, roi, tgt = [], [], []
    for r in by(table, "method", method):
        z = ctx.arrays(r)
        cpu.append(z["cpu_ms"][1:]), roi.append(z["roi_px"][1:]), tgt.append(z["target_px"][1:])
    cpu, roi, tgt = map(np.concatenate, (cpu, roi, tgt))
    slope, icpt = np.polyfit(tgt / 1e4, cpu, 1) if np.ptp(tgt) > 0 else (float("nan"), float(np.median(cpu)))
    return dict(frames=len(cpu), rho_target=metrics.spearman(tgt, cpu), rho_roi=metrics.spearman(roi, cpu),
                slope=slope, icpt=icpt, q=np.percentile(cpu, [50, 95]), cpu=cpu, tgt=tgt)
