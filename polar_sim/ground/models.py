"""Ground models, data normalisation and (weighted) RANSAC for the scale V (spec §4).

Data per candidate: normalised image coordinates (u, v) of the point at the middle frame and its
scaled inverse depth d̄ = V/Z (1/s). With x = 2u/h, y = 2v/h, s = 3 median(d̄) and δ = d̄/s, a flat
level ground satisfies δ² = V/(2s) · yδ, so V = 2 s · (coefficient of yδ) for every model.

| model    | regressors of δ²                     | sample | notes                                      |
|----------|---------------------------------------|--------|--------------------------------------------|
| 2param   | δ, yδ    (d̄ = a + (V/h) v)           | 2      | text's u2/w2                               |
| 3param   | xδ, yδ, 1                              | 3      | the published code's default (B13)         |
| plane3   | xδ, yδ, δ  (any plane)                 | 3      | fixed suggestion                           |
| 6param   | yδ, x, δ, x², xδ, 1 (2nd-order surface)| 6      | ridge λ on all but yδ; text's u6/w6        |
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from polar_sim._validation import as_rng

__all__ = ["GROUND_MODELS", "GroundFit", "fit_ground", "ransac_iterations", "normalise", "design",
           "default_iterations", "sample_weighted"]

GROUND_MODELS = ("2param", "3param", "plane3", "6param")
_SAMPLE = {"2param": 2, "3param": 3, "plane3": 3, "6param": 6}
_SIGMA = {"2param": 0.005, "3param": 0.005, "plane3": 0.005, "6param": 0.002}
_COND = {"2param": 1e3, "3param": 1e3, "plane3": 1e3, "6param": 1e5}


def ransac_iterations(confidence, outlier_ratio, sample_size):
    """Iterations for a given confidence: ⌈log(1 - c) / log(1 - (1 - outlier_ratio)^s)⌉ (spec T2)."""
    return int(math.ceil(math.log(1.0 - confidence) / math.log(1.0 - (1.0 - outlier_ratio) ** sample_size)))


def default_iterations(model, compat="fixed"):
    """Default RANSAC iterations: 2param 16 (text), 3param/plane3 69 (95 %, 65 % outliers),
    6param 55 (text's odometry runs) or 99 under compat="code" (B18)."""
    if model == "6param":
        return 99 if compat == "code" else 55
    if model == "2param":
        return 16
    return ransac_iterations(0.95, 0.65, 3)


def normalise(u, v, dbar, h):
    """Normalised RANSAC data: x = 2u/h, y = 2v/h, δ = d̄/s with s = 3 median(d̄). Returns (x, y, δ, s)."""
    s = 3.0 * float(np.median(dbar))
    return 2.0 * u / h, 2.0 * v / h, dbar / s, s


def design(model, x, y, delta):
    """Design matrix (N, p) and target δ² (N,) of a ground model; column 0 of 6param and the yδ column
    elsewhere carry the scale (see :func:`_scale_column`)."""
    if model == "2param":
        A = np.stack([delta, y * delta], axis=1)
    elif model == "3param":
        A = np.stack([x * delta, y * delta, np.ones_like(x)], axis=1)
    elif model == "plane3":
        A = np.stack([x * delta, y * delta, delta], axis=1)
    else:
        A = np.stack([y * delta, x, delta, x * x, x * delta, np.ones_like(x)], axis=1)
    return A, delta * delta


def _scale_column(model):
    return 0 if model == "6param" else 1


@dataclass(frozen=True)
class GroundFit:
    """Result of :func:`fit_ground`.

    speed : raw scale V = 2 s m_yδ in m/s (0 if no model was found).
    coef : (p,) coefficients in normalised units (empty if none).
    inliers : (N,) bool inlier mask over the candidates (those of the best hypothesis).
    residuals : (N,) distance of every candidate to the final model, normalised units
        (algebraic for 2param/3param/plane3, coefficient-normalised for 6param); inf if no model.
    sigma : inlier threshold on ``residuals``.
    iterations : RANSAC iterations run.
    ok : a model was found.
    speed_var : variance of ``speed``, (m/s)², from the final least squares on the inliers (the
        residuals' variance propagated to the scale coefficient); inf if no model.
    """

    speed: float
    coef: np.ndarray
    inliers: np.ndarray
    residuals: np.ndarray
    sigma: float
    iterations: int
    ok: bool
    speed_var: float = np.inf


def _failed(n, sigma, iterations):
    return GroundFit(0.0, np.zeros(0), np.zeros(n, dtype=bool), np.full(n, np.inf), sigma, iterations, False)


def sample_weighted(rng, weights, n_iter, size):
    """``n_iter`` samples of ``size`` distinct indices, each drawn without replacement with probability
    proportional to ``weights`` (Efraimidis–Spirakis keys; the same law as
    ``rng.choice(N, size, replace=False, p=w/Σw)``, vectorised). Returns (n_iter, size) int."""
    w = np.maximum(np.asarray(weights, dtype=np.float64), 1e-300)
    keys = np.log(rng.random((n_iter, len(w)))) / w
    idx = np.argpartition(-keys, size - 1, axis=1)[:, :size]
    return idx


def _sample_code(rng, weights, n_iter, size, model):
    """The published cumulative-weight draw: first i with c_i > r (3p) or c_i >= r (6p); 3p redraws the
    whole sample until distinct, 6p redraws each new index until distinct (<= 30 tries)."""
    c = np.cumsum(weights) / np.sum(weights)
    side = "left" if model == "6param" else "right"
    n = len(c)
    out = np.empty((n_iter, size), dtype=np.intp)
    for it in range(n_iter):
        if model == "6param":
            picked = []
            for _ in range(size):
                for _try in range(30):
                    i = min(int(np.searchsorted(c, rng.random(), side=side)), n - 1)
                    if i not in picked:
                        break
                picked.append(i)
            out[it] = picked
        else:
            while True:
                s = np.minimum(np.searchsorted(c, rng.random(size), side=side), n - 1)
                if len(set(s.tolist())) == size:
                    break
            out[it] = s
    return out


def _ridge_solve(A, b, w, lam_diag):
    AtW = A.T * w
    return np.linalg.solve(AtW @ A + np.diag(lam_diag), AtW @ b)


def _coef_variance(A, b, coef, w, lam_diag, column):
    """Variance of ``coef[column]`` of the weighted ridge least squares of ``A coef = b`` (the sandwich
    σ² M⁻¹ Aᵀ W² A M⁻¹, M = Aᵀ W A + Λ, σ² the residuals' variance); inf when under-determined."""
    n, p = A.shape
    if n <= p:
        return np.inf
    r = A @ coef - b
    s2 = float(r @ r) / (n - p)
    try:
        Minv = np.linalg.inv((A.T * w) @ A + np.diag(lam_diag))
    except np.linalg.LinAlgError:
        return np.inf
    cov = s2 * Minv @ ((A.T * (w * w)) @ A) @ Minv
    return float(cov[column, column])


def fit_ground(u, v, dbar, h, *, model="6param", weights=None, n_iter=None, rng=None, lam=0.1,
               sigma=None, compat="fixed"):
    """RANSAC fit of a ground model to candidates; returns a :class:`GroundFit` with the raw scale V.

    Parameters
    ----------
    u, v : (N,) normalised image coordinates (middle frame), v > 0 below the principal row.
    dbar : (N,) scaled inverse depths V/Z, 1/s (positive).
    h : camera height above the ground, m.
    weights : (N,) sampling weights (None = uniform). Used for drawing and, for 6param, in the
        weighted ridge LS (spec §4.5–4.6); under "fixed" each LS solve scales its weights to mean 1, so
        that λ regularises weighted and uniform fits equally (the spec's raw weights under "code").
    n_iter : RANSAC iterations (None = :func:`default_iterations`).
    rng : numpy Generator, int seed or None (= seed 0, so the fit is deterministic).
    lam : ridge weight of the 6param hypotheses (all coefficients but the scale).
    sigma : inlier threshold (None = 0.005 for 2/3-parameter models, 0.002 for 6param).
    compat : "code" reproduces the published cumulative draw with redraws; "fixed" draws without
        replacement in proportion to the weights.
    """
    n = len(u)
    s_size = _SAMPLE[model]
    sigma = _SIGMA[model] if sigma is None else float(sigma)
    n_iter = default_iterations(model, compat) if n_iter is None else int(n_iter)
    if n < max(s_size, 2) + 1 or n_iter < 1:
        return _failed(n, sigma, 0)
    rng = as_rng(0 if rng is None else rng, "rng")
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64)
    if not np.any(w > 0):
        w = np.ones(n)
    x, y, delta, s = normalise(u, v, dbar, h)
    if not np.isfinite(s) or s <= 0:
        return _failed(n, sigma, 0)
    A, b = design(model, x, y, delta)
    sc = _scale_column(model)

    idx = _sample_code(rng, w, n_iter, s_size, model) if compat == "code" else sample_weighted(rng, w, n_iter, s_size)
    As = A[idx]  # (it, s, p)
    bs = b[idx]
    sv = np.linalg.svd(As, compute_uv=False)
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = sv[:, 0] / sv[:, -1]
    good = np.isfinite(cond) & (cond < _COND[model])

    if model == "6param":
        lam_diag = np.full(6, lam)
        lam_diag[0] = 0.0
        ws = w[idx]
        if compat != "code":
            # The ridge λ is meant relative to unit weights: with raw P_G weights (< 1) the weighted LS would
            # run a stronger ridge (λ / mean w) than the uniform one, confounding sampling with
            # regularisation. The fixed mode scales each solve's weights to mean 1; "code" keeps the raw ones.
            ws = ws / np.maximum(ws.mean(axis=1, keepdims=True), 1e-300)
        AtW = np.swapaxes(As, 1, 2) * ws[:, None, :]
        M = np.linalg.solve(AtW @ As + np.diag(lam_diag)[None], (AtW @ bs[..., None]))[..., 0]
        res = (M @ A.T) - b[None, :]
        norm = np.sqrt(1.0 + np.sum(M[:, :5] ** 2, axis=1))
        dist2 = (res / norm[:, None]) ** 2
        inl = dist2 < sigma**2
        counts = np.where(good, inl.sum(axis=1), -1)
        best = int(np.argmax(counts))
        if counts[best] < 2:
            return _failed(n, sigma, n_iter)
        best_inl = inl[best]
        wi = w[best_inl]
        if compat != "code":
            wi = wi / max(float(wi.mean()), 1e-300)
        coef = _ridge_solve(A[best_inl], b[best_inl], wi, lam_diag)
        resid = np.abs(A @ coef - b) / np.sqrt(1.0 + np.sum(coef[:5] ** 2))
        var = _coef_variance(A[best_inl], b[best_inl], coef, wi, lam_diag, sc)
    else:
        # Minimal samples are solved exactly; the candidate model is the LS refit on its inliers.
        M = np.zeros((n_iter, A.shape[1]))
        if good.any():
            M[good] = np.linalg.solve(As[good], bs[good][..., None])[..., 0]
        res = (M @ A.T) - b[None, :]
        inl = res**2 < sigma**2
        counts = np.where(good, inl.sum(axis=1), -1)
        best, best_count, coef = -1, -1, None
        for it in range(n_iter):
            cnt = counts[it]
            if cnt > s_size and cnt > best_count:
                m_ref = np.linalg.lstsq(A[inl[it]], b[inl[it]], rcond=None)[0]
                best, best_count, coef = it, cnt, m_ref
        if best < 0:
            return _failed(n, sigma, n_iter)
        best_inl = inl[best]
        resid = np.abs(A @ coef - b)
        var = _coef_variance(A[best_inl], b[best_inl], coef, np.ones(int(best_inl.sum())), np.zeros(A.shape[1]), sc)
    speed = 2.0 * s * float(coef[sc])
    return GroundFit(speed, coef, best_inl.copy(), resid, sigma, n_iter, True, 4.0 * s * s * var)
