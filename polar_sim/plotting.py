"""Layout helpers for matplotlib figures (numpy and matplotlib only): a colour bar exactly as tall
as its axes, a legend under the axes instead of over the data, and round colour-bar ends.

The picture code of ``sim.pictures``, ``runner.pictures2d``, the demo and the experiments draws
with these, so that no legend covers an image or a map and no colour bar runs into a title.
"""

from __future__ import annotations

import numpy as np

__all__ = ["colorbar_beside", "legend_under", "nice_ceil"]


def colorbar_beside(fig, ax, mappable, label, *, size="4%", pad=0.08):
    """A colour bar exactly as tall as ``ax`` on its right (never over its title), labelled ``label``."""
    from mpl_toolkits.axes_grid1 import make_axes_locatable

    cax = make_axes_locatable(ax).append_axes("right", size=size, pad=pad)
    return fig.colorbar(mappable, cax=cax, label=label)


def legend_under(ax, handles=None, *, ncol=2, fontsize=8, inches=0.5, **kw):
    """A frameless legend ``inches`` under the lower edge of ``ax`` (below its tick labels and x
    label), so that it never covers the image or map drawn in it. ``handles`` default to the
    axes' labelled artists."""
    from matplotlib.transforms import ScaledTranslation

    below = ax.transAxes + ScaledTranslation(0, -inches, ax.figure.dpi_scale_trans)
    if handles is not None:
        kw["handles"] = handles
    return ax.legend(loc="upper center", bbox_to_anchor=(0.5, 0), bbox_transform=below, ncol=ncol, fontsize=fontsize,
                     frameon=False, **kw)


def nice_ceil(x):
    """The smallest of 1, 2, 2.5, 5 times a power of ten that is >= ``x`` (> 0): a colour bar's end."""
    e = 10.0 ** np.floor(np.log10(x))
    return float(next(m * e for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * e >= x * (1 - 1e-12)))
