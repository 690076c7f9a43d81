"""The track table of :class:`polar_sim.ground.GroundVO`: one row per tracked feature (spec §3.6).

A table is a dict of arrays with one row per track: ``xy`` (n, 3, 2) positions at frames k-2, k-1, k
(processed px; NaN = not tracked then), ``d`` (n,) fused inverse depth (1/m) and ``P`` (n,) its
variance, ``dmeas`` (n,) the last measured inverse depth, ``has`` (n,) bool a depth measured last
frame, ``gnd`` (n,) int ground-inlier count minus non-ground count, ``age`` (n,) frames tracked.
"""

from __future__ import annotations

import numpy as np

__all__ = ["empty", "select", "append"]


def empty():
    """A table without tracks."""
    return dict(xy=np.zeros((0, 3, 2)), d=np.zeros(0), dmeas=np.zeros(0), P=np.zeros(0),
                has=np.zeros(0, dtype=bool), gnd=np.zeros(0, dtype=np.int64), age=np.zeros(0, dtype=np.int64))


def select(trk, mask):
    """Keep the rows of ``mask`` (bool (n,) or indices), in place."""
    for key in trk:
        trk[key] = trk[key][mask]


def append(trk, xy, p_new):
    """Add new tracks at positions ``xy`` (m, 2) of frame k, inverse-depth variance ``p_new``, in place."""
    n = len(xy)
    hist = np.full((n, 3, 2), np.nan)
    hist[:, 2] = xy
    trk["xy"] = np.concatenate([trk["xy"], hist])
    trk["d"] = np.concatenate([trk["d"], np.zeros(n)])
    trk["dmeas"] = np.concatenate([trk["dmeas"], np.zeros(n)])
    trk["P"] = np.concatenate([trk["P"], np.full(n, p_new)])
    trk["has"] = np.concatenate([trk["has"], np.zeros(n, dtype=bool)])
    trk["gnd"] = np.concatenate([trk["gnd"], np.zeros(n, dtype=np.int64)])
    trk["age"] = np.concatenate([trk["age"], np.zeros(n, dtype=np.int64)])
