"""The loop's search compiled for the ``probabilistic`` judge: uniform draws, the rigidity check, the
minimal fits, the Mahalanobis count, the new bests with their consensus refit, the runner-up refits
and the stopping bound, batch after batch, in one call.

:func:`batch_search` runs what :meth:`stereovo.estimation.loop.RansacSearch.step` does, batch by
batch, for a uniform sampler, the optional rigidity check, full verification by the 3-D Mahalanobis
inlier count, the consensus refit (:class:`~stereovo.estimation.roles.local_optimization.ConsensusRefit`
on the judge's gate) or none, and the uniform adaptive bound or a fixed budget, whose listeners do
nothing: the kernels the loop's roles call, on the same arguments and in the same order, and the
loop's bookkeeping written out, so the estimates are the loop's bit for bit
(``tests/stereovo/estimation/test_compiled_search.py``). It returns only when the search is done or
the uniforms the caller drew run out (:mod:`stereovo.estimation.compiled_search` draws the next block).

At an inlier ratio of 0.1 a frame takes some 30 batches; in the loop each costs about 25 us of Python
around its kernels, a tenth of a frame at N 500 (docs/performance.md, "Hostile match errors").

The loop's counts travel in an int64 array indexed by the ``S_*`` constants, its best model in
arrays the caller passes and reads back (``best_R``, ``best_t``, ``best_inliers``) and its score in
a float64 array (``F_*``).
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels.base import jit
from stereovo.estimation.kernels.fitting import minimal_fits
from stereovo.estimation.kernels.mahalanobis import mahalanobis_sq
from stereovo.estimation.kernels.refinement import GATE_MAHALANOBIS, refine_rounds
from stereovo.estimation.kernels.sampling import distinct_triplets, rigid_triplets
from stereovo.estimation.kernels.scores import count_below
from stereovo.estimation.kernels.stopping import adaptive_bound

# int64 state: the loop's counts, its bound and batch schedule, the best model's support and when it was found
S_DRAWN, S_SCORED, S_CHECKS, S_DEGENERATE, S_REJECTED = 0, 1, 2, 3, 4
S_REQUIRED, S_NEXT_SIZE, S_BEST_COUNT, S_ROW, S_FOUND_AT = 5, 6, 7, 8, 9
S_LOCAL_RUNS, S_RUNNER_UP_RUNS, S_RUNNER_UP_WINS = 10, 11, 12
S_REFIT_RUNS, S_REFIT_IMPROVED = 13, 14  # the consensus refit's own counts
STATE_SIZE = 15
# float64 state
F_BEST_SCORE = 0
FLOAT_STATE_SIZE = 1

# why batch_search returned
DONE, UNIFORMS_USED = 0, 1


@jit
def required_draws(count, n, confidence, max_iterations, min_iterations, budget):
    """The termination's ``required(count, n)``: ``budget`` if positive (a fixed budget), else the
    uniform adaptive bound of three draws (:func:`~stereovo.estimation.kernels.stopping.adaptive_bound`,
    which the termination role calls too) raised to ``min_iterations``."""
    if budget > 0:
        return budget
    return max(adaptive_bound(count, n, confidence, max_iterations, 3), min_iterations)


@jit
def _consensus_refit(R, t, inliers, score, X, Y, mp, mc, cam, cov_prev, cov_curr, sigma_sq, threshold_sq, rounds,
                     iterations, huber, damping, tolerance, state):
    """:meth:`ConsensusRefit.improve` of ``(R, t, inliers (N,), score)``: ``(R, t, inliers, score,
    spent)``, the refit where it scores higher, else the input; its counts into ``state``."""
    n = X.shape[0]
    count = 0
    for i in range(n):
        count += inliers[i]
    if count < 3:
        return R, t, inliers, score, 0
    state[S_REFIT_RUNS] += 1
    R_new, t_new, _, refit_sq, computed = refine_rounds(
        R, t, X, Y, mp, mc, cam, cov_prev, cov_curr, sigma_sq, inliers, GATE_MAHALANOBIS, threshold_sq, False,
        rounds, iterations, huber, damping, tolerance, np.empty(0),
    )
    spent = n * rounds
    if not computed:  # the motion given back, which the refit scores anew (capped, as the loop's context does)
        R_one, t_one = np.empty((1, 3, 3)), np.empty((1, 3))
        R_one[0], t_one[0] = R_new, t_new
        refit_sq = mahalanobis_sq(R_one, t_one, X, Y, cam, sigma_sq, threshold_sq)[0]
        spent += n
    new_score = 0.0
    for i in range(n):
        new_score += refit_sq[i] < threshold_sq
    if new_score > score:
        state[S_REFIT_IMPROVED] += 1
        return R_new, t_new, refit_sq < threshold_sq, new_score, spent
    return R, t, inliers, score, spent


@jit
def batch_search(
    u, state, fstate, best_R, best_t, best_inliers, X, Y, mp, mc, cam, cov_prev, cov_curr, sigma_sq, threshold_sq,
    area_ratio, polish_iterations, rigidity_sq, local_refit, redundant_refit, runner_up_fraction, refit_rounds,
    refit_iterations, refit_huber, damping, tolerance, confidence, max_iterations, min_iterations, budget, batch_size,
):
    """Run the loop's batches until the search is done or the uniforms run out.

    Args:
        u: ``(K, 3)`` uniforms the caller drew from the search's generator, read from row
            ``state[S_ROW]`` on: the rows the sampler's next draws would take.
        state, fstate: the loop's counts (``S_*``) and best score (``F_*``), read and written.
        best_R (3, 3), best_t (3,), best_inliers (N,) bool: the best model, read and written.
        X, Y, mp, mc, cam, cov_prev, cov_curr: the problem's arrays; sigma_sq: its pixel variance.
        threshold_sq: the Mahalanobis gate (the residuals' cap and the count's line).
        area_ratio, polish_iterations: the minimal fit's.
        rigidity_sq: the rigidity check's gate, or <= 0 for no check.
        local_refit: whether a consensus refit is the local optimiser; redundant_refit: whether it is
            skipped on a best found in the batch that ends the search (the loop's
            ``local_refit_redundant``: a final refinement follows).
        runner_up_fraction: the loop's runner-up refit fraction, or < 0 for none.
        refit_rounds, refit_iterations, refit_huber, damping, tolerance: the consensus refit's
            :func:`~stereovo.estimation.kernels.refinement.refine_rounds` settings.
        confidence, max_iterations, min_iterations, budget: the termination's (``budget`` > 0 for a
            fixed budget; :func:`required_draws`).
        batch_size: the largest batch.

    Returns:
        ``DONE`` (drawn >= required) or ``UNIFORMS_USED`` (the next batch needs more rows).
    """
    n = X.shape[0]
    pool = np.full(batch_size, n, dtype=np.int64)
    row = state[S_ROW]
    while state[S_DRAWN] < state[S_REQUIRED]:
        batch = min(state[S_NEXT_SIZE], state[S_REQUIRED] - state[S_DRAWN])
        if row + batch > u.shape[0]:
            state[S_ROW] = row
            return UNIFORMS_USED
        state[S_NEXT_SIZE] = min(2 * state[S_NEXT_SIZE], batch_size)
        samples = distinct_triplets(u[row:row + batch], pool[:batch])
        row += batch
        state[S_DRAWN] += batch
        if rigidity_sq > 0.0:
            keep = rigid_triplets(samples, X, Y, cov_prev, cov_curr, rigidity_sq)
            kept = 0
            for h in range(batch):
                kept += keep[h]
            state[S_REJECTED] += batch - kept
            samples = samples[keep]
        R, t, valid = minimal_fits(samples, X, Y, mp, mc, cam, area_ratio, polish_iterations)
        n_valid = 0
        for h in range(valid.shape[0]):
            n_valid += valid[h]
        state[S_DEGENERATE] += valid.shape[0] - n_valid
        if n_valid:
            if n_valid < valid.shape[0]:
                R, t = R[valid], t[valid]
            sq = mahalanobis_sq(R, t, X, Y, cam, sigma_sq, threshold_sq)
            scores = count_below(sq, threshold_sq)
            _take_scores(R, t, sq, scores, state, fstate, best_R, best_t, best_inliers, X, Y, mp, mc, cam, cov_prev,
                         cov_curr, sigma_sq, threshold_sq, local_refit, redundant_refit, runner_up_fraction,
                         refit_rounds, refit_iterations, refit_huber, damping, tolerance, confidence, max_iterations,
                         min_iterations, budget)
        if fstate[F_BEST_SCORE] > -np.inf:  # the loop's end_batch: the bound for the best's support
            state[S_REQUIRED] = min(required_draws(float(state[S_BEST_COUNT]), n, confidence, max_iterations,
                                                   min_iterations, budget), max_iterations)
    state[S_ROW] = row
    return DONE


@jit
def _take_scores(R, t, sq, scores, state, fstate, best_R, best_t, best_inliers, X, Y, mp, mc, cam, cov_prev,
                 cov_curr, sigma_sq, threshold_sq, local_refit, redundant_refit, runner_up_fraction, refit_rounds,
                 refit_iterations, refit_huber, damping, tolerance, confidence, max_iterations, min_iterations,
                 budget):
    """:meth:`RansacSearch.take_scores` for a scored batch ``R (H, 3, 3)``, ``t (H, 3)`` with capped
    residuals ``sq (H, N)`` and counts ``scores (H,)``: its new best with the consensus refit, its
    runner-up refit, the counts."""
    n, H = X.shape[0], R.shape[0]
    refit = (X, Y, mp, mc, cam, cov_prev, cov_curr, sigma_sq, threshold_sq, refit_rounds, refit_iterations,
             refit_huber, damping, tolerance, state)
    state[S_SCORED] += H
    state[S_CHECKS] += H * n
    top = 0  # np.argmax: the first maximum
    for h in range(1, H):
        if scores[h] > scores[top]:
            top = h
    earlier_best = fstate[F_BEST_SCORE] > -np.inf
    new_best = scores[top] > fstate[F_BEST_SCORE]
    if new_best:  # the loop's _new_best: the inliers read from the batch's residuals
        R_b, t_b, inliers, score = R[top], t[top], sq[top] < threshold_sq, scores[top]
        count = 0
        for i in range(n):
            count += inliers[i]
        state[S_FOUND_AT] = state[S_DRAWN]
        if local_refit and not (redundant_refit and state[S_DRAWN] >= min(
                required_draws(float(count), n, confidence, max_iterations, min_iterations, budget), max_iterations)):
            R_b, t_b, inliers, score, spent = _consensus_refit(R_b, t_b, inliers, score, *refit)
            state[S_LOCAL_RUNS] += 1
            state[S_CHECKS] += spent
        _set_best(R_b, t_b, inliers, score, state, fstate, best_R, best_t, best_inliers)
    if runner_up_fraction >= 0.0 and local_refit and earlier_best and not (new_best and H < 2):
        # the loop's _refit_runner_up: the batch's best hypothesis other than a new best
        j = -1
        for h in range(H):
            if not (new_best and h == top) and (j < 0 or scores[h] > scores[j]):
                j = h
        inliers = sq[j] < threshold_sq
        count = 0
        for i in range(n):
            count += inliers[i]
        if count >= 3 and not count < runner_up_fraction * state[S_BEST_COUNT]:
            R_j, t_j, inliers_j, score_j, spent = _consensus_refit(R[j], t[j], inliers, scores[j], *refit)
            state[S_RUNNER_UP_RUNS] += 1
            state[S_CHECKS] += spent
            if score_j > fstate[F_BEST_SCORE]:
                state[S_RUNNER_UP_WINS] += 1
                state[S_FOUND_AT] = state[S_DRAWN]
                _set_best(R_j, t_j, inliers_j, score_j, state, fstate, best_R, best_t, best_inliers)


@jit
def _set_best(R, t, inliers, score, state, fstate, best_R, best_t, best_inliers):
    """The best model ``(R, t, inliers, score)`` into the caller's arrays, its support into ``state``."""
    best_R[:, :] = R
    best_t[:] = t
    count = 0
    for i in range(inliers.shape[0]):
        best_inliers[i] = inliers[i]
        count += inliers[i]
    state[S_BEST_COUNT] = count
    fstate[F_BEST_SCORE] = score
