"""tracking_strips: a picture strip per tabletop sequence (issue 6, item 4; thesis Figs. 5.3 and 5.9).

For each sequence the tracker (``variant``, default ``ww``) runs from the first frame, with its debug
maps on, up to the frame in which the hand hides the most of the object while touching it (for the
sequences without contact: the most occluded frame; for the orbit, the middle frame). The strip of
that frame shows, on the same crop:

1. the RGB image, with the true visible outline (green) and the hand (magenta);
2. the point cloud of the crop (depth back-projected, coloured by the image) with the model at the
   registered pose (red points), seen from 35 deg beside the camera;
3. the appearance prediction: sigmoid(log Lambda_I), the online classifier's probability of target;
4. the attention map: the prediction map P(L | I, D, T_bar) = prior x depth x appearance (Fig. 5.3(a)),
   whose highly probable points are registered;
5. the final mask (cyan) with the true visible outline (green).

Each trial writes ``strip.png``; the summary stacks them into ``tracking_strips.png`` (all sequences)
and ``tracking_strips_readme.png`` (six of them, for the README). The CI size (``--quick``) draws the
strip of the 320x240 ``mug_touch`` cut.
"""

from __future__ import annotations

import numpy as np

from polar_sim.runner import Check, Experiment
from polar_sim.runner.report import markdown_table

try:  # the registry imports this module as polar_sim.experiments.tracking_strips
    from polar_sim.experiments import _tracking_common as C
except ImportError:  # pragma: no cover
    import _tracking_common as C

README_SEQUENCES = ["mug_touch", "drill_lift", "box_turn", "can_fast", "skin_box_lift", "box_pass"]


def pick_frame(values, start, end):
    """The strip's frame: most occluded (up to 70 %) while touching, else most occluded, else the middle."""
    occ = np.asarray(values["occlusion"][start:end], float)
    con = np.asarray(values["in_contact"][start:end], bool)
    if con.any() and occ[con].max() > 0:
        # at most 70 % hidden, so that there is something to show (the spec's range is 0-70 %)
        cand = np.flatnonzero(con & (occ <= 0.7))
        cand = cand if len(cand) else np.flatnonzero(con)
        return start + int(cand[np.argmax(occ[cand])])
    if occ.max() > 0:
        return start + int(np.argmax(occ))
    return (start + end) // 2


def _crop(shape, *masks, roi=None, pad=0.25):
    H, W = shape
    ys, xs = [], []
    for m in masks:
        y, x = np.nonzero(m)
        ys += [y.min(), y.max()] if len(y) else []
        xs += [x.min(), x.max()] if len(x) else []
    if roi is not None and roi[2] > roi[0]:
        xs += [roi[0], roi[2] - 1]
        ys += [roi[1], roi[3] - 1]
    if not xs:
        return 0, 0, W, H
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    s = max(x1 - x0, y1 - y0) * (1 + pad) / 2 + 4
    s = min(s, H / 2, W / 2)
    cx, cy = np.clip(cx, s, W - s), np.clip(cy, s, H - s)
    return int(cx - s), int(cy - s), int(cx + s), int(cy + s)


def _outline(mask):
    import cv2

    m = mask.astype(np.uint8)
    return (cv2.dilate(m, np.ones((3, 3), np.uint8)) - m) > 0


def draw_strip(path, title, fr, r, K, P, diameter):
    """The five panels of one frame into ``path`` (PNG, fixed size so strips stack)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rgb, depth = fr["rgb"], fr["depth"]
    vis, hand, full = fr["mask_visible"], fr["mask_occluder"], fr["mask_full"]
    x0, y0, x1, y1 = _crop(vis.shape, full, roi=r.roi)
    sl = (slice(y0, y1), slice(x0, x1))
    fig = plt.figure(figsize=(15, 3.2))
    axs = [fig.add_subplot(1, 5, 1), fig.add_subplot(1, 5, 2, projection="3d")] + \
          [fig.add_subplot(1, 5, k) for k in (3, 4, 5)]
    # 1: image, truth outline, hand
    img = rgb[sl].astype(float) / 255
    img[hand[sl]] = 0.55 * img[hand[sl]] + 0.45 * np.array([1.0, 0.0, 1.0])
    img[_outline(vis)[sl]] = (0, 1, 0)
    axs[0].imshow(img)
    axs[0].set_title("RGB, truth (green), hand", fontsize=8)
    # 2: point cloud and the registered model
    ax = axs[1]
    v, u = np.mgrid[y0:y1, x0:x1]
    z = depth[sl].astype(float)
    ok = np.isfinite(z) & (z > 0)
    X = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], -1)[ok]
    col = rgb[sl][ok] / 255.0
    M = P @ r.pose[:3, :3].T + r.pose[:3, 3]
    c = M.mean(axis=0)
    near = np.linalg.norm(X - c, axis=1) < 0.9 * diameter
    X, col = X[near], col[near]
    rng = np.random.default_rng(0)
    if len(X) > 6000:
        k = rng.choice(len(X), 6000, replace=False)
        X, col = X[k], col[k]
    Mk = M[rng.choice(len(M), min(1500, len(M)), replace=False)]
    # plot frame: x right, depth away, up = -y (camera y points down)
    ax.scatter(X[:, 0], X[:, 2], -X[:, 1], c=col, s=0.6, depthshade=False, linewidths=0)
    ax.scatter(Mk[:, 0], Mk[:, 2], -Mk[:, 1], c="red", s=0.8, depthshade=False, linewidths=0)
    h = 0.6 * diameter
    ax.set_xlim(c[0] - h, c[0] + h)
    ax.set_ylim(c[2] - h, c[2] + h)
    ax.set_zlim(-c[1] - h, -c[1] + h)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=12, azim=-90 + 35)
    ax.set_axis_off()
    ax.set_title("point cloud + registered model (red)", fontsize=8)
    # 3: appearance prediction
    app = r.appearance[sl] if r.appearance is not None else np.full(img.shape[:2], np.nan)
    axs[2].imshow(np.nan_to_num(app, nan=0.0), cmap="viridis", vmin=0, vmax=1)
    axs[2].set_title("appearance prediction P(target | I)", fontsize=8)
    # 4: attention (prediction map)
    axs[3].imshow(r.prob[sl], cmap="magma", vmin=0, vmax=1)
    axs[3].set_title("attention: prediction map P(L | I, D, T̄)", fontsize=8)
    # 5: final mask
    img2 = rgb[sl].astype(float) / 255 * 0.6
    img2[r.mask[sl]] = 0.4 * img2[r.mask[sl]] + 0.6 * np.array([0.0, 1.0, 1.0])
    img2[_outline(vis)[sl]] = (0, 1, 0)
    axs[4].imshow(img2)
    axs[4].set_title("final mask (cyan), truth (green)", fontsize=8)
    for a in axs[:1] + axs[2:]:
        a.set_xticks([])
        a.set_yticks([])
    fig.suptitle(title, fontsize=9, x=0.01, ha="left")
    fig.subplots_adjust(left=0.01, right=0.99, top=0.85, bottom=0.02, wspace=0.05)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def trial(params, seed, ctx):
    from polar_sim import metrics

    name, variant = params["sequence"], params["variant"]
    start, end, width, height = C.cut_of(name, ctx.quick)
    stream = C.FrameStream(C.recording_path(name, seed, end if ctx.quick else None, width, height))
    k = pick_frame(stream.values, start, end)
    keep = {}

    def grab(i, fr, r):
        if i == k:
            keep.update(fr=fr, r=r)

    C.track(name, seed, variant, quick=ctx.quick, on_frame=grab, stop=k + 1, tracker_kw={"debug_maps": True})
    fr, r = keep["fr"], keep["r"]
    K = np.array(stream.meta["K"], float)
    P, _ = C.model(stream.meta["object"])
    d = float(stream.meta["diameter"])
    G = stream.values["T_cam_obj"][k]
    e = metrics.adds(P, G, r.pose) if stream.meta["symmetry"] != "none" else metrics.add(P, G, r.pose)
    iou = metrics.iou(r.mask, fr["mask_visible"])
    occ = float(stream.values["occlusion"][k])
    title = (f"{name} ({stream.meta['object']}), frame {k}, {variant}: occlusion {100 * occ:.0f} %, "
             f"hand {'touching' if stream.values['in_contact'][k] else 'not touching'}; "
             f"ADD(-S) {1000 * e:.1f} mm ({100 * e / d:.1f} % of d), IoU {iou:.2f}")
    draw_strip(ctx.out_dir / "strip.png", title, fr, r, K, P, d)
    return {"frame": int(k), "occlusion": occ, "in_contact": bool(stream.values["in_contact"][k]),
            "add_over_d": float(e / d), "iou": float(iou), "object": stream.meta["object"]}


def _stack(paths, out):
    import cv2

    imgs = [cv2.imread(str(p)) for p in paths]
    imgs = [i for i in imgs if i is not None]
    if not imgs:
        return False
    w = max(i.shape[1] for i in imgs)
    imgs = [cv2.copyMakeBorder(i, 0, 0, 0, w - i.shape[1], cv2.BORDER_CONSTANT, value=(255, 255, 255)) for i in imgs]
    cv2.imwrite(str(out), np.vstack(imgs))
    return True


def _trial_png(out_dir, sequence):
    hits = sorted((out_dir / "trials").glob(f"sequence-{sequence}_*/strip.png"))
    return hits[0] if hits else None


def summarize(table, ctx):
    out_dir, quick = ctx.out_dir, ctx.quick
    order = [s for s in C.SEQUENCE_ORDER if any(r["sequence"] == s for r in table)]
    rows = sorted(table, key=lambda r: order.index(r["sequence"]))
    cols = ["sequence", "variant", "object", "frame", "occlusion", "in_contact", "add_over_d", "iou"]
    pngs = [p for p in (_trial_png(out_dir, s) for s in order) if p is not None]
    lines = ["One strip per sequence: the frame where the hand hides the most of the object while touching it. "
             "Panels: RGB with the true outline and the hand; the point cloud with the model at the registered "
             "pose; the appearance prediction; the attention (prediction) map; the final mask.", "",
             markdown_table(rows, cols), ""]
    if _stack(pngs, out_dir / "tracking_strips.png"):
        lines += ["![tracking_strips](tracking_strips.png)", ""]
    sel = [p for p in (_trial_png(out_dir, s) for s in README_SEQUENCES if s in order) if p is not None]
    if sel and _stack(sel, out_dir / "tracking_strips_readme.png"):
        lines += [f"README selection ({', '.join(s for s in README_SEQUENCES if s in order)}): "
                  "`tracking_strips_readme.png`."]
    return "\n".join(lines)


def checks(table, ctx):
    quick = ctx.quick
    n_ok = sum(1 for r in table if r.get("iou") is not None)
    return [Check("a strip is drawn for every sequence", n_ok == len(table) and n_ok > 0, f"{n_ok} strips")]


EXPERIMENT = Experiment(
    name="tracking_strips",
    description="picture strip per tabletop sequence: point cloud with the registered model, appearance "
                "prediction, attention map, final mask",
    grid={"sequence": list(C.SEQUENCE_ORDER), "variant": ["ww"]},
    splits={"dev": {"seeds": [0]}},
    sizes={"quick": {"n_seeds": 1, "grid": {"sequence": ["mug_touch"], "variant": ["ww"]}}, "full": {}},
    trial=trial,
    summarize=summarize,
    checks=checks,
)
