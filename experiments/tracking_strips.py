"""tracking_strips: a picture strip per tabletop sequence (thesis Figs. 5.3 and 5.9).

For each sequence the tracker (``method``, default ``ww``) runs from the first frame, with its debug
maps on, up to the frame in which the hand hides the most of the object while touching it (at most
70 %; without contact the most occluded frame; for the orbit the middle one). The strip of that
frame shows, on the same crop:

1. the RGB image, with the true visible outline (green) and the hand (magenta);
2. the point cloud of the crop with the model at the registered pose (red points);
3. the appearance prediction sigmoid(log Lambda_I), the online classifier's probability of target;
4. the prediction map P(L | I, D, T_bar) = prior x depth x appearance (Fig. 5.3(a));
5. the final mask (cyan) with the true visible outline (green).

Each trial writes ``strip.png``; the summary stacks them into ``tracking_strips.png`` and six into
``tracking_strips_readme.png``. The quick size draws the strip of the 320x240 ``mug_touch`` CI cut.
"""

from __future__ import annotations

import numpy as np

from polar_sim import metrics
from polar_sim.runner import Check, Experiment
from polar_sim.runner.report import markdown_table

from polar_sim.experiments import _tracking_common as C
from polar_sim.experiments import _tracking_pictures as pictures

README_SEQUENCES = ["mug_touch", "drill_lift", "box_turn", "can_fast", "skin_box_lift", "box_pass",
                    "blocks_turn_primary", "bottle_touch_studio", "mug_lift_gloved"]


def trial(params, seed, ctx):
    name, method = params["sequence"], params["method"]
    rec, start, end = C.recording(name, seed, ctx.params)
    values = {k: rec.stack(k) for k in ("occlusion", "in_contact", "T_cam_obj")}
    k = pictures.pick_frame(values, start, end)
    keep = {}

    def grab(i, fr, r):
        if i == k:
            keep.update(fr=fr, r=r)

    C.track(name, seed, method, params=ctx.params, on_frame=grab, stop=k + 1, tracker_kw={"debug_maps": True})
    fr, r = keep["fr"], keep["r"]
    K, obj, d = np.array(rec.meta["K"], float), rec.meta["object"], float(rec.meta["diameter"])
    P, _ = C.model(obj)
    G = values["T_cam_obj"][k]
    e = metrics.adds(P, G, r.pose) if rec.meta["symmetry"] != "none" else metrics.add(P, G, r.pose)
    iou = metrics.iou(r.mask, fr["mask_visible"])
    occ, touch = float(values["occlusion"][k]), bool(values["in_contact"][k])
    family = (rec.meta.get("appearance") or {}).get("family", "default")
    title = (f"{name} ({obj}, {family}), frame {k}, {method}: occlusion {100 * occ:.0f} %, hand "
             f"{'touching' if touch else 'not touching'}; ADD(-S) {1000 * e:.1f} mm ({100 * e / d:.1f} % of d), "
             f"IoU {iou:.2f}")
    pictures.draw_strip(ctx.out_dir / "strip.png", title, fr, r, K, P, d)
    return {"frame": int(k), "occlusion": occ, "in_contact": touch, "add_over_d": float(e / d), "iou": float(iou),
            "object": obj, "appearance": family}


def summarize(table, ctx):
    cols = ["sequence", "method", "object", "appearance", "frame", "occlusion", "in_contact", "add_over_d", "iou"]
    png = {r["sequence"]: ctx.trial_dir(r) / "strip.png" for r in table}
    lines = [f"Split **{ctx.split}**. One strip per sequence: the frame where the hand hides the most of the object "
             "while touching it. Panels: RGB with the true outline and the hand; the point cloud with the model at "
             "the registered pose; the appearance prediction; the prediction map; the final mask.", "",
             markdown_table(table, cols), ""]
    if pictures.stack_pngs(list(png.values()), ctx.out_dir / "tracking_strips.png"):
        lines += ["![tracking_strips](tracking_strips.png)", ""]
    sel = [s for s in README_SEQUENCES if s in png]
    if sel and pictures.stack_pngs([png[s] for s in sel[:6]], ctx.out_dir / "tracking_strips_readme.png"):
        lines += [f"README selection ({', '.join(sel[:6])}): `tracking_strips_readme.png`."]
    return "\n".join(lines)


def checks(table, ctx):
    n_ok = sum(1 for r in table if np.isfinite(r.get("iou", np.nan)))
    return [Check("a strip is drawn for every sequence", n_ok == len(table) and n_ok > 0, f"{n_ok} strips")]


EXPERIMENT = Experiment(
    name="tracking_strips",
    description="picture strip per tabletop sequence: point cloud with the registered model, appearance "
                "prediction, prediction map, final mask",
    grid={"sequence": C.DEV, "method": ["ww"]},
    methods={"method": "tracker"},
    choices=C.CHOICES,
    params=C.PARAMS,
    splits=C.SPLITS,
    sizes={"quick": {"n_seeds": 1, "grid": {"sequence": ["mug_touch"]}, "params": C.QUICK_PARAMS}, "full": {}},
    trial=trial, summarize=summarize, checks=checks,
)
