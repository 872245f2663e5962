"""The loop's batches compiled: uniform draws, the rigidity check, the minimal fits and the
Mahalanobis count, batch after batch, until a batch needs Python.

:func:`batch_search` runs what :meth:`stereovo.estimation.loop.RansacSearch.step` does for the
``probabilistic`` judge (a uniform sampler, the optional rigidity check, full verification by the
3-D Mahalanobis inlier count) for as long as a batch changes nothing but the counts: no new best
and no runner-up to refit, so that the stopping bound stays what it was. A batch that does either
is handed back whole (its hypotheses, samples, capped residuals and scores) for the loop's own
objects to take (:mod:`stereovo.estimation.compiled_search`). Every batch runs the kernels the
loop's roles call, on the same arguments and in the same order, so the estimates are the loop's
bit for bit (``tests/stereovo/estimation/test_compiled_search.py``).

At an inlier ratio of 0.1 a frame takes some 30 batches, most of which find nothing; in the loop
each costs about 25 us of Python around its kernels, a tenth of a frame at N 500
(docs/performance.md, "Hostile match errors").

The loop's counts travel in an int64 array indexed by the ``S_*`` constants and the best score in
a float64 one, read and written by the caller between calls.
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels.base import jit
from stereovo.estimation.kernels.fitting import minimal_fits
from stereovo.estimation.kernels.mahalanobis import mahalanobis_sq
from stereovo.estimation.kernels.refinement import GATE_MAHALANOBIS, refine_rounds
from stereovo.estimation.kernels.sampling import distinct_triplets, rigid_triplets
from stereovo.estimation.kernels.scores import count_below

# int64 state: the loop's counts, its bound and batch schedule, the best model's support
S_DRAWN, S_SCORED, S_CHECKS, S_DEGENERATE, S_REJECTED = 0, 1, 2, 3, 4
S_REQUIRED, S_NEXT_SIZE, S_BEST_COUNT, S_ROW = 5, 6, 7, 8
S_RUNNER_UP_RUNS, S_REFIT_RUNS, S_REFIT_IMPROVED = 9, 10, 11  # counted here, added to the loop's by the caller
STATE_SIZE = 12

# why batch_search returned
DONE, EVENT, UNIFORMS_USED = 0, 1, 2


@jit
def batch_search(
    u, state, best_score, X, Y, mp, mc, cam, cov_prev, cov_curr, sigma_sq, threshold_sq, area_ratio,
    polish_iterations, rigidity_sq, runner_up_fraction, refit_rounds, refit_iterations, refit_huber, damping,
    tolerance, batch_size,
):
    """Run the loop's batches until the search is done or a batch needs Python.

    Args:
        u: ``(K, 3)`` uniforms the caller drew from the search's generator, read from row
            ``state[S_ROW]`` on: the rows the sampler's next draws would take.
        state: the loop's counts (``S_*``), read and written.
        best_score: the best model's score (-inf before the first).
        X, Y, mp, mc, cam, cov_prev, cov_curr: the problem's arrays; sigma_sq: its pixel variance.
        threshold_sq: the Mahalanobis gate (the residuals' cap and the count's line).
        area_ratio, polish_iterations: the minimal fit's.
        rigidity_sq: the rigidity check's gate, or <= 0 for no check.
        runner_up_fraction: the loop's runner-up refit fraction, or < 0 for none.
        refit_rounds, refit_iterations, refit_huber, damping, tolerance: the consensus refit's
            :func:`~stereovo.estimation.kernels.refinement.refine_rounds` settings (ConsensusRefit's
            refiner, gated by the Mahalanobis distance under ``threshold_sq``).
        batch_size: the largest batch.

    Returns:
        ``(why, R (H, 3, 3), t (H, 3), samples (H, 3), residual_sq (H, N), scores (H,))``: the batch
        of an ``EVENT`` (its residuals capped at the gate), empty arrays otherwise. ``why``:
        ``DONE`` (drawn >= required), ``EVENT`` (a batch drawn, checked, fitted and scored whose
        hypotheses hold a new best, or a runner-up whose refit beats the best: counted up to its
        scoring, the rest of its step is the caller's, which refits the runner-up again), or
        ``UNIFORMS_USED`` (the next batch needs more rows). A runner-up whose refit does not beat
        the best is refitted and counted here, as :meth:`RansacSearch._refit_runner_up` counts it.
    """
    n = X.shape[0]
    pool = np.full(batch_size, n, dtype=np.int64)
    none = (np.empty((0, 3, 3)), np.empty((0, 3)), np.empty((0, 3), dtype=np.int64), np.empty((0, n)), np.empty(0))
    row = state[S_ROW]
    while state[S_DRAWN] < state[S_REQUIRED]:
        batch = min(state[S_NEXT_SIZE], state[S_REQUIRED] - state[S_DRAWN])
        if row + batch > u.shape[0]:
            state[S_ROW] = row
            return UNIFORMS_USED, none[0], none[1], none[2], none[3], none[4]
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
        if n_valid == 0:
            continue  # nothing the bound reads has changed
        if n_valid < valid.shape[0]:
            R, t, samples = R[valid], t[valid], samples[valid]
        sq = mahalanobis_sq(R, t, X, Y, cam, sigma_sq, threshold_sq)
        scores = count_below(sq, threshold_sq)
        H = scores.shape[0]
        top = 0  # np.argmax: the first maximum
        for h in range(1, H):
            if scores[h] > scores[top]:
                top = h
        event = scores[top] > best_score
        if not event and runner_up_fraction >= 0.0:
            # the loop's runner-up without a new best: the batch's top, if its consensus (its score,
            # the count below the gate) is a minimal sample and near the best's, refitted on it
            count = int(scores[top])
            if count >= 3 and not count < runner_up_fraction * state[S_BEST_COUNT]:
                inliers = sq[top] < threshold_sq
                _, _, _, refit_sq, computed = refine_rounds(
                    R[top], t[top], X, Y, mp, mc, cam, cov_prev, cov_curr, sigma_sq, inliers, GATE_MAHALANOBIS,
                    threshold_sq, False, refit_rounds, refit_iterations, refit_huber, damping, tolerance, none[4],
                )
                if computed:
                    refit_score = 0.0
                    for i in range(n):
                        refit_score += refit_sq[i] < threshold_sq
                    spent = n * refit_rounds
                else:  # the motion given back, which the loop scores anew: its count, as the batch's
                    refit_score = scores[top]
                    spent = n * refit_rounds + n
                improved = refit_score > scores[top]
                if (refit_score if improved else scores[top]) > best_score:
                    event = True  # the refit wins: the caller's to make the best
                else:
                    state[S_REFIT_RUNS] += 1
                    state[S_REFIT_IMPROVED] += improved
                    state[S_RUNNER_UP_RUNS] += 1
                    state[S_CHECKS] += spent
        if event:
            state[S_ROW] = row
            return EVENT, R, t, samples, sq, scores
        state[S_SCORED] += H
        state[S_CHECKS] += H * n
    state[S_ROW] = row
    return DONE, none[0], none[1], none[2], none[3], none[4]
