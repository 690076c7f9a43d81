"""Figures of the ground experiments' summaries (not an experiment: the underscore keeps it out of the
registry). Arrays and rows in, matplotlib figures out; the scores come from ``polar_sim.metrics``."""

from __future__ import annotations

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def probability_maps(path, rec, probs, captions, iou):
    """Rows of camera image | P(ground) | thresholded errors for the frames in ``probs`` ({frame: map})."""
    plt = _plt()
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


def per_route_bars(table, key, target, ylabel, title):
    """A bar chart of ``key`` per route, one bar per method, with the target as a dashed line;
    returns the figure. Errors span decades (1 % to 200 %), so the axis is logarithmic with plain
    1-2-5 tick labels; the legend sits beside the axes, never over a bar."""
    import textwrap

    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    plt = _plt()
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


def reliability_figure(rels, title):
    """One reliability diagram of the families' pooled bins ({family: Reliability}); returns the figure."""
    from polar_sim.runner.pictures_calibration import plot_reliability

    fig, ax = _plt().subplots(figsize=(5.2, 4.6))
    plot_reliability(list(rels.values()), list(rels), ax=ax, title=title)
    return fig


def success_boxplots(table, fits, cfgs, split, label):
    """ps against RANSAC iterations per config: boxplots over repetitions, uniform and weighted side by
    side, with the fitted curves (``fits`` {(config, sampling): SuccessCurve}); returns the figure."""
    fig, axes = _plt().subplots(1, max(len(cfgs), 1), figsize=(4.2 * max(len(cfgs), 1), 3.6), squeeze=False)
    for ax, cfg in zip(axes[0], cfgs):
        ns = sorted({r["n_iter"] for r in table if r["config"] == cfg})
        pos = np.log(ns)
        half = 0.16 * float(np.min(np.diff(pos))) if len(pos) > 1 else 0.2
        for k, (samp, col) in enumerate((("uniform", "tab:blue"), ("weighted", "tab:red"))):
            vals = [[r["ps"] for r in table if r["config"] == cfg and r["sampling"] == samp and r["n_iter"] == n]
                    for n in ns]
            bp = ax.boxplot(vals, positions=pos + (2 * k - 1) * half, widths=1.6 * half, patch_artist=True,
                            flierprops=dict(markersize=2), manage_ticks=False)
            for b in bp["boxes"]:
                b.set(facecolor=col, alpha=0.35, edgecolor=col)
            fc = fits[(cfg, samp)]
            nn = np.geomspace(ns[0] * 0.8, ns[-1] * 1.25, 200)
            ax.plot(np.log(nn), fc(nn), color=col, lw=1.2, label=f"{samp}: p_max {fc.p_max:.3f}, n95 {fc.n95:.1f}")
        ax.set_xticks(pos, [str(n) for n in ns])
        ax.set(xlabel="RANSAC iterations N", ylabel="ps (recall of true ground)", title=label(cfg))
        ax.legend(fontsize=7, loc="lower right")
        ax.grid(alpha=0.3)
    fig.suptitle(f"RANSAC success rate ps ({split} split, simulated routes): uniform (blue) vs weighted (red); "
                 "curves: fitted ps(N) = p_max − (p_max − p_0)·p^N", fontsize=9)
    return fig


def scale_errorbars(table, cfgs, split, label):
    """ΔV_mean against RANSAC iterations per config, mean ± std over repetitions; returns the figure."""
    fig, axes = _plt().subplots(1, len(cfgs), figsize=(4.0 * len(cfgs), 3.4), squeeze=False)
    for ax, cfg in zip(axes[0], cfgs):
        ns = sorted({r["n_iter"] for r in table if r["config"] == cfg})
        for samp, col in (("uniform", "tab:blue"), ("weighted", "tab:red")):
            vals = [[r["dv"] for r in table if r["config"] == cfg and r["sampling"] == samp and r["n_iter"] == n] for n in ns]
            ax.errorbar(ns, [np.mean(v) for v in vals], yerr=[np.std(v) for v in vals], color=col, marker="o", ms=3,
                        capsize=2, label=samp)
        ax.set_xscale("log")
        ax.set_xticks(ns, [str(n) for n in ns])
        ax.set(xlabel="RANSAC iterations N", ylabel="ΔV_mean (m/s)", title=label(cfg))
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()    # the panels' labels clear of each other, the title above the panels' titles
    fig.suptitle(f"Raw RANSAC speed error ({split} split, simulated routes; mean ± std over repetitions)", fontsize=9,
                 y=1.02)
    return fig
