"""The cells of the cluster grid shell by shell: the one walk of the nearest-neighbour searches.

Both searches that visit the cluster grid outward from a point's cell (:func:`._distance.knn`, the
k nearest samples, and :func:`._query._nearest3`, the nearest clusters of the query) walk the cells
at Chebyshev distance exactly ``r`` from a centre cell, clipped to a box, in one order: the rows of
axes 1..d-1 in turn (axis 1 fastest), and along axis 0 each row's cells in increasing order, with a
stride of 2r where the other axes are inside the shell (only the row's two end cells are on it).
The walk allocates nothing: :func:`shell_start` fills the caller's work arrays, then each
:func:`shell_next` puts the next cell into ``cc``.
"""

from __future__ import annotations

import numba as nb

__all__ = ["shell_start", "shell_next", "SHELL_STATE"]

#: Length of the int64 state array of a walk.
SHELL_STATE = 4


@nb.njit(cache=True)
def shell_start(r, c0, lo, hi, a0, a1, st):
    """Prepare the walk over the cells at Chebyshev distance ``r`` from ``c0`` inside the box
    ``[lo, hi]`` (inclusive integer corners, (d,) each); False when the shell misses the box.

    ``a0``, ``a1`` (d,) and ``st`` (``SHELL_STATE``,) are int64 work arrays for :func:`shell_next`.
    """
    total = 1
    for k in range(1, c0.shape[0]):
        a0[k] = max(c0[k] - r, lo[k])
        a1[k] = min(c0[k] + r, hi[k])
        if a1[k] < a0[k]:
            return False
        total *= a1[k] - a0[k] + 1
    st[0] = -1                  # the row (cell of axes 1..d-1) being walked
    st[1] = total               # rows
    st[2] = c0[0] + r + 1       # the next axis-0 coordinate: past the row's end, so a row starts
    st[3] = 1                   # the axis-0 step in this row
    return True


@nb.njit(cache=True)
def shell_next(r, c0, lo, hi, a0, a1, cc, st):
    """Put the walk's next cell (integer coordinates) into ``cc`` (d,); False when it is done."""
    while True:
        while st[2] <= c0[0] + r:
            x = st[2]
            st[2] += st[3]
            if lo[0] <= x <= hi[0]:
                cc[0] = x
                return True
        st[0] += 1
        if st[0] >= st[1]:
            return False
        f = st[0]
        edge = False
        for k in range(1, c0.shape[0]):
            span = a1[k] - a0[k] + 1
            cc[k] = a0[k] + f % span
            f //= span
            if abs(cc[k] - c0[k]) == r:
                edge = True
        st[3] = 1 if (edge or r == 0) else 2 * r
        st[2] = c0[0] - r
