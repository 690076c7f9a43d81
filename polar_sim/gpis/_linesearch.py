"""The re-evaluation line search (spec §6.2 step 3): move a sample along its normal until the
scan's occupancy test reads the surface.

:func:`line_search` is the general form over any occupancy test (the depth camera's tiled GP);
the planar scan runs the same search in one kernel, :meth:`polar_sim.gpis._obsgp.ObsGP1D.line_search`
(``tests/gpis/test_query_kernel.py`` checks that the two agree).
"""

from __future__ import annotations

import numpy as np

__all__ = ["TOL", "line_search"]

TOL = 0.02          # |oc| below which the search has reached the observed surface
MAX_STEPS = 10


def line_search(p, n, oc_fn, step, oc_skip, *, depth=False, reproject_bug=False):
    """Search along the unit normals n from the sensor-frame points p (k, d).

    Each point starts with the step ``step`` and moves toward the surface the occupancy test
    ``oc_fn(q) -> (oc, observable, r_hat)`` indicates (negative oc: free space, step along the
    normal); the step halves when oc changes sign and grows by 1.1 otherwise, for at most
    ``MAX_STEPS`` steps. A point whose oc falls below ``oc_skip`` (occluded) or leaves the
    observable region stops.

    Parameters
    ----------
    depth : bool
        Ranges are depths (``q[:, 2]``) and only points in front of the sensor are live (3D);
        otherwise ranges are Euclidean norms.
    reproject_bug : bool
        The published 3D quirk: the occupancy is re-tested at the start point p every step, and
        the range is not updated.

    Returns
    -------
    live : (k,) bool
        Observable, not occluded points (the others are left as they are).
    q : (k, d)
        End points.
    A : (k,)
        |oc| at the last accepted step.
    rnew : (k,)
        Range of q.
    found : (k,) bool
        The search reached |oc| < TOL.
    """
    rng = (lambda x: x[:, 2]) if depth else (lambda x: np.linalg.norm(x, axis=1))
    oc0, obs0, _ = oc_fn(p)
    live = obs0.copy()
    if depth:
        live &= p[:, 2] > 0
    with np.errstate(invalid="ignore"):
        live &= ~(oc0 < oc_skip)
    q = p.copy()
    delta = np.full(len(p), float(step))
    A = np.abs(oc0)
    occ = oc0.copy()
    rnew = rng(p)
    run = live & (A > TOL)
    found = live & ~run
    for _ in range(MAX_STEPS):
        idx = np.nonzero(run)[0]
        if len(idx) == 0:
            break
        s = np.where(occ[idx] < 0, delta[idx], -delta[idx])
        q[idx] += s[:, None] * n[idx]
        if not reproject_bug:
            rnew[idx] = rng(q[idx])
        o2, ob2, _ = oc_fn(p[idx] if reproject_bug else q[idx])
        conv = ob2 & (np.abs(o2) < TOL)
        found[idx[conv]] = True
        prev = ob2 & ~conv & (occ[idx] < oc_skip)
        cont = ob2 & ~conv & ~prev
        c = idx[cont]
        flip = occ[c] * o2[cont] < 0
        delta[c] = np.where(flip, delta[c] / 2, 1.1 * delta[c])
        A[c] = np.abs(o2[cont])
        occ[c] = o2[cont]
        run[idx] = cont
    return live, q, A, rnew, found
