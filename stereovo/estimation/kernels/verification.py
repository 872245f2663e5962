"""Compiled (numba) kernels of early-rejection verification and of the guided stopping bound.

An early-rejection test (the T(d,d) pre-test, Matas & Chum 2002; the SPRT, Matas & Chum 2005)
saves time only if a hypothesis costs what its point checks say. Run point by point in numpy,
each check is a Python-level round; here each hypothesis walks its points in one compiled loop,
computes a point's residual in registers and stops at the decision, so a hypothesis rejected
after j points costs j residuals. The residual is the forward stereo reprojection error of
:func:`stereovo.estimation.kernels.residuals.forward_reprojection_sq` (px^2, ``inf`` behind the camera)
or, for the SPRT under ``probabilistic``'s judge, the 3-D Mahalanobis distance of
:func:`stereovo.estimation.kernels.mahalanobis.mahalanobis_sq`, each with the same arithmetic as
full scoring (one point function), so a compiled check agrees with full scoring bit for bit.

The wrappers in :mod:`stereovo.estimation.methods.tdd`, :mod:`stereovo.estimation.methods.sprt` and
:mod:`stereovo.estimation.roles.samplers` fix the shapes and meaning; nothing else calls this module.
Array arguments are float64 / int64 and C-contiguous (the wrappers ensure it); ``cam`` is
``(fx, fy, cx, cy, baseline, ...)``. No kernel draws random numbers: the callers pass uniforms or a
permutation drawn from their generator.
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels.base import inline_jit, jit
from stereovo.estimation.kernels.mahalanobis import point_mahalanobis_sq
from stereovo.estimation.kernels.residuals import point_reprojection_sq
from stereovo.estimation.kernels.sampling import CANCELLATION



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


@inline_jit
def _first_block(N, log_inconsistent, log_A):
    """The fewest checks that can reach ``log_A`` (inconsistent points only), at least 8, or N: the
    sample's own points are skipped, so a first block this long may decide nothing, never too much."""
    first = N
    if log_inconsistent > 0.0:
        need = log_A / log_inconsistent
        if need < N:
            first = max(int(need) + 1, 8)
    return first


@inline_jit
def _walk_block(buf, perm, start, stop, s0, s1, s2, threshold_sq, log_lambda, n_checked, n_consistent,
                log_consistent, log_inconsistent, log_A):
    """Wald's decisions on the residuals ``buf[start:stop]`` (points ``perm[start:stop]``), skipping the
    sample's own points ``s0, s1, s2``: ``(log_lambda, n_checked, n_consistent, alive)`` after the
    block, ``alive`` False at the first crossing of ``log_A`` (the counts include that point)."""
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
                return log_lambda, n_checked, n_consistent, False
    return log_lambda, n_checked, n_consistent, True


@inline_jit
def _record(h, alive, n_checked, n_consistent, buf, perm, accepted, checked, consistent, out):
    """Hypothesis ``h``'s verdict and counts; an accepted one's residuals ``buf`` (in checking order)
    scattered back to the points' own order in ``out[h]``."""
    accepted[h] = alive
    checked[h] = n_checked
    consistent[h] = n_consistent
    if alive:
        row = out[h]
        for j in range(perm.shape[0]):
            row[perm[j]] = buf[j]


@inline_jit
def _sprt(mahalanobis, R, t, X, Y, mc, cam, sigma_sq, cap, threshold_sq, samples, perm, log_consistent,
          log_inconsistent, log_A):
    """The SPRT walk of :func:`sprt_verify` (``mahalanobis`` False: ``X`` and the pixels ``mc``) and of
    :func:`sprt_verify_mahalanobis` (True: ``X`` and ``Y``, ``sigma_sq``, ``cap``); inlined into each,
    where ``mahalanobis`` is a constant, so each compiles to its own residual's loop."""
    H, N = R.shape[0], X.shape[0]
    fx, fy, cx, cy, b = cam[0], cam[1], cam[2], cam[3], cam[4]
    inv_fx, inv_fy, inv_fb = 1.0 / fx, 1.0 / fy, 1.0 / (fx * b)
    v_variance = 1.0 / cam[5] if mahalanobis else 1.0
    c_lateral = 2.0 * inv_fx * inv_fx + v_variance * inv_fy * inv_fy
    c_depth = 3.0 * inv_fb * inv_fb
    # the points in checking order, as far as some hypothesis reaches: X, then the pixels at k
    # (reprojection) or Y with |X|, |Y| and 1 / y_z (Mahalanobis)
    X0, X1, X2 = np.empty(N), np.empty(N), np.empty(N)
    M0, M1, M2, M3 = np.empty(N), np.empty(N), np.empty(N), np.empty(N)
    norm_x, norm_y = np.empty(N), np.empty(N)
    copied = 0
    first = _first_block(N, log_inconsistent, log_A)
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
        norm_t = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
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
                if mahalanobis:
                    M0[copied], M1[copied], M2[copied] = Y[n, 0], Y[n, 1], Y[n, 2]
                    M3[copied] = 1.0 / Y[n, 2]
                    norm_x[copied] = np.sqrt(X[n, 0] ** 2 + X[n, 1] ** 2 + X[n, 2] ** 2)
                    norm_y[copied] = np.sqrt(Y[n, 0] ** 2 + Y[n, 1] ** 2 + Y[n, 2] ** 2)
                else:
                    M0[copied], M1[copied], M2[copied], M3[copied] = mc[n, 0], mc[n, 1], mc[n, 2], mc[n, 3]
                copied += 1
            for j in range(start, stop):
                if mahalanobis:
                    buf[j] = point_mahalanobis_sq(
                        r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2, norm_t,
                        X0[j], X1[j], X2[j], M0[j], M1[j], M2[j], M3[j], norm_x[j], norm_y[j],
                        inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq, cap,
                    )
                else:
                    buf[j] = point_reprojection_sq(
                        r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2,
                        X0[j], X1[j], X2[j], M0[j], M1[j], M2[j], M3[j], fx, fy, cx, cy, b,
                    )
            log_lambda, n_checked, n_consistent, alive = _walk_block(
                buf, perm, start, stop, s0, s1, s2, threshold_sq, log_lambda, n_checked, n_consistent,
                log_consistent, log_inconsistent, log_A,
            )
            block = 8 if start == 0 else min(2 * block, 128)
            start = stop
        _record(h, alive, n_checked, n_consistent, buf, perm, accepted, checked, consistent, out)
    return accepted, checked, consistent, out


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
    return _sprt(False, R, t, X, X, mc, cam, 1.0, 0.0, threshold_sq, samples, perm, log_consistent,
                 log_inconsistent, log_A)


@jit
def sprt_verify_mahalanobis(R, t, X, Y, cam, sigma_sq, cap, threshold_sq, samples, perm, log_consistent,
                            log_inconsistent, log_A):
    """:func:`sprt_verify` with the 3-D Mahalanobis residual of :func:`~stereovo.estimation.kernels.mahalanobis.mahalanobis_sq`.

    ``X``, ``Y``: ``(N, 3)`` the points triangulated at k-1 and k; ``cam`` the camera's parameters
    (``(fx, fy, cx, cy, baseline, v measurements per match)``); ``sigma_sq`` the pixel noise variance;
    ``cap`` as in ``mahalanobis_sq`` (the gate, when the quality saturates there: a residual at or
    above it may come back as any value >= cap). The walk, the blocks and the returns are those of
    :func:`sprt_verify`; an accepted hypothesis' residuals equal ``mahalanobis_sq``'s bit for bit
    (the same point function).
    """
    return _sprt(True, R, t, X, Y, Y, cam, sigma_sq, cap, threshold_sq, samples, perm, log_consistent,
                 log_inconsistent, log_A)


@inline_jit
def _top_two(w):
    """Indices of the largest and second largest entries of ``w (m,)`` (-1 where ``m`` is smaller)."""
    t1, t2 = -1, -1
    for i in range(w.shape[0]):
        if t1 < 0 or w[i] > w[t1]:
            t2, t1 = t1, i
        elif t2 < 0 or w[i] > w[t2]:
            t2 = i
    return t1, t2


@inline_jit
def _sum_without(w, skip1, skip2):
    """``sum(w)`` without the entries at ``skip1`` and ``skip2`` (-1: none), summed directly."""
    s = 0.0
    for i in range(w.shape[0]):
        if i != skip1 and i != skip2:
            s += w[i]
    return s


@inline_jit
def _inlier_mass_without(w, s, a, b, t1, t2, s1, s12):
    """The inliers' weight without ``a`` and ``b`` (``b`` -1: only ``a``), free of cancellation: what
    is left always holds a weight at least as large as each one taken away, except when the two
    largest (``t1``, ``t2``) are both taken, whose remainder ``s12`` was summed directly (``s1``:
    without ``t1`` alone)."""
    if a == t1 or b == t1:
        other = b if a == t1 else a
        if other == t2:
            return s12
        return s1 if other < 0 else s1 - w[other]
    return s - w[a] if b < 0 else s - w[a] - w[b]


@jit
def weighted_all_inlier_probability(w, outside, total):
    """Chance that three sequential draws without replacement, P(i) proportional to the weights, all
    fall in a set I whose weights are ``w (m,)``; ``outside (k,)`` are the other weights and ``total``
    their sum with ``w``'s (W).

    ``q = sum_{a != b in I} w_a/W * w_b/(W - w_a) * (W_I - w_a - w_b)/(W - w_a - w_b)``: the sum over
    the third index c is done in closed form, so the cost is O(m^2), every term non-negative. The
    masses left, ``W - w_a``, ``W - w_a - w_b`` and ``W_I - w_a - w_b``, are taken as differences; one
    that cancels to under :data:`~stereovo.estimation.kernels.sampling.CANCELLATION` of its whole (a
    weight of 1e300 beside ones: the first draw is that point, and what is left is 1e-300-sized) is
    summed again from the weights that are left, so such priors get their true q instead of 0.
    """
    m = w.shape[0]
    s = 0.0
    for i in range(m):
        s += w[i]
    t1, t2 = _top_two(w)
    s1 = _sum_without(w, t1, -1)
    s12 = _sum_without(w, t1, t2)
    out = _sum_without(outside, -1, -1)
    q = 0.0
    for i in range(m):
        wa = w[i]
        if wa <= 0.0:
            continue
        rest_a = total - wa
        if rest_a < CANCELLATION * total:
            rest_a = out + _inlier_mass_without(w, s, i, -1, t1, t2, s1, s12)
        if rest_a <= 0.0:
            continue
        inner = 0.0
        for j in range(m):
            wb = w[j]
            if j == i or wb <= 0.0:
                continue
            rest_ab = rest_a - wb
            left_in = s - wa - wb
            if rest_ab < CANCELLATION * rest_a or left_in < CANCELLATION * s:
                left_in = _inlier_mass_without(w, s, i, j, t1, t2, s1, s12)
                rest_ab = out + left_in
            if rest_ab <= 0.0:
                continue
            third = left_in / rest_ab
            if third > 1.0:
                third = 1.0
            elif third < 0.0:
                third = 0.0
            inner += wb * third
        q += wa / total * inner / rest_a
    return min(max(q, 0.0), 1.0)
