"""Compiled (numba) kernels of early-rejection verification and of the guided stopping bound.

An early-rejection test (the T(d,d) pre-test, Matas & Chum 2002; the SPRT, Matas & Chum 2005)
saves time only if a hypothesis costs what its point checks say. Run point by point in numpy,
each check is a Python-level round; here each hypothesis walks its points in one compiled loop,
computes a point's residual in registers and stops at the decision, so a hypothesis rejected
after j points costs j residuals. The residual is the forward stereo reprojection error of
:func:`stereovo.estimation.kernels.residuals.forward_reprojection_sq` (px^2, ``inf`` behind the camera),
with the same arithmetic, so a compiled check agrees with full scoring bit for bit.

The wrappers in :mod:`stereovo.estimation.methods.tdd`, :mod:`stereovo.estimation.methods.sprt` and
:mod:`stereovo.estimation.roles.samplers` fix the shapes and meaning; nothing else calls this module.
Array arguments are float64 / int64 and C-contiguous (the wrappers ensure it); ``cam`` is
``(fx, fy, cx, cy, baseline)``. No kernel draws random numbers: the callers pass uniforms or a
permutation drawn from their generator.
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels.base import inline_jit, jit
from stereovo.estimation.kernels.residuals import point_reprojection_sq



@inline_jit
def _point_sq(R, t, h, X, mc, n, fx, fy, cx, cy, b):
    """Hypothesis ``h``'s squared forward reprojection error (px^2) of point ``n``; ``inf`` behind."""
    return point_reprojection_sq(
        R[h, 0, 0], R[h, 0, 1], R[h, 0, 2], R[h, 1, 0], R[h, 1, 1], R[h, 1, 2],
        R[h, 2, 0], R[h, 2, 1], R[h, 2, 2], t[h, 0], t[h, 1], t[h, 2],
        X[n, 0], X[n, 1], X[n, 2], mc[n, 0], mc[n, 1], mc[n, 2], mc[n, 3], fx, fy, cx, cy, b,
    )


@jit
def tdd_pretest(R, t, X, mc, cam, threshold_sq, samples, u, stop_at_failure):
    """The T(d,d) pre-test of ``H`` hypotheses on d random points each, none of them its own sample.

    Args:
        R, t: ``(H, 3, 3)``, ``(H, 3)`` motions; X ``(N, 3)`` points at k-1; mc ``(N, 4)`` pixels at k.
        threshold_sq: the inlier gate (px^2).
        samples: ``(H, 3)`` each hypothesis' minimal sample (distinct indices).
        u: ``(H, d)`` uniforms in [0, 1); point j of hypothesis h is the ``floor(u[h, j] (N - 3 - j))``-th
            of the points not yet excluded (its sample and its earlier pre-test points), so the d
            points are distinct and uniform over the ``N - 3`` others.
        stop_at_failure: True for the pre-test (a hypothesis stops at its first inconsistent
            point); False checks all d points (a support estimate on a random subset).

    Returns:
        ``(passed (H,) bool, checks (H,) int64, consistent (H,) int64)``: whether all checked points
        were consistent, the points checked and the consistent ones among them.
    """
    H, d = u.shape[0], u.shape[1]
    N = X.shape[0]
    fx, fy, cx, cy, b = cam[0], cam[1], cam[2], cam[3], cam[4]
    passed = np.zeros(H, dtype=np.bool_)
    checks = np.zeros(H, dtype=np.int64)
    consistent = np.zeros(H, dtype=np.int64)
    excluded = np.empty(3 + d, dtype=np.int64)
    for h in range(H):
        # the excluded indices, kept sorted: a rank among the rest is shifted past each one it reaches
        a, bb, c = samples[h, 0], samples[h, 1], samples[h, 2]
        lo, hi = min(a, bb), max(a, bb)
        excluded[0], excluded[1], excluded[2] = min(lo, c), max(lo, min(hi, c)), max(hi, c)
        size = 3
        ok = True
        for j in range(d):
            pool = N - size
            r = int(u[h, j] * pool)
            if r >= pool:
                r = pool - 1
            # the rank's index: shifted past each exclusion it reaches; the exclusions are sorted, so
            # the first one beyond it ends the walk and is where it goes in (one pass, not two)
            idx = r
            e = 0
            while e < size and idx >= excluded[e]:
                idx += 1
                e += 1
            checks[h] += 1
            if _point_sq(R, t, h, X, mc, idx, fx, fy, cx, cy, b) < threshold_sq:
                consistent[h] += 1
            else:
                ok = False
                if stop_at_failure:
                    break
            for k in range(size, e, -1):
                excluded[k] = excluded[k - 1]
            excluded[e] = idx
            size += 1
        passed[h] = ok
    return passed, checks, consistent


@jit
def sprt_verify(R, t, X, mc, cam, threshold_sq, samples, perm, log_consistent, log_inconsistent, log_A):
    """Wald's SPRT on each of ``H`` hypotheses, points in the order ``perm (N,)``, own sample skipped.

    The log likelihood ratio ``log lambda`` (bad model over good model) starts at 0 and moves by
    ``log_consistent = log(delta / epsilon) < 0`` for a point inside the gate and by
    ``log_inconsistent = log((1 - delta) / (1 - epsilon)) > 0`` for one outside; the hypothesis is
    rejected as soon as ``log lambda > log_A``. Working with logarithms, no product can overflow.

    Each hypothesis computes its residuals in blocks (a loop the compiler vectorises, as in full
    scoring) and then walks the block's decisions. No hypothesis can be rejected before
    ``floor(log_A / log_inconsistent) + 1`` checks, so the first block is that long (at least 8);
    later blocks start at 8 and double up to 128. A hypothesis rejected at its j-th point thus costs
    j residuals plus at most a block's overshoot, and an accepted one runs at nearly full-scoring
    speed. The points are copied into contiguous arrays in checking order as far as some hypothesis
    reaches (a batch that rejects everything early copies a prefix, not all N).

    Returns:
        ``(accepted (H,) bool, checked (H,) int64, consistent (H,) int64, residual_sq (H, N))``:
        the points checked up to and including the one that crossed (own sample points are not
        counted), the consistent ones among them, and for an accepted hypothesis its squared
        residual on every point (rows of rejected hypotheses are left unset).
    """
    H, N = R.shape[0], X.shape[0]
    fx, fy, cx, cy, b = cam[0], cam[1], cam[2], cam[3], cam[4]
    X0, X1, X2 = np.empty(N), np.empty(N), np.empty(N)
    M0, M1, M2, M3 = np.empty(N), np.empty(N), np.empty(N), np.empty(N)
    copied = 0
    # the fewest checks that can reach log_A (inconsistent points only); the sample's own points
    # are skipped, so the first block may decide nothing, never too much
    first = N
    if log_inconsistent > 0.0:
        need = log_A / log_inconsistent
        if need < N:
            first = max(int(need) + 1, 8)
    accepted = np.zeros(H, dtype=np.bool_)
    checked = np.zeros(H, dtype=np.int64)
    consistent = np.zeros(H, dtype=np.int64)
    out = np.empty((H, N))
    buf = np.empty(N)
    for h in range(H):
        r00, r01, r02 = R[h, 0, 0], R[h, 0, 1], R[h, 0, 2]
        r10, r11, r12 = R[h, 1, 0], R[h, 1, 1], R[h, 1, 2]
        r20, r21, r22 = R[h, 2, 0], R[h, 2, 1], R[h, 2, 2]
        t0, t1, t2 = t[h, 0], t[h, 1], t[h, 2]
        s0, s1, s2 = samples[h, 0], samples[h, 1], samples[h, 2]
        log_lambda = 0.0
        n_checked = 0
        n_consistent = 0
        alive = True
        start = 0
        block = first
        while start < N and alive:
            stop = min(start + block, N)
            while copied < stop:
                n = perm[copied]
                X0[copied], X1[copied], X2[copied] = X[n, 0], X[n, 1], X[n, 2]
                M0[copied], M1[copied], M2[copied], M3[copied] = mc[n, 0], mc[n, 1], mc[n, 2], mc[n, 3]
                copied += 1
            for j in range(start, stop):
                buf[j] = point_reprojection_sq(
                    r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2,
                    X0[j], X1[j], X2[j], M0[j], M1[j], M2[j], M3[j], fx, fy, cx, cy, b,
                )
            for j in range(start, stop):
                n = perm[j]
                if n == s0 or n == s1 or n == s2:
                    continue
                n_checked += 1
                if buf[j] < threshold_sq:
                    n_consistent += 1
                    log_lambda += log_consistent
                else:
                    log_lambda += log_inconsistent
                    if log_lambda > log_A:
                        alive = False
                        break
            block = 8 if start == 0 else min(2 * block, 128)
            start = stop
        accepted[h] = alive
        checked[h] = n_checked
        consistent[h] = n_consistent
        if alive:
            row = out[h]
            for j in range(N):
                row[perm[j]] = buf[j]
    return accepted, checked, consistent, out


@jit
def weighted_all_inlier_probability(w, total):
    """Chance that three sequential draws without replacement, P(i) proportional to the weights, all
    fall in a set I whose weights are ``w (m,)``; ``total`` is the sum of all N weights (W).

    ``q = sum_{a != b in I} w_a/W * w_b/(W - w_a) * (W_I - w_a - w_b)/(W - w_a - w_b)``: the sum over
    the third index c is done in closed form, so the cost is O(m^2), every term non-negative.
    """
    m = w.shape[0]
    s = 0.0
    for i in range(m):
        s += w[i]
    q = 0.0
    for i in range(m):
        wa = w[i]
        if wa <= 0.0:
            continue
        rest_a = total - wa
        if rest_a <= 0.0:
            continue
        inner = 0.0
        for j in range(m):
            wb = w[j]
            if j == i or wb <= 0.0:
                continue
            rest_ab = rest_a - wb
            if rest_ab <= 0.0:
                continue
            third = (s - wa - wb) / rest_ab
            if third > 1.0:
                third = 1.0
            elif third < 0.0:
                third = 0.0
            inner += wb * third
        q += wa / total * inner / rest_a
    return min(max(q, 0.0), 1.0)
