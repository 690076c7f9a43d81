"""Reliability diagrams for experiment summaries (matplotlib; :class:`polar_sim.metrics.Reliability` in,
axes drawn on). The statistics are :mod:`polar_sim.metrics.calibration`'s; only the drawing lives here."""

from __future__ import annotations

__all__ = ["plot_reliability"]


def plot_reliability(rels, labels=None, *, ax=None, title="reliability diagram"):
    """Draw one or more :class:`~polar_sim.metrics.Reliability` curves with the diagonal.

    ``rels``: a Reliability or a list of them; ``labels``: their legend names. Returns the axes.
    """
    import matplotlib.pyplot as plt

    from polar_sim.metrics.calibration import Reliability

    if isinstance(rels, Reliability):
        rels = [rels]
    labels = list(labels) if labels is not None else [f"curve {i}" for i in range(len(rels))]
    if len(labels) != len(rels):
        raise ValueError(f"labels: expected {len(rels)} names, got {len(labels)}")
    if ax is None:
        _, ax = plt.subplots(figsize=(4.6, 4.2))
    ax.plot([0, 1], [0, 1], c="0.6", ls="--", lw=1, label="calibrated")
    for r, name in zip(rels, labels):
        nz = r.count > 0
        ax.plot(r.confidence[nz], r.frequency[nz], marker="o", ms=3, label=f"{name} (ECE {r.ece:.3f})")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_xlabel("predicted probability (bin mean)")
    ax.set_ylabel("observed frequency of the class")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    return ax
