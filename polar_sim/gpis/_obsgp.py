"""Observation GPs on the current scan (spec §4): partitioned Ornstein-Uhlenbeck regressions.

``ObsGP1D`` regresses rho = r^(-1/2) on beam angle (2D lidar); ``ObsGP2D`` regresses rho = 1/z on
normalised image coordinates (v, u) in tiles (depth camera). Both predict (rho_hat, var) for
batches of query coordinates; unobservable queries get var = 1e6 and rho_hat = NaN.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from polar_sim.gpis._native import K, entry

__all__ = ["ObsGP1D", "ObsGP2D", "UNOBSERVABLE"]

UNOBSERVABLE = 1e6


class ObsGP1D:
    """Piecewise OU GP over the valid beams of one scan (spec §4.2), vectorised.

    Parameters
    ----------
    angles, rho : ndarray of shape (n,)
        Valid beam angles (rad, increasing) and targets r^(-1/2).
    scale, noise : float
        OU length scale (rad) and noise variance.
    group, overlap, margin : int, int, float
        Partition size, overlap (beams) and the angular margin (rad) at both ends.
    """

    def __init__(self, angles, rho, *, scale=0.5, noise=0.01, group=20, overlap=6, margin=0.0175):
        self.scale, self.noise, self.margin = scale, noise, margin
        N = len(angles)
        self.empty = N // group + 1 == 1
        if self.empty:
            return
        self.bounds, self.X, self.C, self.sums, self.nobs = K._fit(
            np.ascontiguousarray(angles, np.float64), np.ascontiguousarray(rho, np.float64),
            float(scale), float(noise), int(group), int(overlap))

    def args(self):
        """The GP's arrays and constants, in the order the 1D kernels take them (``bounds``,
        ``margin``, ``X``, ``C``, ``sums``, ``nobs``, ``scale``, ``noise``; see
        ``_predict_one``); an empty GP has a single bound and answers nothing."""
        if self.empty:
            return (np.zeros(1), float(self.margin), np.zeros((1, 1)), np.zeros(1),
                    np.zeros((5, 1, 2)), np.zeros(1, np.int64), float(self.scale),
                    float(self.noise))
        return (self.bounds, float(self.margin), self.X, self.C, self.sums, self.nobs,
                float(self.scale), float(self.noise))

    def predict(self, phi):
        """(rho_hat, var) at angles phi (any shape)."""
        phi = np.asarray(phi, np.float64)
        shp = phi.shape
        flat = np.ascontiguousarray(phi.ravel())
        rho = np.empty(flat.shape)
        var = np.empty(flat.shape)
        K._predict_1d(flat, *self.args(), rho, var)
        return rho.reshape(shp), var.reshape(shp)


@nb.njit(cache=True)
def _predict_one(x, b, margin, X, C, sums, nobs, scale, noise):
    """(rho_hat, var) of the OU GP at angle x; (NaN, UNOBSERVABLE) outside its groups.

    The OU kernel factorises on either side of x: with t = (x - c) / l, an observation at
    X_j <= x has k_j = e^-t u_j, u_j = e^((X_j - c) / l), and one at X_j > x has k_j = e^t v_j,
    v_j = e^-((X_j - c) / l). So with a = #{X_j <= x} the mean k.alpha and the quadratic form
    k' K^-1 k are sums over the split at a, precomputed for every a (``_split_sums``): O(1) per
    point instead of O(n^2).
    """
    G = b.shape[0] - 1
    if not (G >= 1 and x >= b[0] + margin and x <= b[G] - margin):
        return np.nan, UNOBSERVABLE
    g = np.searchsorted(b, x) - 1          # b[g] < x <= b[g + 1]
    if g < 0 or g >= G or x == b[g + 1]:
        return np.nan, UNOBSERVABLE
    a = np.searchsorted(X[g, :nobs[g]], x, side="right")
    t = (x - C[g]) / scale
    e = np.exp(t)
    ei = np.exp(-t)
    m = ei * sums[0, g, a] + e * sums[1, g, a]
    q = ei * ei * sums[2, g, a] + 2.0 * sums[3, g, a] + e * e * sums[4, g, a]
    return m, 1.0 + noise - q


@entry
@nb.njit(cache=True)
def _predict_1d(phi, b, margin, X, C, sums, nobs, scale, noise, rho, var):
    for i in range(phi.shape[0]):
        rho[i], var[i] = _predict_one(phi[i], b, margin, X, C, sums, nobs, scale, noise)


@entry
@nb.njit(cache=True)
def _fit(x, rho, scale, noise, group, overlap):
    """Partition the N beams (spec §4.2: groups of ``group`` overlapping by ``overlap``, the
    last two splitting the remainder) and fit each group's GP; returns (bounds (G + 1,), X,
    centres, split sums, observations per group)."""
    N = x.shape[0]
    ng = N // group + 1
    G = ng
    ranges = np.empty((G, 2), np.int64)
    bounds = np.empty(G + 1)
    bounds[0] = x[0]
    for g in range(ng - 2):
        i0 = group * g
        ranges[g, 0] = i0
        ranges[g, 1] = i0 + group + overlap - 1
        bounds[g + 1] = x[i0 + group + overlap // 2]
    i1 = group * (ng - 2)
    h = (N - i1) // 2
    ranges[ng - 2, 0] = i1
    ranges[ng - 2, 1] = i1 + h + overlap
    bounds[ng - 1] = x[i1 + h + overlap // 2]
    ranges[ng - 1, 0] = i1 + h
    ranges[ng - 1, 1] = N - 1
    bounds[ng] = x[N - 1]
    M = 0
    nobs = np.empty(G, np.int64)
    for g in range(G):
        nobs[g] = ranges[g, 1] - ranges[g, 0] + 1
        M = max(M, nobs[g])
    X = np.zeros((G, M))
    C = np.zeros(G)
    sums = np.zeros((5, G, M + 1))
    _fit_groups(x, rho, ranges, scale, noise, X, C, sums)
    return bounds, X, C, sums, nobs


@nb.njit(cache=True)
def _fit_groups(x, rho, ranges, scale, noise, X, C, sums):
    """OU GP of each group: its inverse covariance (via Cholesky), the weights K^-1 rho, and
    the split sums of ``_predict_one`` (``_split_sums``)."""
    for g in range(ranges.shape[0]):
        a = ranges[g, 0]
        n = ranges[g, 1] - a + 1
        xc = 0.5 * (x[a] + x[a + n - 1])
        u = np.empty(n)
        v = np.empty(n)
        for j in range(n):
            u[j] = np.exp((x[a + j] - xc) / scale)
            v[j] = np.exp(-(x[a + j] - xc) / scale)
        L = np.zeros((n, n))
        for i in range(n):             # x is sorted: exp(-|x_i - x_j| / l) = v_i u_j for j <= i
            for j in range(i + 1):
                L[i, j] = v[i] * u[j]
            L[i, i] += noise
        for j in range(n):                      # in-place Cholesky (lower)
            s = L[j, j]
            for k in range(j):
                s -= L[j, k] * L[j, k]
            L[j, j] = np.sqrt(s)
            for i in range(j + 1, n):
                s = L[i, j]
                for k in range(j):
                    s -= L[i, k] * L[j, k]
                L[i, j] = s / L[j, j]
        Li = np.zeros((n, n))                   # L^-1 by forward substitution
        for c in range(n):
            for i in range(c, n):
                s = 1.0 if i == c else 0.0
                for k in range(c, i):
                    s -= L[i, k] * Li[k, c]
                Li[i, c] = s / L[i, i]
        Kinv = np.empty((n, n))
        for i in range(n):
            X[g, i] = x[a + i]
            for j in range(i + 1):         # K^-1 = L^-T L^-1, symmetric
                s = 0.0
                for k in range(i, n):
                    s += Li[k, i] * Li[k, j]
                Kinv[i, j] = s
                Kinv[j, i] = s
        alpha = np.empty(n)
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += Kinv[i, j] * rho[a + j]
            alpha[i] = s
        C[g] = xc
        _split_sums(u, v, alpha, Kinv, sums[:, g])


@nb.njit(cache=True)
def _split_sums(u, v, alpha, Kinv, out):
    """For every split a = 0..n of the sorted observations into L = {j < a} and R = {j >= a},
    with u_j = e^((X_j - c) / l), v_j = e^-((X_j - c) / l): out[0, a] = sum_L u alpha, out[1, a] =
    sum_R v alpha, out[2, a] = u_L' K^-1 u_L, out[3, a] = u_L' K^-1 v_R, out[4, a] = v_R' K^-1 v_R
    (each updated from its neighbour: O(n^2) in all)."""
    n = u.shape[0]
    pu = np.empty(n)                 # pu[a] = sum_{i < a} K_ai u_i
    pv = np.empty(n)                 # pv[a] = sum_{j > a} K_aj v_j
    for a in range(n):
        s = 0.0
        for i in range(a):
            s += Kinv[a, i] * u[i]
        pu[a] = s
        s = 0.0
        for j in range(a + 1, n):
            s += Kinv[a, j] * v[j]
        pv[a] = s
    out[0, 0] = 0.0
    out[2, 0] = 0.0
    out[3, 0] = 0.0
    for a in range(n):               # observation a moves from R to L
        out[0, a + 1] = out[0, a] + u[a] * alpha[a]
        out[2, a + 1] = out[2, a] + u[a] * (2.0 * pu[a] + Kinv[a, a] * u[a])
        out[3, a + 1] = out[3, a] - v[a] * pu[a] + u[a] * pv[a]
    out[1, n] = 0.0
    out[4, n] = 0.0
    for a in range(n - 1, -1, -1):
        out[1, a] = out[1, a + 1] + v[a] * alpha[a]
        out[4, a] = out[4, a + 1] + v[a] * (2.0 * pv[a] + Kinv[a, a] * v[a])


@nb.njit(cache=True)
def _chol_inv_tile(xs, noise, scale, out_Kinv, y, out_a):
    n = xs.shape[0]
    K = np.empty((n, n))
    for i in range(n):
        for j in range(i + 1):
            d = 0.0
            for k in range(2):
                e = xs[i, k] - xs[j, k]
                d += e * e
            v = np.exp(-np.sqrt(d) / scale)
            K[i, j] = v
            K[j, i] = v
        K[i, i] += noise
    Ki = np.linalg.inv(K)
    for i in range(n):
        s = 0.0
        for j in range(n):
            out_Kinv[i, j] = Ki[i, j]
            s += Ki[i, j] * y[j]
        out_a[i] = s


@entry
@nb.njit(cache=True)
def _fit_tiles(tiles, slots, rows0, rows1, cols0, cols1, v, u, rho, noise, scale, Mmax,
               TI, TX, TA, TK, TN):
    """Fit the OU GPs of the listed tiles (flat indices into the (nr, nc) grid) into slots."""
    nc = TI.shape[1]
    xs = np.empty((Mmax, 2))
    ys = np.empty(Mmax)
    for r in range(tiles.shape[0]):
        t = tiles[r]
        s = slots[r]
        a = t // nc
        c = t % nc
        n = 0
        for j in range(cols0[c], cols1[c] + 1):       # column-major, row fastest
            for i in range(rows0[a], rows1[a] + 1):
                if rho[i, j] > 0:
                    xs[n, 0] = v[i]
                    xs[n, 1] = u[j]
                    ys[n] = rho[i, j]
                    n += 1
        TI[a, c] = s
        TN[s] = n
        if n > 0:
            TX[s, :n] = xs[:n]
            Ki = np.empty((n, n))
            _chol_inv_tile(xs[:n], noise, scale, Ki, ys[:n], TA[s, :n])
            for i in range(n):
                for j in range(n):
                    TK[s, i, j] = Ki[i, j]


@entry
@nb.njit(cache=True)
def _predict_tiles(qv, qu, bv, bu, margin, TI, TX, TA, TK, TN, scale, noise, rho_out, var_out):
    nr = bv.shape[0] - 1
    nc = bu.shape[0] - 1
    k = np.empty(TX.shape[1])
    for i in range(qv.shape[0]):
        v = qv[i]
        u = qu[i]
        rho_out[i] = np.nan
        var_out[i] = UNOBSERVABLE
        if not (v >= bv[0] + margin and v <= bv[nr] - margin and u >= bu[0] + margin
                and u <= bu[nc] - margin):
            continue
        a = np.searchsorted(bv[1:], v, side="right")
        c = np.searchsorted(bu[1:], u, side="right")
        if a >= nr or c >= nc:
            continue
        t = TI[a, c]
        if t < 0:
            continue
        n = TN[t]
        if n <= 0:
            continue
        m = 0.0
        for j in range(n):
            dv = v - TX[t, j, 0]
            du = u - TX[t, j, 1]
            k[j] = np.exp(-np.sqrt(dv * dv + du * du) / scale)
            m += k[j] * TA[t, j]
        # q = k' Kinv k: four rows at a time (independent sums, each in the original order)
        q = 0.0
        j = 0
        while j + 4 <= n:
            r0 = TK[t, j]
            r1 = TK[t, j + 1]
            r2 = TK[t, j + 2]
            r3 = TK[t, j + 3]
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            s3 = 0.0
            for l in range(n):
                kl = k[l]
                s0 += r0[l] * kl
                s1 += r1[l] * kl
                s2 += r2[l] * kl
                s3 += r3[l] * kl
            q += k[j] * s0
            q += k[j + 1] * s1
            q += k[j + 2] * s2
            q += k[j + 3] * s3
            j += 4
        while j < n:
            r0 = TK[t, j]
            s0 = 0.0
            for l in range(n):
                s0 += r0[l] * k[l]
            q += k[j] * s0
            j += 1
        rho_out[i] = m
        var_out[i] = 1.0 + noise - q


class ObsGP2D:
    """Tiled OU GP over a subsampled depth image (spec §4.3); tiles are fitted lazily.

    Parameters
    ----------
    v, u : ndarray of shape (m,), (n,)
        Normalised coordinates of the subsampled rows and columns (increasing).
    rho : ndarray of shape (m, n)
        1/z for valid pixels, -1 for invalid ones.
    """

    def __init__(self, v, u, rho, *, scale=0.5, noise=0.01, group=5, overlap=3, margin=0.005):
        self.v, self.u, self.rho = v, u, np.ascontiguousarray(rho)
        self.scale, self.noise, self.margin = scale, noise, margin
        self.rows0, self.rows1, self.bv = self._partition(len(v), v, group, overlap)
        self.cols0, self.cols1, self.bu = self._partition(len(u), u, group, overlap)
        nr, nc = len(self.rows0), len(self.cols0)
        self.M = int(max(self.rows1 - self.rows0 + 1) * max(self.cols1 - self.cols0 + 1))
        self.TI = np.full((nr, nc), -1, np.int64)    # slot of a fitted tile, -1 = not fitted yet
        self.n_fit = 0
        self._grow(64)

    def _grow(self, cap):
        M = self.M
        TX, TA = np.zeros((cap, M, 2)), np.zeros((cap, M))
        TK, TN = np.zeros((cap, M, M), np.float32), np.zeros(cap, np.int64)
        if self.n_fit:
            k = self.n_fit
            TX[:k], TA[:k], TK[:k], TN[:k] = self.TX[:k], self.TA[:k], self.TK[:k], self.TN[:k]
        self.TX, self.TA, self.TK, self.TN = TX, TA, TK, TN

    @staticmethod
    def _partition(m, x, group, overlap):
        n = (m - overlap) // group + 1
        s0 = np.arange(n) * group
        s1 = np.minimum(s0 + group + overlap - 1, m - 1)
        s1[-1] = m - 1
        b = np.empty(n + 1)
        b[0] = x[0]
        b[1:n] = x[s0[:-1] + group + 1]
        b[n] = x[m - 1]
        return s0.astype(np.int64), s1.astype(np.int64), b

    def _tiles_of(self, qv, qu):
        nr, nc = self.TI.shape
        a = np.clip(np.searchsorted(self.bv[1:], qv, side="right"), 0, nr - 1)
        c = np.clip(np.searchsorted(self.bu[1:], qu, side="right"), 0, nc - 1)
        return a * nc + c

    def predict(self, qv, qu):
        """(rho_hat, var) at normalised coordinates (v, u), arrays of one shape."""
        qv = np.ascontiguousarray(qv, np.float64).ravel()
        qu = np.ascontiguousarray(qu, np.float64).ravel()
        fin = np.isfinite(qv) & np.isfinite(qu)
        qv = np.where(fin, qv, -1e9)
        qu = np.where(fin, qu, -1e9)
        t = np.unique(self._tiles_of(qv, qu))
        t = t[self.TI.ravel()[t] < 0]
        if len(t):
            if self.n_fit + len(t) > self.TN.shape[0]:
                self._grow(max(self.n_fit + len(t), 2 * self.TN.shape[0]))
            slots = np.arange(self.n_fit, self.n_fit + len(t))
            self.n_fit += len(t)
            K._fit_tiles(t, slots, self.rows0, self.rows1, self.cols0, self.cols1, self.v, self.u,
                       self.rho, self.noise, self.scale, self.M, self.TI, self.TX, self.TA,
                       self.TK, self.TN)
        rho = np.empty(len(qv))
        var = np.empty(len(qv))
        K._predict_tiles(qv, qu, self.bv, self.bu, self.margin, self.TI, self.TX, self.TA, self.TK,
                       self.TN,
                       self.scale, self.noise, rho, var)
        return rho, var
