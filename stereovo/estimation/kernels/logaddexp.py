"""``np.logaddexp`` compiled, bit for bit: numpy's scalar formula, and over arrays with a short path
where its ``exp`` underflows.

numpy computes ``logaddexp(x, y)`` element by element with the C library's ``exp`` and ``log1p``
(``npy_logaddexp``), which is what numba's ``math.exp`` and ``math.log1p`` call, so
:func:`logaddexp` gives numpy's bits. MLESAC's mixture likelihood takes it over every residual of
every hypothesis, and under most hypotheses most residuals lie so far outside the gate that
``exp(-|x - y|)`` is 0: there numpy's formula is the larger argument plus ``log1p(0.0)``, which
:func:`logaddexp_2d` adds without calling either function.
"""

from __future__ import annotations

import math

import numpy as np

from stereovo.estimation.kernels.base import inline_jit, jit

LOG_2 = 0.693147180559945309417232121458176568  # numpy's NPY_LOGE2
# exp(-d) is 0.0 in float64 beyond this (the smallest subnormal is exp(-744.44))
EXP_UNDERFLOW = 746.0


@inline_jit
def logaddexp(x, y):
    """``np.logaddexp(x, y)`` for two float64, numpy's formula (``npy_logaddexp``)."""
    if x == y:
        return x + LOG_2
    d = x - y
    if d > 0:
        return x + math.log1p(math.exp(-d))
    if d <= 0:
        return y + math.log1p(math.exp(d))
    return d  # a NaN


@jit
def logaddexp_2d(a, b):
    """``np.logaddexp(a, b)`` for ``a``, ``b`` of one shape ``(H, N)`` (any strides), bit for bit."""
    H, N = a.shape
    out = np.empty((H, N))
    for h in range(H):
        for n in range(N):
            x, y = a[h, n], b[h, n]
            d = x - y
            if x != y and abs(d) > EXP_UNDERFLOW:
                out[h, n] = (x if d > 0 else y) + 0.0  # + log1p(exp(-|d|)) = + log1p(0.0)
            else:
                out[h, n] = logaddexp(x, y)
    return out
