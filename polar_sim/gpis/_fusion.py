"""Sample noise model (spec §5) and the re-evaluation / Bayesian fusion of samples (spec §6.2),
vectorised over all candidates of one update. Works in 2D and 3D."""

from __future__ import annotations

import numpy as np

__all__ = ["normal_noise", "fuse", "RangeNoiseModel"]

_TOL = 0.02          # line-search tolerance on |oc|
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
        return (self.sigma_r * c) ** 2 + self.floor_p

    def normal(self, r, c):
        return (self.kappa * self.sigma_r * c * c / (np.maximum(r, 1e-3) * self.dtheta)) ** 2

    def between(self, r, c):
        """Variance (m^2) of a surface point located between beams (re-evaluation): the
        observation GP's range there is an interpolation over the beam spacing r dtheta, and its
        error normal to the surface is ``beta r dtheta sin(incidence)``."""
        return (self.beta * r * self.dtheta) ** 2 * (1.0 - c * c)

    @staticmethod
    def residual(A, r, c):
        """Normal-direction distance (m) of a point whose occupancy test reads |oc| = A at range r
        (2D: oc = tanh(15 r (r^-1/2 - rho_hat)), so the range residual is (2/15) sqrt(r) atanh A)."""
        return (2.0 / 15.0) * np.sqrt(r) * np.arctanh(np.minimum(A, 0.999)) * c


def normal_noise(g, obar, s, r_term, smin_p, smin_g, R, model=None):
    """New-sample normal (world) and noises from the finite-difference gradient g (n, d).

    ``r_term`` is r^2 in 2D and |s| in 3D (spec §5 step 5). With a :class:`RangeNoiseModel`
    the noises follow it instead (default-mode 2D).
    """
    g2 = (g * g).sum(1)
    good = g2 > 1e-6
    gn = np.sqrt(np.where(good, g2, 1.0))
    n = g / gn[:, None]
    if model is None:
        c = np.maximum(-(s * n).sum(1) / np.linalg.norm(s, axis=1), 0.1)
        sview = smin_p * (1 - c * c) / (c * c)
        sp = np.where(good, smin_p * np.clip(r_term, 1.0, 100.0) + sview, 100.0)
        sg = np.where(good, np.clip(np.abs(obar), smin_g, 1.0), 1.0)
    else:
        rs = np.linalg.norm(s, axis=1)
        c = np.maximum(np.abs((s * n).sum(1)) / rs, model.c_min)
        sp = np.where(good, model.position(c), 100.0)
        sg = np.where(good, np.clip(np.abs(obar) + model.normal(rs, c), smin_g, 1.0), 1.0)
    N = np.where(good[:, None], n @ R.T, g)
    return N, sp, sg


def _rotate_toward(N, Np, w, legacy):
    """Rotate unit normals N toward N' by the fraction w of the angle between them."""
    d = N.shape[1]
    if d == 2:
        th = np.arctan2(N[:, 0] * Np[:, 1] - N[:, 1] * Np[:, 0], (N * Np).sum(1))
        a = w * th
        c, s = np.cos(a), np.sin(a)
        return np.stack([c * N[:, 0] - s * N[:, 1], s * N[:, 0] + c * N[:, 1]], 1)
    dot = np.clip((N * Np).sum(1), -1.0, 1.0)
    al = np.arccos(dot)
    if legacy:
        # quaternion with the non-normalised axis k = N' x N, applied as the spec's DCM
        k = np.cross(Np, N)
        ph = w * al
        q0 = np.cos(ph / 2)
        q1, q2, q3 = (k * np.sin(ph / 2)[:, None]).T
        D = np.empty((len(N), 3, 3))
        D[:, 0, 0] = q0**2 + q1**2 - q2**2 - q3**2
        D[:, 0, 1] = 2 * (q1 * q2 + q0 * q3)
        D[:, 0, 2] = 2 * (q1 * q3 - q0 * q2)
        D[:, 1, 0] = 2 * (q1 * q2 - q0 * q3)
        D[:, 1, 1] = q0**2 - q1**2 + q2**2 - q3**2
        D[:, 1, 2] = 2 * (q2 * q3 + q0 * q1)
        D[:, 2, 0] = 2 * (q1 * q3 + q0 * q2)
        D[:, 2, 1] = 2 * (q2 * q3 - q0 * q1)
        D[:, 2, 2] = q0**2 - q1**2 - q2**2 + q3**2
        return np.einsum("nij,nj->ni", D, N)
    # slerp on the unit sphere (unit rotation axis)
    sa = np.sin(al)
    small = sa < 1e-9
    sa = np.where(small, 1.0, sa)
    out = (np.sin((1 - w) * al)[:, None] * N + np.sin(w * al)[:, None] * Np) / sa[:, None]
    out = np.where(small[:, None], N, out)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def fuse(m, p, n, P, N, sp_old, sg_old, scan, oc_fn, fd_fn, to_world, R, *, oc_skip, rhat_dim,
         model=None):
    """Stage 2 for candidates with sensor-frame positions p and normals n (k, d).

    Returns (action, P_new, N_new, sp_new, sg_new); see ``apply_reeval`` for the actions.
    """
    k, d = p.shape
    legacy = m._pub("fusion")
    dx = float(m.delx)
    rng = (lambda q: np.linalg.norm(q, axis=1)) if d == 2 else (lambda q: q[:, 2])
    action = np.zeros(k, np.int8)
    Pn, Nn = np.zeros((k, d)), np.zeros((k, d))
    spn, sgn = np.zeros(k), np.zeros(k)
    oc0, obs0, _ = oc_fn(p, scan.gp)
    live = obs0.copy()
    if d == 3:
        live &= p[:, 2] > 0
    with np.errstate(invalid="ignore"):
        live &= ~(oc0 < oc_skip)
    # line search along the stored normal (spec §6.2 step 3)
    q = p.copy()
    delta = np.full(k, dx)
    A = np.abs(oc0)
    occ = oc0.copy()
    rnew = rng(p)
    run = live & (A > _TOL)
    found = live & ~run                  # the line search reached |oc| < tol
    bug3d = legacy and d == 3
    for _ in range(10):
        idx = np.nonzero(run)[0]
        if len(idx) == 0:
            break
        step = np.where(occ[idx] < 0, delta[idx], -delta[idx])
        q[idx] += step[:, None] * n[idx]
        if not bug3d:
            rnew[idx] = rng(q[idx])
        o2, ob2, _ = oc_fn(p[idx] if bug3d else q[idx], scan.gp)
        conv = ob2 & (np.abs(o2) < _TOL)
        found[idx[conv]] = True
        prev = ob2 & ~conv & (occ[idx] < oc_skip)
        cont = ob2 & ~conv & ~prev
        c = idx[cont]
        flip = occ[c] * o2[cont] < 0
        delta[c] = np.where(flip, delta[c] / 2, 1.1 * delta[c])
        A[c] = np.abs(o2[cont])
        occ[c] = o2[cont]
        run[idx] = cont
    # finite differences at q (step 4)
    li = np.nonzero(live)[0]
    if len(li) == 0:
        return action, Pn, Nn, spn, sgn
    ql = q[li]
    oc, fd_ok, rhat = fd_fn(ql, scan.gp)
    g = (oc[:, 0::2] - oc[:, 1::2]) / dx
    obar = oc.mean(1)
    with np.errstate(invalid="ignore"):
        vr = rhat.var(axis=1, ddof=1) / dx
    rn = rnew[li] if not (legacy and d == 3) else ql[:, 2] - dx
    if legacy and d == 3:
        rn = np.where(fd_ok, rn, rnew[li])
    gl = np.linalg.norm(g, axis=1)
    ok = fd_ok & (gl >= 1e-3)
    action[li[fd_ok & (gl < 1e-3)]] = 1
    if model is not None:
        # the doubled noises meet the same drop gate as fused ones (step 9): a sample the rays
        # keep passing through (oc saturated, no gradient) leaves the map instead of staying
        # forever with noises growing as 2^k
        dbl = li[fd_ok & (gl < 1e-3)]
        gone = (2 * sp_old[dbl] > 1) & (2 * sg_old[dbl] > 0.61)
        action[dbl[gone]] = 3
    j = np.nonzero(ok)[0]
    if len(j) == 0:
        return action, Pn, Nn, spn, sgn
    ii = li[j]
    np_ = g[j] / gl[j, None]
    qq = ql[j]
    smin_p = float(m.min_position_noise)
    if model is None:
        c = np.maximum(-(qq * np_).sum(1) / np.linalg.norm(qq, axis=1), 0.1)
        sview = smin_p * (1 - c * c) / (c * c)
        sp = smin_p * np.clip(rn[j] ** 2, 1.0, 100.0) + sview + A[ii]
        sg = np.clip(np.abs(obar[j]) + vr[j], float(m.min_grad_noise), 1.0) + 0.1 * sview
    else:
        rq = np.linalg.norm(qq, axis=1)
        c = np.maximum(np.abs((qq * np_).sum(1)) / rq, model.c_min)
        sp = model.position(c) + model.residual(A[ii], rq, c) ** 2 + model.between(rq, c)
        sg = np.clip(np.abs(obar[j]) + model.normal(rq, c), float(m.min_grad_noise), 1.0)
    Pq = to_world(qq)
    Nq = np_ @ R.T
    # fusion (step 8)
    Po, No, spo, sgo = P[ii], N[ii], sp_old[ii], sg_old[ii]
    replace = (spo > 0.5) | (sgo > 0.6)
    Sp = sp + spo
    Sg = sg + sgo
    Pf = (sp[:, None] * Po + spo[:, None] * Pq) / Sp[:, None]
    dd = 0.5 * np.linalg.norm(Po - Pf, axis=1)
    w = sp / Sp if legacy else sgo / Sg
    Nf = _rotate_toward(No, Nq, w, legacy)
    if model is None:
        sgf = np.minimum(1.0, np.maximum(sg * sgo / Sg + dd, float(m.map_noise)))
        spf = np.maximum(sp * spo / Sp + dd, float(m.map_noise))
    else:   # variances in m^2 and rad^2: the displacement enters squared, floors of the model
        sgf = np.minimum(1.0, np.maximum(sg * sgo / Sg, float(m.min_grad_noise)))
        spf = np.maximum(sp * spo / Sp + dd * dd, model.floor_p)
    Pf = np.where(replace[:, None], Pq, Pf)
    Nf = np.where(replace[:, None], Nq, Nf)
    spf = np.where(replace, sp, spf)
    sgf = np.where(replace, sg, sgf)
    drop = (spf > 1) & (sgf > 0.61)
    act = np.where(drop, 3, 2)
    if model is not None:
        # data association: a line search that had to move the sample further than 3 sigma of
        # the two position noises (and 5 cm) found another surface along the normal (an edge
        # seen against a farther wall, an occluder): leave the sample as it is rather than
        # drag it into free space one scan at a time
        move = np.linalg.norm(qq - p[ii], axis=1)
        # (the gate is on the measurement noises: the model floor is what the GPs cannot resolve;
        # a sample about to be replaced counts the new noise only, its own says nothing)
        far = move > np.maximum(3.0 * np.sqrt(sp + np.where(replace, 0.0, spo)), _GATE_MIN)
        # nor fuse a search that did not reach the observed surface (it stopped on the step
        # limit or an unobservable direction): moving such samples a little every scan lets
        # them creep off edges into free space. Replacing is no exception: a sample with an
        # untrusted normal searched along it across a range jump lands where the observation
        # GP interpolates between the near and the far return, in free space (office2d corner
        # samples 10-18 cm off the surface)
        act = np.where(far | ~found[ii], 0, act)
        # nor take a normal that faces away from the sensor (not the surface the scan sees)
        act = np.where((qq * np_).sum(1) > 0, 0, act)
    action[ii] = act
    Pn[ii], Nn[ii], spn[ii], sgn[ii] = Pf, Nf, spf, sgf
    return action, Pn, Nn, spn, sgn
