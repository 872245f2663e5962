"""The compiled search of BANSAC (Piedade & Miraldo, "BANSAC: A dynamic BAyesian Network for adaptive
SAmple Consensus", ICCV 2023) in its paper's form: one hypothesis drawn, checked, fitted, scored and
fed back into the beliefs at a time, as :class:`stereovo.estimation.loop.RansacSearch` steps batches
of one hypothesis with :class:`stereovo.estimation.methods.bansac.BansacSampler`.

:func:`bansac_search` runs those steps until the search is done or a step needs Python: a new best
model (its local refit and the stopping bound for its support), a runner-up that the loop would
refit, or the end of the uniforms the caller drew. The caller
(:func:`stereovo.estimation.methods.bansac.compiled_bansac_search`) handles such a step with the
loop's own objects and resumes. Every step the kernel completes computes what the loop computes, in
the same order and with the same kernels (the weighted draw, the rigidity check, the minimal fit,
the capped Mahalanobis score, the log-odds update, BANSAC's stop count), so the estimates are the
loop's bit for bit (``tests/stereovo/estimation/methods/test_bansac_runner.py``).

The loop scores a hypothesis on residuals capped at the gate and feeds the beliefs its uncapped
residuals. Below the gate the two are the same number; at or above it the capped value may be a
lower bound of the distance (:func:`~stereovo.estimation.kernels.mahalanobis.mahalanobis_sq`), so a
point whose capped value lies within :data:`VERDICT_GUARD` (relative) of the gate gets its exact
distance here before its verdict is taken. Any other bound is farther from the gate than the
rounding of the exact distance reaches (its relative error is about the 3x3 covariance's condition
number times 1e-16; it would need a condition number near 1e10, where the usable rows of simulated
frames reach about 1e6, default and hostile presets), so its verdict is the uncapped one.

The loop's state travels in an int64 array indexed by the ``S_*`` constants and a float64 array
(``F_*``), read and written by the caller between calls.
"""

from __future__ import annotations

import math

import numpy as np

from stereovo.estimation.kernels.base import inline_jit, jit
from stereovo.estimation.kernels.beliefs import bansac_draw_arrays, bansac_log_odds_update, discretised_weight
from stereovo.estimation.kernels.fitting import minimal_fits
from stereovo.estimation.kernels.mahalanobis import point_mahalanobis_sq, point_mahalanobis_sq_lanes
from stereovo.estimation.kernels.sampling import rigid_triplets, weighted_triplets

# int64 state (the loop's counts and the stop's inputs)
S_DRAWN, S_SCORED, S_CHECKS, S_DEGENERATE, S_REJECTED = 0, 1, 2, 3, 4
S_UPDATES, S_BEST_SEEN, S_BEST_SUPPORT = 5, 6, 7  # the sampler's counts
S_REQUIRED, S_BOUND, S_BEST_COUNT, S_STOPPED = 8, 9, 10, 11  # the loop's bound, the uniform bound, the best's support
S_ROW, S_EVENT_COUNT = 12, 13  # the next uniform row; the event hypothesis' inlier count
STATE_SIZE = 14
# float64 state
F_BEST_SCORE, F_EVENT_SCORE = 0, 1
FLOAT_STATE_SIZE = 2

# why bansac_search returned
DONE, NEW_BEST, RUNNER_UP, UNIFORMS_USED = 0, 1, 2, 3

LEVEL_MARGIN = 1e-7  # log-odds this close to a weight level's edge take the logistic
VERDICT_GUARD = 1e-6  # a capped distance within this relative margin of the gate is recomputed exactly


@jit
def exact_weighted_redraw(w, u, out):
    """:func:`stereovo.estimation.methods.bansac.exact_weighted_draw` compiled: three ordered draws
    without replacement from normalised weights ``w (N,)`` and uniforms ``u (3,)``, each inverting
    the explicitly renormalised weights' cumulative sum (``np.cumsum``: left to right), written
    into ``out (3,)``."""
    n = w.shape[0]
    left = w.copy()
    cdf = np.empty(n)
    for k in range(3):
        running = 0.0
        for i in range(n):
            running += left[i]
            cdf[i] = running
        mass = u[k] * cdf[n - 1]
        lo, hi = 0, n  # np.searchsorted(cdf, mass, side="right")
        while lo < hi:
            mid = (lo + hi) >> 1
            if cdf[mid] <= mass:
                lo = mid + 1
            else:
                hi = mid
        i = lo
        if not (i < n and left[i] > 0):
            # the nearest positive weight, the smaller index on a tie (np.argmin's first minimum)
            best, best_gap = -1, 0
            for j in range(n):
                if left[j] > 0:
                    gap = abs(j - i)
                    if best < 0 or gap < best_gap:
                        best, best_gap = j, gap
            i = best
        out[k] = i
        left[i] = 0.0


@jit
def capped_distances(r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2, norm_t, x0, x1, x2, y0, y1, y2,
                     inv_depth, norm_x, norm_y, inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq,
                     cap, out):
    """``out (N,)``: the capped Mahalanobis distance of every point under one motion, as
    :func:`~stereovo.estimation.kernels.mahalanobis.mahalanobis_sq` computes it (its lanes form
    ``point_mahalanobis_sq_lanes``, bit for bit the branching one), the points as columns
    ``x0 .. y2 (N,)``: a loop that runs on vectors (5 us for 500 points, whatever the motion)."""
    for i in range(x0.shape[0]):
        out[i] = point_mahalanobis_sq_lanes(
            r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2, norm_t,
            x0[i], x1[i], x2[i], y0[i], y1[i], y2[i], inv_depth[i], norm_x[i], norm_y[i],
            inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq, cap,
        )


@jit
def level_edges(levels):
    """``(L + 1,)`` the log-odds where the discretised weight ``max(ceil(L p), 1)`` steps from
    ``k`` to ``k + 1``: ``logit(k / L)``, with -inf and +inf at the ends (``L = levels``, an integer)."""
    L = int(levels)
    edges = np.empty(L + 1)
    edges[0], edges[L] = -np.inf, np.inf
    for k in range(1, L):
        edges[k] = math.log(k / L) - math.log1p(-k / L)
    return edges


@inline_jit
def _level_from(log_odds, level, edges, levels):
    """A point's discretised weight ``(k, known)``, searched from its previous weight ``level``:
    ``known`` when its log-odds lie more than :data:`LEVEL_MARGIN` inside weight k's interval,
    where the weight :func:`~stereovo.estimation.kernels.beliefs.discretised_weight` computes is
    exactly k (the interval's edges are off by rounding only, ~1e-15, and a margin of 1e-7 in
    log-odds keeps ``L p`` at least ~1e-7 L p (1 - p) from an integer, beyond its 1e-9 guard)."""
    L = int(levels)
    k = level
    while k > 1 and log_odds < edges[k - 1] + LEVEL_MARGIN:
        k -= 1
    while k < L and log_odds > edges[k] - LEVEL_MARGIN:
        k += 1
    known = (k == 1 or log_odds > edges[k - 1] + LEVEL_MARGIN) and (k == L or log_odds < edges[k] - LEVEL_MARGIN)
    return k, known


@inline_jit
def _discretised_draw_arrays(log_odds, level, lower, upper, edges, levels, weights, w, cdf, before):
    """:func:`~stereovo.estimation.kernels.beliefs.bansac_draw_arrays`' discretised weights, ``w``,
    ``cdf`` and ``before``, in place. Each point keeps its weight ``level (N,)`` int64 while its
    log-odds stay inside ``(lower, upper)`` (its weight's interval less :data:`LEVEL_MARGIN`; an
    empty interval where the weight took the logistic), a test over all points that runs on vectors;
    a point outside finds its new weight from its previous one (:func:`_level_from`), the logistic
    only where that is too close to call, and its interval is updated. The weights are integers, so
    their sum is exact in any order: it is numpy's pairwise sum."""
    n = log_odds.shape[0]
    L = int(levels)
    moved = 0
    for i in range(n):
        moved += not (lower[i] < log_odds[i] and log_odds[i] < upper[i])
    if moved:
        for i in range(n):
            if not (lower[i] < log_odds[i] < upper[i]):
                k, known = _level_from(log_odds[i], level[i], edges, levels)
                if known:
                    weights[i] = k
                    lower[i] = -np.inf if k == 1 else edges[k - 1] + LEVEL_MARGIN
                    upper[i] = np.inf if k == L else edges[k] - LEVEL_MARGIN
                else:
                    weights[i] = discretised_weight(log_odds[i], levels)
                    lower[i], upper[i] = np.inf, -np.inf
                level[i] = int(weights[i])
    total = 0
    for i in range(n):
        total += level[i]
    total = float(total)
    for i in range(n):  # apart from the running sum, so that it runs on vectors
        w[i] = weights[i] / total
    running = 0.0
    for i in range(n):
        before[i] = running
        running += w[i]
        cdf[i] = running


@jit
def discretised_draw_arrays(log_odds, level, lower, upper, edges, levels):
    """:func:`_discretised_draw_arrays` into new arrays ``(weights, w, cdf, before)``, as
    :func:`~stereovo.estimation.kernels.beliefs.bansac_draw_arrays` returns them (``level``,
    ``lower`` and ``upper`` updated: the state a search keeps between updates; ``level`` each
    point's weight, ``lower = inf``, ``upper = -inf`` where nothing is known yet)."""
    n = log_odds.shape[0]
    weights = level.astype(np.float64)
    w, cdf, before = np.empty(n), np.empty(n), np.empty(n)
    _discretised_draw_arrays(log_odds, level, lower, upper, edges, levels, weights, w, cdf, before)
    return weights, w, cdf, before


@inline_jit
def _classification_scalars(k, n, table_knee, c_max, log_gated_in, log_gated_out):
    """The update's scalars for ``k`` gated points of ``n``, as ``BansacSampler._apply`` rounds them:
    ``(log c, log 0.2 + log(1 - c), log 0.8 + log(1 - c), log(1 - c) - log c)``."""
    r = k / n
    c = 0.62 * r + 0.5 if r < table_knee else 0.2 * r + 0.8
    c = min(c, c_max)
    log_c, log_1mc = math.log(c), math.log1p(-c)
    return log_c, log_gated_in + log_1mc, log_gated_out + log_1mc, log_1mc - log_c


@jit
def update_scalars(k, n, table_knee, c_max, log_gated_in, log_gated_out):
    """:func:`_classification_scalars` callable from Python (the tests hold it to Python's rounding)."""
    return _classification_scalars(k, n, table_knee, c_max, log_gated_in, log_gated_out)


@jit
def bansac_search(
    log_odds, u, state, fstate, discretised, levels, weight_floor, outlier_log_odds,
    table_knee, c_max, log_gated_in, log_gated_out,
    X, Y, mp, mc, cam, cov_prev, cov_curr, sigma_sq, threshold_sq,
    area_ratio, polish_iterations, rigidity_sq, runner_up_fraction, constants, edges, level, lower, upper,
    weights, w, cdf, before, sample_out, R_out, t_out, mask_out, verdicts,
):
    """Run BANSAC's one-hypothesis steps until the search is done or a step needs Python.

    Args:
        log_odds: ``(N,)`` the sampler's beliefs, updated in place.
        u: ``(K, 3)`` uniforms the caller drew from the search's generator, read from row
            ``state[S_ROW]`` on: the row a one-hypothesis batch would draw.
        state, fstate: the loop's state (``S_*``, ``F_*``), read and written.
        discretised, levels, weight_floor: the sampling weights (``BansacSampler``'s).
        outlier_log_odds: ``log(tau / (1 - tau))``, the stop's "ruled out" line.
        table_knee, c_max, log_gated_in, log_gated_out: the update's constants (``bansac``'s).
        X, Y, mp, mc, cam, cov_prev, cov_curr: the problem's arrays; sigma_sq: its pixel variance.
        threshold_sq: the Mahalanobis gate (the residual cap and the verdicts' line).
        area_ratio, polish_iterations: the minimal fit's.
        rigidity_sq: the rigidity check's gate, or <= 0 for no check.
        runner_up_fraction: the loop's runner-up refit fraction, or < 0 for none.
        constants: :func:`~stereovo.estimation.kernels.mahalanobis.point_columns` of the problem's points.
        edges, level, lower, upper: :func:`level_edges` of ``levels``, each point's discretised
            weight ``(N,)`` int64 and the interval of log-odds that keeps it ``(N,)``, kept between
            calls (:func:`discretised_draw_arrays`; unused with ``discretised`` False).
        weights, w, cdf, before: ``(N,)`` the draw arrays, rewritten here.
        sample_out (3,), R_out (3, 3), t_out (3,), mask_out (N,) bool, verdicts (N,) bool: the
            hypothesis of a ``NEW_BEST`` or ``RUNNER_UP`` step, its inliers from the capped
            residuals and its verdicts for the beliefs (otherwise scratch); its score in
            ``fstate[F_EVENT_SCORE]``, its count in ``state[S_EVENT_COUNT]``.

    Returns:
        ``DONE`` (drawn >= required), ``NEW_BEST`` or ``RUNNER_UP`` (the hypothesis was drawn,
        fitted and scored and counted so; the rest of its step is the caller's), ``UNIFORMS_USED``.
    """
    n = X.shape[0]
    fx, fy, bl = cam[0], cam[1], cam[4]
    inv_fx, inv_fy, inv_fb = 1.0 / fx, 1.0 / fy, 1.0 / (fx * bl)
    v_variance = 1.0 / cam[5]
    c_lateral = 2.0 * inv_fx * inv_fx + v_variance * inv_fy * inv_fy
    c_depth = 3.0 * inv_fb * inv_fb
    x0, x1, x2, y0, y1, y2, inv_depth, norm_x, norm_y = constants
    capped = np.empty(n)
    guard, low_guard = threshold_sq * (1.0 + VERDICT_GUARD), threshold_sq * (1.0 - VERDICT_GUARD)
    samples = np.empty((1, 3), dtype=np.int64)
    stale = True  # the draw arrays lag the log-odds
    row = state[S_ROW]
    while state[S_DRAWN] < state[S_REQUIRED]:
        if row >= u.shape[0]:
            state[S_ROW] = row
            return UNIFORMS_USED
        if stale:
            if discretised:
                _discretised_draw_arrays(log_odds, level, lower, upper, edges, levels, weights, w, cdf, before)
            else:
                fresh = bansac_draw_arrays(log_odds, discretised, levels, weight_floor)
                weights[:], w[:], cdf[:], before[:] = fresh[0], fresh[1], fresh[2], fresh[3]
            stale = False
        drawn, suspect = weighted_triplets(u[row:row + 1], w, cdf, before)
        if suspect[0]:
            exact_weighted_redraw(w, u[row], sample_out)
        else:
            sample_out[0], sample_out[1], sample_out[2] = drawn[0, 0], drawn[0, 1], drawn[0, 2]
        row += 1
        state[S_DRAWN] += 1
        samples[0, 0], samples[0, 1], samples[0, 2] = sample_out[0], sample_out[1], sample_out[2]
        if rigidity_sq > 0.0 and not rigid_triplets(samples, X, Y, cov_prev, cov_curr, rigidity_sq)[0]:
            state[S_REJECTED] += 1
            continue  # nothing the stop reads has changed
        R, t, valid = minimal_fits(samples, X, Y, mp, mc, cam, area_ratio, polish_iterations)
        if not valid[0]:
            state[S_DEGENERATE] += 1
            continue
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = (
            R[0, 0, 0], R[0, 0, 1], R[0, 0, 2], R[0, 1, 0], R[0, 1, 1], R[0, 1, 2], R[0, 2, 0], R[0, 2, 1], R[0, 2, 2]
        )
        t0, t1, t2 = t[0, 0], t[0, 1], t[0, 2]
        norm_t = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        capped_distances(r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2, norm_t, x0, x1, x2, y0, y1, y2,
                         inv_depth, norm_x, norm_y, inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth,
                         sigma_sq, threshold_sq, capped)
        count = 0  # the score: inliers by the capped residuals
        near = 0
        for i in range(n):
            inside = capped[i] < threshold_sq
            mask_out[i] = inside
            count += inside
            near += low_guard <= capped[i] and capped[i] < guard
        judged, k = mask_out, count  # the verdicts: by the uncapped residuals, the same unless near the gate
        if near:
            k = 0
            for i in range(n):
                inside = mask_out[i]
                if low_guard <= capped[i] < guard:
                    inside = point_mahalanobis_sq(
                        r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2, norm_t,
                        x0[i], x1[i], x2[i], y0[i], y1[i], y2[i], inv_depth[i], norm_x[i], norm_y[i],
                        inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq, 0.0,
                    ) < threshold_sq
                verdicts[i] = inside
                k += inside
            judged = verdicts
        state[S_SCORED] += 1
        state[S_CHECKS] += n
        score = float(count)
        if score > fstate[F_BEST_SCORE] or (
            runner_up_fraction >= 0.0 and count >= 3 and count >= runner_up_fraction * state[S_BEST_COUNT]
        ):
            R_out[:, :] = R[0]
            t_out[:] = t[0]
            if near == 0:
                verdicts[:] = mask_out
            fstate[F_EVENT_SCORE] = score
            state[S_EVENT_COUNT] = count
            state[S_ROW] = row
            return NEW_BEST if score > fstate[F_BEST_SCORE] else RUNNER_UP
        # the feedback: the beliefs' update from the uncapped residuals, counted as the loop counts it
        state[S_CHECKS] += n
        log_c, gated_offset, gated_scale, shift = _classification_scalars(
            k, n, table_knee, c_max, log_gated_in, log_gated_out
        )
        bansac_log_odds_update(log_odds, judged, log_c, gated_offset, gated_scale, shift)
        stale = True
        state[S_UPDATES] += 1
        state[S_BEST_SEEN] = max(state[S_BEST_SEEN], k)
        state[S_BEST_SUPPORT] = state[S_BEST_COUNT]
        # the termination, asked after the step as the loop asks it (a best exists: this score is not one)
        ruled_out = 0
        for i in range(n):
            ruled_out += log_odds[i] < outlier_log_odds
        if ruled_out >= n - state[S_BEST_COUNT]:
            state[S_STOPPED] = 1
            state[S_REQUIRED] = 0
        else:
            state[S_STOPPED] = 0
            state[S_REQUIRED] = state[S_BOUND]
    state[S_ROW] = row
    return DONE
