"""The planar laser's sensor model on its observation GP (spec §3, §5, §6.2): the occupancy
test, the re-evaluation line search and the new samples' normals and noises, one kernel each
over a whole scan (``ObsGP1D.args()`` gives the GP's arrays)."""

from __future__ import annotations

import numba as nb
import numpy as np

from polar_sim.gpis._fusion import model_args, normal_noise_one
from polar_sim.gpis._native import K, entry
from polar_sim.gpis._obsgp import _predict_one

__all__ = ["occupancy", "line_search", "new_samples", "raw_support", "face_runs", "RUNS"]

#: :func:`face_runs`' settings in the map's update (m): a sample is seen by a return within
#: ``near``; the returns run on along its face while within ``dev`` of its tangent line (the
#: 1 cm range noise, and a 0.4 m pillar's curvature over 0.175 m, stay below 5 cm; a second face
#: leaves the line within a few beams) and ``jump`` of each other; runs are recorded up to ``cap``
#: (above ``_surface.FACE_END``: a face whose returns reach it runs on as far as any gate asks).
RUNS = {"near": 0.03, "dev": 0.05, "jump": 0.10, "cap": 0.2}


def raw_support(q, phi, r, dtheta):
    """The scan's own returns around sensor-frame points q (k, 2): (distance (k,) m, tangent (k, 2)).

    The distance is to the nearest chord between two consecutive returns (beams at most
    1.5 ``dtheta`` apart, rad) within two beams of the point's bearing, or to the nearest return
    where a neighbour is missing; the tangent is that chord's unit direction (zero where the
    nearest is a lone return). ``phi`` (n,) are the sorted beam angles (rad) and ``r`` (n,) the
    ranges (m) of the valid returns. A point of the observed surface lies on these chords up to
    the range noise (and, at a corner, the chord's cut across it); the observation GP's smoothed
    level does not where it interpolates across a corner or a range jump."""
    H = np.stack([r * np.cos(phi), r * np.sin(phi)], 1)
    j = np.searchsorted(phi, np.arctan2(q[:, 1], q[:, 0]))
    last = len(phi) - 1
    best = np.full(len(q), np.inf)
    tan = np.zeros((len(q), 2))
    for k in (-2, -1, 0):
        a, b = np.clip(j + k, 0, last), np.clip(j + k + 1, 0, last)
        A, AB = H[a], H[b] - H[a]
        L2 = np.einsum("ij,ij->i", AB, AB)
        t = np.clip(np.einsum("ij,ij->i", q - A, AB) / np.maximum(L2, 1e-12), 0.0, 1.0)
        chord = (b > a) & (phi[b] - phi[a] <= 1.5 * dtheta)
        d = np.where(chord, np.linalg.norm(q - A - t[:, None] * AB, axis=1),
                     np.minimum(np.linalg.norm(q - A, axis=1), np.linalg.norm(q - H[b], axis=1)))
        closer = d < best
        best[closer] = d[closer]
        tan[closer] = np.where(chord[closer, None], AB[closer] / np.sqrt(np.maximum(L2[closer], 1e-24))[:, None], 0.0)
    return best, tan


def occupancy(gp, q, var_thre):
    """Occupancy test (spec §3) at sensor-frame points q (..., 2): (oc, observable, r_hat),
    each of shape q.shape[:-1]; NaN (and not observable) where the GP has no answer."""
    shp = q.shape[:-1]
    flat = np.ascontiguousarray(q, np.float64).reshape(-1, 2)
    n = flat.shape[0]
    oc, obs, rhat = np.empty(n), np.empty(n, np.bool_), np.empty(n)
    K._occupancy_1d(flat, *gp.args(), float(var_thre), oc, obs, rhat)
    return oc.reshape(shp), obs.reshape(shp), rhat.reshape(shp)


def line_search(gp, p, n, var_thre, step, tol, oc_skip):
    """Spec §6.2 step 3 for sensor-frame points p along unit normals n (k, 2); the planar
    kernel of :func:`polar_sim.gpis._linesearch.line_search` (same outputs)."""
    k = p.shape[0]
    q = np.ascontiguousarray(p, np.float64).copy()
    A, rnew = np.empty(k), np.empty(k)
    found, live = np.empty(k, np.bool_), np.empty(k, np.bool_)
    K._line_search_1d(np.ascontiguousarray(n, np.float64), *gp.args(), float(var_thre), float(step),
                    float(tol), float(oc_skip), q, A, rnew, found, live)
    return live, q, A, rnew, found


@nb.njit(cache=True)
def _oc_one(q0, q1, b, margin, X, C, sums, nobs, scale, noise, var_thre):
    """Occupancy test (spec §3) of one sensor-frame point: (oc, observable, r_hat)."""
    rho, var = _predict_one(np.arctan2(q1, q0), b, margin, X, C, sums, nobs, scale, noise)
    r = np.hypot(q0, q1)
    return np.tanh(15.0 * r * (r ** -0.5 - rho)), var <= var_thre, 1.0 / rho ** 2


@entry
@nb.njit(cache=True)
def _occupancy_1d(q, b, margin, X, C, sums, nobs, scale, noise, var_thre, oc, obs, rhat):
    """Occupancy test (spec §3) at sensor-frame points q (n, 2) against the scan's GP: oc, obs
    (var <= var_thre) and r_hat, written into the (n,) outputs (NaN where unobservable)."""
    for i in range(q.shape[0]):
        oc[i], obs[i], rhat[i] = _oc_one(q[i, 0], q[i, 1], b, margin, X, C, sums, nobs, scale,
                                         noise, var_thre)


@entry
@nb.njit(cache=True)
def _line_search_1d(nrm, b, margin, X, C, sums, nobs, scale, noise, var_thre, step, tol, oc_skip,
                    q, Aout, rnew, found, live):
    """``_linesearch.line_search`` for a planar scan, one point at a time (each point's search
    is independent of the others'). q (k, 2) holds the start points and receives the ends."""
    for i in range(q.shape[0]):
        occ, obs, _ = _oc_one(q[i, 0], q[i, 1], b, margin, X, C, sums, nobs, scale, noise,
                              var_thre)
        lv = obs and not occ < oc_skip
        a = abs(occ)
        rnew[i] = np.sqrt(q[i, 0] * q[i, 0] + q[i, 1] * q[i, 1])
        run = lv and a > tol
        fd = lv and not run
        delta = step
        for _ in range(10):
            if not run:
                break
            s = delta if occ < 0 else -delta
            q[i, 0] += s * nrm[i, 0]
            q[i, 1] += s * nrm[i, 1]
            rnew[i] = np.sqrt(q[i, 0] * q[i, 0] + q[i, 1] * q[i, 1])
            o2, ob2, _ = _oc_one(q[i, 0], q[i, 1], b, margin, X, C, sums, nobs, scale, noise,
                                 var_thre)
            if ob2 and abs(o2) < tol:
                fd = True
                break
            if not ob2 or occ < oc_skip:
                break
            delta = delta / 2 if occ * o2 < 0 else 1.1 * delta
            a = abs(o2)
            occ = o2
        Aout[i] = a
        found[i] = fd
        live[i] = lv


def new_samples(gp, s, phi, r, var_thre, delx, R, smin_p, smin_g, model, grad_gate):
    """Spec §5 for the beams of a planar scan, sensor-frame end points s (k, 2) at angles phi and
    ranges r (k,): ``ok`` (the GP observes the beam), world normals (k, 2), position and gradient
    noises (k,), and ``bad`` (a finite difference was unobservable).

    With the range-noise model, a beam without a usable gradient (none, or one facing away from
    the sensor: the GP smoothed across an edge) keeps its position with the range noise along
    its ray and an untrusted normal facing the sensor, as does one whose gradient noise fails
    ``grad_gate``: only the surfel field uses such normals, and a wrong one there puts a zero
    level in free space.
    """
    k = s.shape[0]
    ok, bad = np.empty(k, np.bool_), np.empty(k, np.bool_)
    nrm, sp, sg = np.empty((k, 2)), np.empty(k), np.empty(k)
    K._new_samples_1d(np.ascontiguousarray(s, np.float64), np.ascontiguousarray(phi, np.float64),
                    np.ascontiguousarray(r, np.float64), *gp.args(), float(var_thre), float(delx),
                    np.ascontiguousarray(R, np.float64), float(smin_p), float(smin_g),
                    *model_args(model), float(grad_gate), ok, nrm, sp, sg, bad)
    return ok, nrm, sp, sg, bad


@entry
@nb.njit(cache=True)
def _new_samples_1d(s, phi, r, b, margin, X, C, sums, nobs, scale, noise, var_thre, dx, R, smin_p,
                    smin_g, on, sigma_r, dtheta, floor_p, kappa, c_min, grad_gate, ok, nrm, sp, sg,
                    bad):
    g = np.empty(2)
    for i in range(s.shape[0]):
        _, var = _predict_one(phi[i], b, margin, X, C, sums, nobs, scale, noise)
        ok[i] = var <= var_thre
        x, y = s[i, 0], s[i, 1]
        o0, b0, _ = _oc_one(x + dx, y, b, margin, X, C, sums, nobs, scale, noise, var_thre)
        o1, b1, _ = _oc_one(x - dx, y, b, margin, X, C, sums, nobs, scale, noise, var_thre)
        o2, b2, _ = _oc_one(x, y + dx, b, margin, X, C, sums, nobs, scale, noise, var_thre)
        o3, b3, _ = _oc_one(x, y - dx, b, margin, X, C, sums, nobs, scale, noise, var_thre)
        bad[i] = not (b0 and b1 and b2 and b3)
        g[0] = (o0 - o1) / dx
        g[1] = (o2 - o3) / dx
        obar = (((o0 + o1) + o2) + o3) / 4.0
        sp[i], sg[i] = normal_noise_one(g, obar, s[i], r[i] * r[i], smin_p, smin_g, R, on,
                                        sigma_r, dtheta, floor_p, kappa, c_min, nrm[i])
        if not on:
            continue
        deg = g[0] * g[0] + g[1] * g[1] <= 1e-6 or g[0] * x + g[1] * y > 0
        if deg:
            sp[i] = sigma_r ** 2 + floor_p
            sg[i] = 1.0
        if deg or sg[i] > grad_gate:
            rs = np.sqrt(x * x + y * y)
            for c in range(2):
                nrm[i, c] = -((x / rs) * R[c, 0] + (y / rs) * R[c, 1])


def face_runs(p, n, phi, r, dtheta, near, dev, jump, cap):
    """How far the scan's returns run on along the face of each sensor-frame sample point p (k, 2)
    with unit normal n (k, 2): (k, 2) m, on the side of its tangent t = (-n_y, n_x) and of -t.

    From the return nearest the point (none within ``near`` m: zeros, the scan did not see it),
    the returns are followed in both beam directions while each is a neighbour of the one before
    (beams at most 1.5 ``dtheta`` rad apart, end points at most ``jump`` m apart) and lies within
    ``dev`` m of the point's tangent line; the farthest offset along the tangent reached on each
    side is the run, up to ``cap``. At a corner the returns leave the line where the face ends;
    along a face that goes on (the silhouette of a pillar) they keep to it; at a range jump (an
    occluding edge) the run stops: the scan cannot say."""
    k = p.shape[0]
    out = np.zeros((k, 2))
    if k == 0 or len(phi) < 2:
        return out
    K._face_runs_1d(np.ascontiguousarray(p, np.float64), np.ascontiguousarray(n, np.float64),
                    np.ascontiguousarray(phi, np.float64), np.ascontiguousarray(r, np.float64),
                    float(dtheta), float(near), float(dev), float(jump), float(cap), out)
    return out


@entry
@nb.njit(cache=True)
def _face_runs_1d(p, n, phi, r, dtheta, near, dev, jump, cap, out):
    """:func:`face_runs`, one point at a time; writes the runs into ``out`` (k, 2)."""
    m = phi.shape[0]
    hx, hy = r * np.cos(phi), r * np.sin(phi)
    for i in range(p.shape[0]):
        px, py, nx, ny = p[i, 0], p[i, 1], n[i, 0], n[i, 1]
        j = np.searchsorted(phi, np.arctan2(py, px))
        j0, best = -1, near * near
        for c in range(j - 1, j + 1):
            if 0 <= c < m:
                d2 = (hx[c] - px) ** 2 + (hy[c] - py) ** 2
                if d2 <= best:
                    j0, best = c, d2
        if j0 < 0:
            continue
        for step in (1, -1):
            prev = j0
            c = j0 + step
            while 0 <= c < m:
                if abs(phi[c] - phi[prev]) > 1.5 * dtheta:
                    break
                if (hx[c] - hx[prev]) ** 2 + (hy[c] - hy[prev]) ** 2 > jump * jump:
                    break
                vx, vy = hx[c] - px, hy[c] - py
                if abs(vx * nx + vy * ny) > dev:
                    break
                u = nx * vy - ny * vx               # along t = (-n_y, n_x)
                if u > 0.0:
                    out[i, 0] = max(out[i, 0], min(u, cap))
                else:
                    out[i, 1] = max(out[i, 1], min(-u, cap))
                if abs(u) >= cap:
                    break
                prev = c
                c += step
