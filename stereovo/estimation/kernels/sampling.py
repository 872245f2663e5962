"""Compiled sampling of minimal samples and their check before a fit.

:func:`distinct_triplets` (uniform) and :func:`weighted_triplets` (proportional to weights)
draw three distinct indices per row from given uniforms; :func:`prior_defects` checks the
weights in one pass and :func:`cumulative_weights` builds the weighted draw's tables; :func:`rigid_triplets` keeps the samples whose pairwise distances agree
between k-1 and k (:mod:`stereovo.estimation.kernels.rigidity`).
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels.base import inline_jit, jit
from stereovo.estimation.kernels.beliefs import numpy_sum
from stereovo.estimation.kernels.rigidity import distance_change_sq_jit, rigid_distance_consistent_jit

# A mass left after one or two picks that is below this share of the whole has lost most of its
# digits to cancellation (one or two weights hold nearly all of it): a draw inverting the cumulative
# sums there cannot tell the remaining points apart well (its relative error grows as 1e-16 over the
# share), and the probability of an all-inlier draw cannot take the difference either. The
# environments' weights (exp of actions in [-10, 10], at least 1e-6 of the mass left beside the two
# largest of 500) never come near it.
CANCELLATION = 1e-9


@jit
def distinct_triplets(u, m):
    """Three distinct indices per row from uniforms ``u (B, 3)`` and pool sizes ``m (B,)``.

    Draws from ``range(m)``, ``range(m - 1)``, ``range(m - 2)`` and shifts each index past
    those already taken: exact sampling without replacement, no rejection.
    """
    B = u.shape[0]
    out = np.empty((B, 3), dtype=np.int64)
    for k in range(B):
        mk = m[k]
        a = min(np.int64(u[k, 0] * mk), mk - 1)
        b = min(np.int64(u[k, 1] * (mk - 1)), mk - 2)
        c = min(np.int64(u[k, 2] * (mk - 2)), mk - 3)
        if b >= a:
            b += 1
        lo, hi = min(a, b), max(a, b)
        if c >= lo:
            c += 1
        if c >= hi:
            c += 1
        out[k, 0], out[k, 1], out[k, 2] = a, b, c
    return out

@inline_jit
def _first_above(cdf, mass):
    """Index of the first ``cdf`` entry above ``mass`` (``np.searchsorted(cdf, mass, "right")``),
    capped at the last index."""
    lo, hi = 0, cdf.shape[0]
    while lo < hi:
        mid = (lo + hi) >> 1
        if cdf[mid] <= mass:
            lo = mid + 1
        else:
            hi = mid
    return min(lo, cdf.shape[0] - 1)


@jit
def weighted_triplets(u, w, cdf, before):
    """Ordered draws without replacement, P(i) proportional to ``w (N,)``, from uniforms ``u (B, 3)``.

    ``cdf`` and ``before`` are the inclusive and exclusive cumulative sums of ``w``. Each draw
    inverts the cumulative weights with the indices already drawn cut out of them (a position in
    the remaining mass is shifted past each drawn interval it reaches). Rounding at an interval's
    edge can return a drawn or zero-weight index, and a mass left under :data:`CANCELLATION` of the
    whole (weights of 1e200 beside ones) cannot be resolved by the cumulative sums: those rows are
    flagged in ``suspect (B,)`` for the caller to redraw exactly. Returns ``(samples (B, 3), suspect (B,))``.
    """
    B = u.shape[0]
    total = cdf[cdf.shape[0] - 1]
    out = np.empty((B, 3), dtype=np.int64)
    suspect = np.zeros(B, dtype=np.bool_)
    for k in range(B):
        a = _first_above(cdf, u[k, 0] * total)
        left_a = total - w[a]
        x = u[k, 1] * left_a
        b = _first_above(cdf, x if x < before[a] else x + w[a])
        lo, hi = min(a, b), max(a, b)
        left_ab = total - w[a] - w[b]
        x = u[k, 2] * left_ab
        if not x < before[lo]:
            x = x + w[lo]
        c = _first_above(cdf, x if x < before[hi] else x + w[hi])
        out[k, 0], out[k, 1], out[k, 2] = a, b, c
        suspect[k] = (b == a or c == a or c == b or w[a] == 0 or w[b] == 0 or w[c] == 0
                      or left_a < CANCELLATION * total or left_ab < CANCELLATION * total)
    return out, suspect


@jit
def prior_defects(p):
    """One pass over priors ``p (N,)``: ``(any non-finite, minimum, number of positive weights)``."""
    nonfinite = False
    minimum = np.inf
    positive = 0
    for i in range(p.shape[0]):
        x = p[i]
        if not np.isfinite(x):
            nonfinite = True
        elif x < minimum:
            minimum = x
        if x > 0:
            positive += 1
    return nonfinite, minimum, positive


@jit
def cumulative_weights(p, tiny):
    """A guided sampler's tables from valid priors ``p (N,)`` in one pass: ``w = p / sum(p)`` (the sum
    numpy's pairwise one, bit for bit), the inclusive and exclusive cumulative sums (numpy's
    running ``cumsum``), whether the positive weights are all equal and how many there are.

    Returns ``(w, cdf, before, equal, n_positive, direct)``; ``direct`` is False where the sum is not
    a finite number of at least ``tiny`` or a positive weight's quotient falls below ``tiny``: the
    caller then takes :func:`stereovo.estimation.roles.samplers.normalised_weights`' careful path,
    and the other values are not to be read.
    """
    N = p.shape[0]
    w = np.empty(N)
    cdf = np.empty(N)
    before = np.empty(N)
    total = numpy_sum(p)
    if not (np.isfinite(total) and total >= tiny):
        return w, cdf, before, False, 0, False
    running = 0.0
    first = 0.0
    n_positive = 0
    equal = True
    for i in range(N):
        wi = p[i] / total
        if p[i] > 0 and wi < tiny:
            return w, cdf, before, False, 0, False
        w[i] = wi
        if wi > 0:
            if n_positive == 0:
                first = wi
            elif wi != first:
                equal = False
            n_positive += 1
        before[i] = running
        running += wi
        cdf[i] = running
    return w, cdf, before, equal, n_positive, True


@inline_jit
def _summed_quadratic_form(cov, a, b, x0, x1, x2):
    """``x^T (cov[a] + cov[b]) x`` for symmetric ``cov (N, 3, 3)``."""
    S, T = cov[a], cov[b]
    return (
        x0 * x0 * (S[0, 0] + T[0, 0]) + x1 * x1 * (S[1, 1] + T[1, 1]) + x2 * x2 * (S[2, 2] + T[2, 2])
        + 2.0 * (x0 * x1 * (S[0, 1] + T[0, 1]) + x0 * x2 * (S[0, 2] + T[0, 2]) + x1 * x2 * (S[1, 2] + T[1, 2]))
    )


@inline_jit
def _pair_is_rigid(X, Y, cov_prev, cov_curr, a, b, threshold_sq):
    """The rigid-distance test (:mod:`stereovo.estimation.kernels.rigidity`) for points ``a`` and ``b``: their
    distance changes from k-1 to k by less than ``sqrt(threshold_sq)`` standard deviations, ``var``
    carrying both points' triangulation covariances in both frames onto the direction between them
    (first order). False for coincident points."""
    x0, x1, x2 = X[a, 0] - X[b, 0], X[a, 1] - X[b, 1], X[a, 2] - X[b, 2]
    y0, y1, y2 = Y[a, 0] - Y[b, 0], Y[a, 1] - Y[b, 1], Y[a, 2] - Y[b, 2]
    lx_sq = x0 * x0 + x1 * x1 + x2 * x2
    ly_sq = y0 * y0 + y1 * y1 + y2 * y2
    if not (lx_sq > 0.0 and ly_sq > 0.0):
        return False
    # u^T S u for the unit direction u: the quadratic forms of the difference vectors over their squared lengths
    var = _summed_quadratic_form(cov_prev, a, b, x0, x1, x2) / lx_sq
    var += _summed_quadratic_form(cov_curr, a, b, y0, y1, y2) / ly_sq
    return rigid_distance_consistent_jit(distance_change_sq_jit(x0, x1, x2, y0, y1, y2), var, threshold_sq)


@jit
def rigid_triplets(samples, X, Y, cov_prev, cov_curr, threshold_sq):
    """``(H,)`` True where all three pairwise distances of a sample agree between k-1 and k within
    ``threshold_sq`` (a chi-square(1) quantile) of their standardised change."""
    H = samples.shape[0]
    keep = np.empty(H, dtype=np.bool_)
    for h in range(H):
        i, j, k = samples[h, 0], samples[h, 1], samples[h, 2]
        keep[h] = (
            _pair_is_rigid(X, Y, cov_prev, cov_curr, i, j, threshold_sq)
            and _pair_is_rigid(X, Y, cov_prev, cov_curr, i, k, threshold_sq)
            and _pair_is_rigid(X, Y, cov_prev, cov_curr, j, k, threshold_sq)
        )
    return keep
