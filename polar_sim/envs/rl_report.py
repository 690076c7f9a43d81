"""Reporting training runs as the field does: rliable's interquartile mean (IQM) with 95 %
stratified bootstrap confidence intervals over training seeds, and learning curves of success
against environment steps and against wall-clock time (needs ``rliable``, the ``[learn]`` extra).
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["iqm_with_ci", "plot_learning_curves"]


def iqm_with_ci(scores, *, reps=2000, seed=0, confidence=0.95):
    """IQM and its stratified bootstrap confidence interval.

    Parameters
    ----------
    scores : dict of str -> array of shape (n_runs, n_tasks)
        Per method, one score per training run (seed) and task (tier), e.g. held-out success.
    reps : int
        Bootstrap resamples.
    seed : int
        Seeds the bootstrap (same seed, same interval).
    confidence : float
        Size of the interval.

    Returns
    -------
    dict of str -> (iqm, low, high)
    """
    from rliable import library as rly
    from rliable import metrics

    arrays = {}
    for k, v in scores.items():
        a = np.asarray(v, np.float64)
        if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] < 1 or not np.isfinite(a).all():
            raise ValueError(f"scores[{k!r}]: expected a finite array of shape (n_runs, n_tasks), got {a.shape}")
        arrays[k] = a
    # rliable's StratifiedBootstrap draws its resamples from numpy's global RNG (np.random.choice),
    # whatever random_state it is given: seed that, and put the caller's state back afterwards.
    saved = np.random.get_state()
    np.random.seed(int(seed))
    try:
        with warnings.catch_warnings():  # arch deprecates random_state, which rliable still passes
            warnings.simplefilter("ignore", FutureWarning)
            point, ci = rly.get_interval_estimates(arrays, lambda x: np.array([metrics.aggregate_iqm(x)]),
                                                   reps=int(reps), confidence_interval_size=confidence,
                                                   random_state=np.random.RandomState(seed))
    finally:
        np.random.set_state(saved)
    return {k: (float(point[k][0]), float(ci[k][0, 0]), float(ci[k][1, 0])) for k in arrays}


def plot_learning_curves(curves, path, *, title="", baselines=None):
    """Success against environment steps (left) and wall-clock minutes (right), one line per
    training run, coloured by method.

    Parameters
    ----------
    curves : dict of str -> list of list of dict
        Per method, per run, the curve rows (``steps``, ``wall_s``, ``success``).
    path : str or Path
        The PNG to write.
    baselines : dict of str -> float, optional
        Horizontal lines (e.g. the experts' success on the same worlds).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9.6, 3.6), sharey=True)
    for c, (method, runs) in enumerate(curves.items()):
        for i, rows in enumerate(runs):
            for ax, key, scale in ((axes[0], "steps", 1.0), (axes[1], "wall_s", 1 / 60)):
                ax.plot([r[key] * scale for r in rows], [r["success"] for r in rows], "o-", ms=3, color=f"C{c}",
                        alpha=0.8, label=method if i == 0 else None)
    for j, (name, value) in enumerate((baselines or {}).items()):
        for ax in axes:
            ax.axhline(value, color="grey", ls=["--", ":", "-."][j % 3], label=name if ax is axes[0] else None)
    axes[0].set_xlabel("environment steps")
    axes[1].set_xlabel("wall-clock time (min, 2 shared CPU cores)")
    axes[0].set_ylabel("success rate (dev worlds)")
    axes[0].set_ylim(-0.02, 1.02)
    axes[0].legend(fontsize=8, loc="lower right")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
