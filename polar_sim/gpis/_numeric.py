"""Small numeric kernels shared by the GPIS kernels."""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["_exp_neg"]

_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01     # ln 2 in two parts (Cody-Waite): k * _LN2_HI is exact
_LN2_LO = 1.90821492927058770002e-10


@nb.njit(cache=True, fastmath=False)
def _exp_neg(x, n, work):
    """x[:n] = exp(x[:n]) in place for x <= 0, within 1 ulp of ``np.exp`` (0 below -708).

    A loop that vectorises (numba's scalar ``exp`` is a libm call per element, and the query
    takes one per training sample and point): exp(x) = 2^k exp(f), x = k ln 2 + f, |f| <= ln 2 / 2,
    exp(f) by its Taylor polynomial of degree 13 (truncation < 1e-17 relative); 2^k is built
    from its bits in ``work`` (float64, >= n, viewed as int64).
    """
    bits = work.view(np.int64)
    for p in range(n):
        v = max(x[p], -708.0)
        k = np.floor(v * _LOG2E + 0.5)
        f = (v - k * _LN2_HI) - k * _LN2_LO
        y = 1.0 / 6227020800.0
        y = y * f + 1.0 / 479001600.0
        y = y * f + 1.0 / 39916800.0
        y = y * f + 1.0 / 3628800.0
        y = y * f + 1.0 / 362880.0
        y = y * f + 1.0 / 40320.0
        y = y * f + 1.0 / 5040.0
        y = y * f + 1.0 / 720.0
        y = y * f + 1.0 / 120.0
        y = y * f + 1.0 / 24.0
        y = y * f + 1.0 / 6.0
        y = y * f + 0.5
        y = y * f + 1.0
        y = y * f + 1.0
        x[p] = y if x[p] >= -708.0 else 0.0
        bits[p] = (np.int64(k) + 1023) << 52
    for p in range(n):
        x[p] *= work[p]
