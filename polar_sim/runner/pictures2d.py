"""Pictures of 2D maps for experiment summaries (matplotlib; numpy arrays in, axes drawn on).

- :func:`map_picture`: a mapper's SDF, variance and ``surface()`` sampled on a grid, as arrays a
  trial saves (``ctx.save_arrays``) for the summary;
- :func:`map_panel`: those arrays drawn (SDF where observed, grey where never observed, zero
  level, path);
- :func:`map_figure`: the three-panel figure of a whole log (update-time histogram, SDF, variance);
- :func:`error_figure`: |SDF error| near surfaces and the worst 1 % of the surface, classed;
  :func:`error_rows_figure`: one row of those per trial;
- :func:`spacing_figure`: scores against the scan spacing, per scene and method.

Coordinates in metres; SDF in metres; variance in m^2; times in ms. Legends sit under the axes
and colour bars beside them (:mod:`polar_sim.plotting`), so neither covers a map.
"""

from __future__ import annotations

import numpy as np

from polar_sim.plotting import colorbar_beside, legend_under

#: Grey of never-observed map cells (the map's distance there is an extrapolation).
UNSEEN_GREY = "0.75"

__all__ = ["map_picture", "map_panel", "map_figure", "error_figure", "error_rows_figure", "spacing_figure"]


def map_picture(m, pts, step):
    """The map's SDF and variance on a grid of ``step`` m over the box of ``pts`` (k, 2) plus 1 m,
    and its ``surface()`` polylines (NaN-separated), as arrays for :func:`map_panel`."""
    lo, hi = pts.min(0) - 1.0, pts.max(0) + 1.0
    xs, ys = np.arange(lo[0], hi[0], step), np.arange(lo[1], hi[1], step)
    X, Y = np.meshgrid(xs, ys)
    Q = np.column_stack([X.ravel(), Y.ravel()])
    s, v = np.empty(len(Q)), np.full(len(Q), np.nan)
    for i in range(0, len(Q), 10_000):       # below the size where a query goes multi-threaded
        d, _, var = m.query(Q[i:i + 10_000])
        s[i:i + 10_000] = d
        if var is not None:
            v[i:i + 10_000] = var
    lines = m.surface() if callable(getattr(m, "surface", None)) else []
    return {"xs": xs, "ys": ys, "sdf": s.reshape(X.shape).astype(np.float32), "var": v.reshape(X.shape).astype(np.float32),
            "lines": np.vstack([np.vstack([ln, [np.nan, np.nan]]) for ln in lines]) if lines else np.zeros((0, 2))}


def map_panel(ax, z, title, *, var_max=1.0):
    """Draw :func:`map_picture` arrays: the SDF where the variance is below ``var_max`` (never
    observed space grey: the map's distance there is only an extrapolation), the surface, the path."""
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.patches import Patch

    ext = [z["xs"][0], z["xs"][-1], z["ys"][0], z["ys"][-1]]
    unseen = z["var"] >= var_max
    ax.set_facecolor(UNSEEN_GREY)   # NaN cells show the face: grey, unlike the white of SDF = 0
    im = ax.imshow(np.where(unseen, np.nan, np.clip(z["sdf"], -1.0, 2.0)), origin="lower", extent=ext, cmap="RdBu",
                   norm=TwoSlopeNorm(vmin=-1.0, vcenter=0.0, vmax=2.0))
    if len(z["lines"]):
        # a lone vertex between NaN separators is a point of the zero level (an object below the
        # grid's resolution): give every vertex a dot small enough to vanish along the lines
        ax.plot(z["lines"][:, 0], z["lines"][:, 1], "-", c="k", lw=0.7, marker=".", ms=1.5,
                label="zero level (surface())")
    ax.plot(z["path"][:, 0], z["path"][:, 1], "-", c="tab:orange", lw=1.0, label="path")
    ax.set(title=title, xlabel="x (m)", ylabel="y (m)", aspect="equal")
    ax.title.set_fontsize(9)
    handles, _ = ax.get_legend_handles_labels()
    legend_under(ax, handles + [Patch(color=UNSEEN_GREY, label=f"never observed (variance >= {var_max:g})")], ncol=3,
                 fontsize=7)
    colorbar_beside(ax.figure, ax, im, "SDF (m), clipped to -1..2")
    ax.figure.subplots_adjust(wspace=0.35)    # the colour bar's label clear of the next panel


def error_figure(ax, z, r, scene):
    """Two panels from a trial's arrays: |SDF error| near surfaces, and ``surface()`` with its worst
    1 % classed (corner / sparse / wall)."""
    ax[0].scatter(z["hits"][:, 0], z["hits"][:, 1], s=0.2, c="0.6", lw=0)
    sc = ax[0].scatter(z["P"][:, 0], z["P"][:, 1], c=np.abs(z["err"]), s=1.5, cmap="inferno_r", vmin=0, vmax=0.1, lw=0)
    ax[0].plot(z["path"][:, 0], z["path"][:, 1], "-", c="tab:blue", lw=1, label="drive")
    colorbar_beside(ax[0].figure, ax[0], sc, "|SDF error| (m), clipped to 0.1,\nat points within 0.3 m of observed surfaces")
    ax[0].set_title(f"{scene} seed {r['seed']}, {r['method']}: SDF error near surfaces (RMSE {r['near_rmse_m'] * 100:.1f} cm)",
                    fontsize=9)
    ax[1].scatter(z["hits"][:, 0], z["hits"][:, 1], s=0.2, c="0.6", lw=0, label="observed true surface")
    if "est" in z:
        sel = z["dA"] > 0.05
        ax[1].scatter(z["est"][:, 0], z["est"][:, 1], s=0.3, c="k", lw=0, label="estimated surface")
        ax[1].scatter(z["est"][sel, 0], z["est"][sel, 1], c=np.minimum(z["dA"][sel], 0.3), s=3, cmap="autumn_r",
                      vmin=0.05, vmax=0.3, lw=0, label="estimate > 5 cm off the truth")
        for k, (name, c) in enumerate(zip(["corner", "sparse", "wall"], ["tab:red", "tab:purple", "tab:green"])):
            s = z["worst_cls"] == k
            ax[1].scatter(z["worst"][s, 0], z["worst"][s, 1], marker="x", s=18, c=c, label=f"worst 1%: {name}")
        ax[1].set_title(f"surface: Hausdorff {r['hausdorff_m'] * 100:.1f} cm", fontsize=9)
    for a in ax:
        a.set_aspect("equal")
        a.set_xlabel("x (m)")
        a.set_ylabel("y (m)")
        legend_under(a, ncol=3, fontsize=7, markerscale=2)
    # room between the panels for the colour bar's label, and under each row for its legends
    ax[0].figure.subplots_adjust(wspace=0.45, hspace=0.4)


def map_figure(z, *, mapper, title):
    """Three panels from :func:`map_picture` arrays plus ``z["cpu_ms"]`` (per-update CPU ms) and
    ``z["path"]``: the update-time histogram, the SDF with its zero level, and log10 of the variance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(20, 6.2))
    # bins up to the 99.5th percentile, so that one slow first scan does not squeeze the rest
    cpu = np.asarray(z["cpu_ms"])
    top = float(np.percentile(cpu, 99.5))
    ax[0].hist(np.minimum(cpu, top), bins=60, range=(0.0, top), color="tab:blue")
    ax[0].axvline(np.median(cpu), color="k", lw=1, label=f"median {np.median(cpu):.2f} ms")
    legend_under(ax[0], title=f"{int((cpu > top).sum())} scans above {top:.1f} ms (max {cpu.max():.0f}) in the last bin",
                 ncol=1, title_fontsize=8)
    ax[0].set(xlabel="update CPU time per scan (ms)", ylabel="scans", title=f"{mapper}: update time over the whole log (Fig 7.12a)")
    map_panel(ax[1], z, "SDF and zero level of the whole log (Fig 7.19)")
    im = ax[2].imshow(np.log10(np.maximum(z["var"], 1e-6)), origin="lower", cmap="magma",
                      extent=[z["xs"][0], z["xs"][-1], z["ys"][0], z["ys"][-1]])
    ax[2].set(title="log10 variance of the SDF", xlabel="x (m)", ylabel="y (m)", aspect="equal")
    colorbar_beside(fig, ax[2], im, "log10 variance (m^2)")
    fig.suptitle(title)
    return fig


def error_rows_figure(arrays, rows, scene, *, height):
    """One row of :func:`error_figure`'s two panels per trial (its saved ``arrays`` and its ``rows``,
    alike in order), ``height`` inches a row."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(len(rows), 2, figsize=(15, height * len(rows)), squeeze=False)
    for a, z, r in zip(ax, arrays, rows):
        error_figure(a, z, r, scene)
    return fig


def spacing_figure(long, keys):
    """Per scene of ``long`` (rows of scene, spacing_m, method and the ``keys``, metres), each method's
    ``keys`` against the scan spacing: a row of log-scale panels per scene."""
    import matplotlib.pyplot as plt

    scenes = sorted({r["scene"] for r in long})
    fig, ax = plt.subplots(len(scenes), len(keys), figsize=(15, 4.2 * len(scenes)), squeeze=False)
    for i, scene in enumerate(scenes):
        for k in sorted({r["method"] for r in long}):
            rs = [r for r in long if r["scene"] == scene and r["method"] == k]
            for a, key in zip(ax[i], keys):
                a.plot([r["spacing_m"] for r in rs], [r[key] for r in rs], "o-", label=k)
                a.set(xlabel="scan spacing (m of travel)", ylabel="m", yscale="log", title=f"{scene}: {key} (mean)")
                a.grid(alpha=0.3)
        ax[i, 0].legend()
    return fig
