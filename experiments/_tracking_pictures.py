"""Picture strips of the tracking experiments (``tracking_strips``): one frame's five panels.

Not an experiment (the underscore keeps it out of the registry).
"""

from __future__ import annotations

import numpy as np

__all__ = ["pick_frame", "draw_strip", "stack_pngs", "success_curves", "variants_figures"]


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


def stack_pngs(paths, out):
    """Stack PNG strips vertically into ``out`` (padded to the widest); False if none could be read."""
    import cv2

    imgs = [cv2.imread(str(p)) for p in paths]
    imgs = [i for i in imgs if i is not None]
    if not imgs:
        return False
    w = max(i.shape[1] for i in imgs)
    imgs = [cv2.copyMakeBorder(i, 0, 0, 0, w - i.shape[1], cv2.BORDER_CONSTANT, value=(255, 255, 255)) for i in imgs]
    cv2.imwrite(str(out), np.vstack(imgs))
    return True


def success_curves(table, ctx, methods, ax_pose=None, ax_iou=None):
    """Pose success over k (ADD(-S) < k d) and mask success over the IoU threshold, per method,
    all frames of ``table`` pooled (from each trial's saved arrays)."""
    th, tt = np.linspace(0, 0.3, 61), np.linspace(0, 1, 101)
    for m in methods:
        rows = [r for r in table if r["method"] == m]
        if not rows:
            continue
        z = [ctx.arrays(r) for r in rows]
        ls = "--" if m in ("shape-only", "plain-icp") else "-"
        if ax_pose is not None:
            e = np.concatenate([a["err_d"] for a in z])
            ax_pose.plot(th, [(e < t).mean() for t in th], ls, label=m)
        if ax_iou is not None:
            u = np.concatenate([a["iou"] for a in z])
            ax_iou.plot(tt, [(u > t).mean() for t in tt], ls, label=m)
    for ax, xl, title in ((ax_pose, "threshold k (ADD(-S) < k x diameter)", "pose success"),
                          (ax_iou, "IoU threshold", "2D segmentation success")):
        if ax is not None:
            ax.set(xlabel=xl, ylabel="fraction of frames", title=title)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)


def variants_figures(head, ctx, methods, size_rows, cost, ref):
    """``tracking_variants``' figures: success curves of ``methods`` beside ADD(-S) AUC against the
    object's diameter (``size_rows``, one per sequence of ``ref``), and the CPU time per frame
    against the object's image size (``cost``); returns their markdown lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from polar_sim.runner.report import savefig

    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    success_curves(head, ctx, methods, ax[0], ax[1])
    for r in size_rows:
        ax[2].scatter(r["diameter_cm"], 100 * r["add_auc"], marker={"distinct": "o", "cuboid": "s"}.get(r["shape"], "^"))
        ax[2].annotate(r["sequence"], (r["diameter_cm"], 100 * r["add_auc"]), fontsize=6)
    ax[2].set(xlabel="object diameter, cm", ylabel=f"{ref} ADD(-S) AUC 0-10 cm, %",
              title="per sequence (o distinct, s cuboid, ^ revolved)")
    ax[2].grid(alpha=0.3)
    fig.tight_layout()
    lines = [savefig(fig, ctx.out_dir, "tracking_variants_curves"), ""]
    fig, a = plt.subplots(figsize=(5, 4))
    a.scatter(cost["tgt"] / 1e3, cost["cpu"], s=2, alpha=0.3)
    a.set(xlabel="object pixels (amodal mask), thousands", ylabel="CPU ms per frame (one thread)",
          title=f"{ref}: cost against the object's image size")
    a.grid(alpha=0.3)
    fig.tight_layout()
    return lines + [savefig(fig, ctx.out_dir, "tracking_variants_cost")]
