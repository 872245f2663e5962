"""``np.logaddexp`` compiled, bit for bit: numpy's scalar formula, over arrays with a short path
where its ``exp`` underflows, and over MLESAC's mixture terms in one pass.

numpy computes ``logaddexp(x, y)`` element by element with the C library's ``exp`` and ``log1p``
(``npy_logaddexp``), which is what numba's ``math.exp`` and ``math.log1p`` call, so
:func:`logaddexp` gives numpy's bits. MLESAC's mixture likelihood takes it over every residual of
every hypothesis, and under most hypotheses most residuals lie so far outside the gate that
``exp(-|x - y|)`` is 0: there numpy's formula is the larger argument plus ``log1p(0.0)``, which
:func:`logaddexp_2d` adds without calling either function. :func:`mixture_logaddexp` builds the
mixture's two terms ``log g_h + log p_in`` and ``log(1 - g_h) + log p_out`` in the same pass (the
additions numpy would make, so the same values) instead of in two ``(H, N)`` temporaries.
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


@inline_jit
def _logaddexp_or_short(x, y):
    """:func:`logaddexp`, skipping ``exp`` and ``log1p`` where ``exp(-|x - y|)`` underflows to 0."""
    d = x - y
    if x != y and abs(d) > EXP_UNDERFLOW:
        return (x if d > 0 else y) + 0.0  # + log1p(exp(-|d|)) = + log1p(0.0)
    return logaddexp(x, y)


@jit
def logaddexp_2d(a, b):
    """``np.logaddexp(a, b)`` for ``a``, ``b`` of one shape ``(H, N)`` (any strides), bit for bit."""
    H, N = a.shape
    out = np.empty((H, N))
    for h in range(H):
        for n in range(N):
            out[h, n] = _logaddexp_or_short(a[h, n], b[h, n])
    return out


@jit
def mixture_logaddexp(log_g, log_1mg, log_p_in, log_p_out, minus_first):
    """``(H, N)``: ``np.logaddexp(a, b)`` for ``a = log_g[:, None] + log_p_in`` and
    ``b = log_1mg[:, None] + log_p_out`` (``log_g``, ``log_1mg`` ``(H,)``, ``log_p_in (H, N)``,
    ``log_p_out (N,)``), bit for bit; with ``minus_first``, ``a - np.logaddexp(a, b)`` instead
    (an EM step's log responsibilities)."""
    H, N = log_p_in.shape
    out = np.empty((H, N))
    for h in range(H):
        lg, l1 = log_g[h], log_1mg[h]
        for n in range(N):
            a = lg + log_p_in[h, n]
            both = _logaddexp_or_short(a, l1 + log_p_out[n])
            out[h, n] = a - both if minus_first else both
    return out
