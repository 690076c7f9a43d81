"""Sample noise model (spec §5) and the re-evaluation / Bayesian fusion of samples (spec §6.2),
vectorised over all candidates of one update. Works in 2D and 3D."""

from __future__ import annotations

import numba as nb
import numpy as np

from polar_sim.gpis._native import K, entry

__all__ = ["normal_noise", "fuse", "RangeNoiseModel"]

_BETA = 1.0          # between-beam interpolation error of the observation GP, in beam spacings
_GATE_MIN = 0.05     # m, smallest association gate of the default-mode re-evaluation


class RangeNoiseModel:
    """Default-mode (2D) sample noise driven by the sensor's range noise and the incidence angle.

    The spec's model (position variance 0.01 r^2 plus a view term that explodes at grazing
    incidence, normal variance grown by the same view term on re-evaluation) makes every sample
    seen from beyond ~10 m, or at a grazing angle, fail the fusion drop gate and the GP's
    gradient gate, although on simulated and real lidars those samples are among the best:
    a return's error lies along its ray, so its error *normal to the surface* shrinks at grazing
    incidence, and its normal is estimated over a surface baseline that grows with the range and
    with the incidence. With ``c`` the cosine between the ray and the surface normal, ``r`` the
    range (m), ``sigma_r`` the range noise (m) and ``dtheta`` the beam spacing (rad):

    - position variance (m^2), the variance of the sample's signed distance to the true surface:
      ``sigma_r^2 c^2 + floor``, plus on re-evaluation the squared normal-direction residual of
      the line search (its ``|oc|`` converted to metres);
    - normal variance (per component, rad^2): the angle error of a normal fitted across beams
      whose normal-direction errors are ``sigma_r c`` and whose spacing on the surface is
      ``r dtheta / c``: ``(kappa sigma_r c^2 / (r dtheta))^2``; ``kappa`` (0.5) is the effective
      finite-difference baseline of the observation GP in beams (its inverse), calibrated on
      exact normals (office2d, 1081 beams: the fitted error goes as r^-0.7 c^1.7, within a
      factor of 2 of this law from 1 to 17 m). The spec's mismatch term ``|oc mean|`` (large where
      the observation GP smooths over a range discontinuity) is kept on top.
    """

    def __init__(self, sigma_r, dtheta, floor_p, kappa=0.5, c_min=0.05, beta=_BETA):
        self.sigma_r, self.dtheta, self.floor_p = float(sigma_r), float(dtheta), float(floor_p)
        self.kappa, self.c_min, self.beta = float(kappa), float(c_min), float(beta)

    def position(self, c):
        """Position variance (m^2) of a return at incidence cosine c."""
        return position_var(c, self.sigma_r, self.floor_p)

    def normal(self, r, c):
        """Normal variance (rad^2) of a return at range r and incidence cosine c."""
        return normal_var(r, c, self.sigma_r, self.dtheta, self.kappa)

    def between(self, r, c):
        """Variance (m^2) of a surface point located between beams (re-evaluation): the
        observation GP's range there is an interpolation over the beam spacing r dtheta, and its
        error normal to the surface is ``beta r dtheta sin(incidence)``."""
        return between_var(r, c, self.dtheta, self.beta)

    @staticmethod
    def residual(A, r, c):
        """Normal-direction distance (m) of a point whose occupancy test reads |oc| = A at range r
        (2D: oc = tanh(15 r (r^-1/2 - rho_hat)), so the range residual is (2/15) sqrt(r) atanh A)."""
        return residual(A, r, c)


# the model's formulas, shared by RangeNoiseModel and the kernels
@nb.njit(cache=True)
def position_var(c, sigma_r, floor_p):
    return (sigma_r * c) ** 2 + floor_p


@nb.njit(cache=True)
def normal_var(r, c, sigma_r, dtheta, kappa):
    return (kappa * sigma_r * c * c / (np.maximum(r, 1e-3) * dtheta)) ** 2


@nb.njit(cache=True)
def between_var(r, c, dtheta, beta):
    return (beta * r * dtheta) ** 2 * (1.0 - c * c)


@nb.njit(cache=True)
def residual(A, r, c):
    return (2.0 / 15.0) * np.sqrt(r) * np.arctanh(np.minimum(A, 0.999)) * c


def normal_noise(g, obar, s, r_term, smin_p, smin_g, R, model=None):
    """New-sample normal (world) and noises from the finite-difference gradient g (n, d).

    ``r_term`` is r^2 in 2D and |s| in 3D (spec §5 step 5). With a :class:`RangeNoiseModel`
    the noises follow it instead (default-mode 2D).
    """
    n = g.shape[0]
    N, sp, sg = np.empty(g.shape), np.empty(n), np.empty(n)
    K._normal_noise_rows(np.ascontiguousarray(g, np.float64), np.ascontiguousarray(obar, np.float64),
                       np.ascontiguousarray(s, np.float64), np.ascontiguousarray(r_term, np.float64),
                       float(smin_p), float(smin_g), np.ascontiguousarray(R, np.float64),
                       *model_args(model), N, sp, sg)
    return N, sp, sg


def model_args(model):
    """(on, sigma_r, dtheta, floor_p, kappa, c_min) of a :class:`RangeNoiseModel` (or None) for
    the kernels."""
    if model is None:
        return False, 0.0, 1.0, 0.0, 0.0, 0.0
    return True, model.sigma_r, model.dtheta, model.floor_p, model.kappa, model.c_min


def _beta(model):
    return _BETA if model is None else model.beta


@entry
@nb.njit(cache=True)
def _normal_noise_rows(g, obar, s, r_term, smin_p, smin_g, R, on, sigma_r, dtheta, floor_p, kappa,
                       c_min, N, sp, sg):
    for i in range(g.shape[0]):
        sp[i], sg[i] = normal_noise_one(g[i], obar[i], s[i], r_term[i], smin_p, smin_g, R, on,
                                        sigma_r, dtheta, floor_p, kappa, c_min, N[i])


@nb.njit(cache=True)
def normal_noise_one(g, obar, s, r_term, smin_p, smin_g, R, on, sigma_r, dtheta, floor_p, kappa,
                     c_min, nrm):
    """One sample of :func:`normal_noise`: its world normal into ``nrm`` (the raw gradient when
    it has none), returns (position noise, gradient noise)."""
    d = g.shape[0]
    g2 = 0.0
    for k in range(d):
        g2 += g[k] * g[k]
    good = g2 > 1e-6
    gn = np.sqrt(g2) if good else 1.0
    sn = 0.0
    ss = 0.0
    for k in range(d):
        sn += s[k] * (g[k] / gn)
        ss += s[k] * s[k]
    rs = np.sqrt(ss)
    if not on:
        c = max(-sn / rs, 0.1)
        sview = smin_p * (1 - c * c) / (c * c)
        sp = smin_p * min(max(r_term, 1.0), 100.0) + sview
        sg = min(max(abs(obar), smin_g), 1.0)
    else:
        c = max(abs(sn) / rs, c_min)
        sp = position_var(c, sigma_r, floor_p)
        sg = min(max(abs(obar) + normal_var(rs, c, sigma_r, dtheta, kappa), smin_g), 1.0)
    for i in range(d):
        if good:
            v = 0.0
            for k in range(d):
                v += (g[k] / gn) * R[i, k]
            nrm[i] = v
        else:
            nrm[i] = g[i]
    return (sp, sg) if good else (100.0, 1.0)


def fuse(m, p, n, P, N, sp_old, sg_old, scan, search, fd_fn, R, t, *, model=None, keep_position=False):
    """Stage 2 (spec §6.2) for candidates with sensor-frame positions p and normals n (k, d)
    and world positions P, normals N and noises ``sp_old``, ``sg_old``.

    ``search(p, n)`` is the line search (:func:`polar_sim.gpis._linesearch.line_search` or the
    planar scan's kernel) and ``fd_fn(q, gp)`` the finite-difference occupancy; sensor-frame
    points map to the world as ``R q + t``. With ``keep_position`` (and a model) a sample whose
    position is trusted but whose normal is not is fused instead of replaced. Returns (action,
    P_new, N_new, sp_new, sg_new); see ``apply_reeval`` for the actions.
    """
    k, d = p.shape
    action = np.zeros(k, np.int8)
    Pn, Nn = np.zeros((k, d)), np.zeros((k, d))
    spn, sgn = np.zeros(k), np.zeros(k)
    live, q, A, rnew, found = search(p, n)                        # step 3
    li = np.nonzero(live)[0]
    if len(li) == 0:
        return action, Pn, Nn, spn, sgn
    oc, fd_ok, rhat = fd_fn(q[li], scan.gp)                        # step 4
    legacy = bool(m._pub("fusion"))
    c = np.ascontiguousarray
    K._fuse_rows(li, q, c(A), c(rnew), found, c(p, np.float64), c(oc, np.float64), fd_ok,
                 c(rhat, np.float64), P, N, sp_old, sg_old, c(R, np.float64), c(t, np.float64),
                 float(m.observation.delx), legacy, legacy and d == 3,
                 float(m.noise.min_position_noise), float(m.noise.min_grad_noise),
                 float(m.noise.map_noise), *model_args(model), _beta(model), bool(keep_position),
                 action, Pn, Nn, spn, sgn)
    return action, Pn, Nn, spn, sgn


@entry
@nb.njit(cache=True)
def _fuse_rows(li, q, A, rnew, found, p, oc, fd_ok, rhat, P, N, sp_old, sg_old, R, t, dx, legacy,
               legacy3d, smin_p, smin_g, map_noise, on, sigma_r, dtheta, floor_p, kappa, c_min, beta,
               keep_position, action, Pn, Nn, spn, sgn):
    """Steps 4-9 for the live candidates li, whose line searches ended at q (sensor frame) and
    whose finite-difference occupancies (oc, fd_ok, rhat; one row per live candidate) were
    taken there: the re-measured normal and noises, their fusion with the stored sample, and
    the action (0 leave, 1 double the noises, 2 fused, 3 drop)."""
    d = q.shape[1]
    g = np.empty(d)
    Pq = np.empty(d)
    Nq = np.empty(d)
    for r in range(li.shape[0]):
        i = li[r]
        gl = 0.0
        for c in range(d):
            g[c] = (oc[r, 2 * c] - oc[r, 2 * c + 1]) / dx
            gl += g[c] * g[c]
        gl = np.sqrt(gl)
        if fd_ok[r] and gl < 1e-3:               # no gradient: double the noises (step 4)
            action[i] = 1
            # with the range model the doubled noises meet the drop gate of fused ones: a sample
            # the rays keep passing through leaves the map instead of staying forever with
            # noises growing as 2^k
            if on and 2 * sp_old[i] > 1 and 2 * sg_old[i] > 0.61:
                action[i] = 3
            continue
        if not (fd_ok[r] and gl >= 1e-3):
            continue
        for c in range(d):
            g[c] /= gl
        sp, sg = _measurement(q[i], g, oc[r], rhat[r], A[i], rnew[i], fd_ok[r], dx, legacy3d, smin_p,
                              smin_g, on, sigma_r, dtheta, floor_p, kappa, c_min, beta)
        for j in range(d):
            Pq[j] = 0.0
            Nq[j] = 0.0
            for c in range(d):
                Pq[j] += q[i, c] * R[j, c]
                Nq[j] += g[c] * R[j, c]
            Pq[j] += t[j]
        # the spec replaces a sample whose position or normal fails its gate. With the range model
        # a sample's position is a return measured along its ray and stays trusted when only its
        # normal (fitted across a corner) is not: keep_position fuses it, so that the new normal
        # takes over (weight sg_old / (sg_old + sg)) while the position moves by its share only.
        # Replaced, it followed the untrusted normal to wherever the line search stopped: 5-12 cm
        # into free space at the corners of the dev warehouse2d maps.
        replace = sp_old[i] > 0.5 or (sg_old[i] > 0.6 and not (on and keep_position))
        spn[i], sgn[i] = _combine(P[i], N[i], sp_old[i], sg_old[i], Pq, Nq, sp, sg, replace,
                                  legacy, on, smin_g, map_noise, floor_p, Pn[i], Nn[i])
        act = 3 if (spn[i] > 1 and sgn[i] > 0.61) else 2              # step 9
        if on and _not_this_surface(q[i], p[i], g, sp, sp_old[i], replace, found[i]):
            act = 0
        action[i] = act


@nb.njit(cache=True)
def _measurement(q, nrm, oc, rhat, A, rnew, fd_ok, dx, legacy3d, smin_p, smin_g, on, sigma_r,
                 dtheta, floor_p, kappa, c_min, beta):
    """Position and normal noise of a re-measured sample at q (sensor frame), unit normal nrm:
    the spec's model (steps 5-7; the published 3D code takes the range of a stencil point), or
    the range-noise model."""
    d = q.shape[0]
    m = oc.shape[0]
    obar = 0.0
    for j in range(m):
        obar += oc[j]
    obar /= m
    qn = 0.0
    rq = 0.0
    for c in range(d):
        qn += q[c] * nrm[c]
        rq += q[c] * q[c]
    rq = np.sqrt(rq)
    if on:
        c = max(abs(qn) / rq, c_min)
        sp = position_var(c, sigma_r, floor_p) + residual(A, rq, c) ** 2 + between_var(rq, c, dtheta, beta)
        return sp, min(max(abs(obar) + normal_var(rq, c, sigma_r, dtheta, kappa), smin_g), 1.0)
    mean = 0.0
    for j in range(m):
        mean += rhat[j]
    mean /= m
    ss = 0.0
    for j in range(m):
        ss += (rhat[j] - mean) * (rhat[j] - mean)
    vr = ss / (m - 1) / dx
    rn = q[2] - dx if (legacy3d and fd_ok) else rnew
    c = max(-qn / rq, 0.1)
    sview = smin_p * (1 - c * c) / (c * c)
    sp = smin_p * min(max(rn * rn, 1.0), 100.0) + sview + A
    return sp, min(max(abs(obar) + vr, smin_g), 1.0) + 0.1 * sview


@nb.njit(cache=True)
def _combine(Po, No, spo, sgo, Pq, Nq, sp, sg, replace, legacy, on, smin_g, map_noise, floor_p,
             Pf, Nf):
    """Step 8: the Bayesian fusion of the stored sample (Po, No, spo, sgo) with the new
    measurement (Pq, Nq, sp, sg) into Pf, Nf; returns the fused (position, gradient) noises.
    A sample whose old noises fail the gate is replaced."""
    d = Po.shape[0]
    if replace:
        for c in range(d):
            Pf[c] = Pq[c]
            Nf[c] = Nq[c]
        return sp, sg
    Sp = sp + spo
    Sg = sg + sgo
    dd = 0.0
    for c in range(d):
        Pf[c] = (sp * Po[c] + spo * Pq[c]) / Sp
        dd += (Po[c] - Pf[c]) * (Po[c] - Pf[c])
    dd = 0.5 * np.sqrt(dd)
    _rotate_toward(No, Nq, sp / Sp if legacy else sgo / Sg, legacy, Nf)
    if on:      # variances in m^2 and rad^2: the displacement enters squared, floors of the model
        return max(sp * spo / Sp + dd * dd, floor_p), min(1.0, max(sg * sgo / Sg, smin_g))
    return max(sp * spo / Sp + dd, map_noise), min(1.0, max(sg * sgo / Sg + dd, map_noise))


@nb.njit(cache=True)
def _rotate_toward(N, Np, w, legacy, out):
    """Rotate the unit normal N toward N' by the fraction w of the angle between them: in 2D by
    the signed angle; in 3D by slerp, or (published) by the spec's DCM of the quaternion with
    the non-normalised axis N' x N."""
    d = N.shape[0]
    dot = 0.0
    for c in range(d):
        dot += N[c] * Np[c]
    if d == 2:
        a = w * np.arctan2(N[0] * Np[1] - N[1] * Np[0], dot)
        ca, sa = np.cos(a), np.sin(a)
        out[0] = ca * N[0] - sa * N[1]
        out[1] = sa * N[0] + ca * N[1]
        return
    al = np.arccos(min(max(dot, -1.0), 1.0))
    if legacy:
        h = np.sin(w * al / 2)
        q0 = np.cos(w * al / 2)
        q1 = (Np[1] * N[2] - Np[2] * N[1]) * h
        q2 = (Np[2] * N[0] - Np[0] * N[2]) * h
        q3 = (Np[0] * N[1] - Np[1] * N[0]) * h
        out[0] = ((q0**2 + q1**2 - q2**2 - q3**2) * N[0] + 2 * (q1 * q2 + q0 * q3) * N[1]
                  + 2 * (q1 * q3 - q0 * q2) * N[2])
        out[1] = (2 * (q1 * q2 - q0 * q3) * N[0] + (q0**2 - q1**2 + q2**2 - q3**2) * N[1]
                  + 2 * (q2 * q3 + q0 * q1) * N[2])
        out[2] = (2 * (q1 * q3 + q0 * q2) * N[0] + 2 * (q2 * q3 - q0 * q1) * N[1]
                  + (q0**2 - q1**2 - q2**2 + q3**2) * N[2])
        return
    s = np.sin(al)
    if s < 1e-9:
        for c in range(d):
            out[c] = N[c]
        return
    a, b = np.sin((1 - w) * al), np.sin(w * al)
    nl = 0.0
    for c in range(d):
        out[c] = (a * N[c] + b * Np[c]) / s
        nl += out[c] * out[c]
    nl = np.sqrt(nl)
    for c in range(d):
        out[c] /= nl


@nb.njit(cache=True)
def _not_this_surface(q, p, nrm, sp, spo, replace, found):
    """Default mode: the re-measurement is not of this sample, which is left as it is.

    - Data association: a line search that had to move the sample further than 3 sigma of the
      two position noises (and 5 cm) found another surface along the normal (an edge seen
      against a farther wall, an occluder); fusing it would drag the sample into free space one
      scan at a time. (The gate is on the measurement noises: the model floor is what the GPs
      cannot resolve; a sample about to be replaced counts the new noise only, its own says
      nothing.)
    - A search that did not reach the observed surface (it stopped on the step limit or an
      unobservable direction): moving such samples a little every scan lets them creep off
      edges into free space. Replacing is no exception: a sample with an untrusted normal
      searched along it across a range jump lands where the observation GP interpolates
      between the near and the far return, in free space (office2d corner samples 10-18 cm off
      the surface).
    - A normal that faces away from the sensor (not the surface the scan sees).
    """
    move = 0.0
    facing = 0.0
    for c in range(q.shape[0]):
        move += (q[c] - p[c]) * (q[c] - p[c])
        facing += q[c] * nrm[c]
    far = np.sqrt(move) > max(3.0 * np.sqrt(sp + (0.0 if replace else spo)), _GATE_MIN)
    return far or not found or facing > 0
