"""The loop's batches in one compiled call while they change nothing but the counts.

:func:`compiled_batch_search` is a :attr:`~stereovo.estimation.loop.RansacComponents.search_runner`:
for the ``probabilistic`` judge with uniform draws it runs the search's batches in
:func:`stereovo.estimation.kernels.batch_search.batch_search`, and hands each batch that finds a
new best, or a runner-up whose refit beats the best, to :meth:`RansacSearch.take_scores` and
:meth:`RansacSearch.end_batch`, the loop's own code for the rest of a step. Components it does not
cover (:func:`batch_search_applies`) are left to the loop, untouched; ``COMPILED_BATCHES = False``
leaves every search to it, the reference the kernel is held to.
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels import batch_search as kernel
from stereovo.estimation.loop import RansacComponents, RansacSearch
from stereovo.estimation.roles.local_optimization import ConsensusRefit
from stereovo.estimation.roles.refinement import LM_DAMPING, LM_TOLERANCE
from stereovo.estimation.roles.sample_check import RigidityCheck
from stereovo.estimation.roles.samplers import UniformSampler
from stereovo.estimation.roles.scoring import InlierCount, MahalanobisResidual
from stereovo.estimation.roles.solvers import DEGENERATE_AREA_RATIO, SAMPLE_SIZE
from stereovo.estimation.roles.termination import AdaptiveTermination, FixedBudget
from stereovo.estimation.roles.verification import FullVerification

COMPILED_BATCHES = True  # False: every search steps the loop (the reference the kernel is held to)
FIRST_UNIFORM_ROWS = 256  # hypotheses' uniforms drawn per block, doubling up to MAX_UNIFORM_ROWS
MAX_UNIFORM_ROWS = 8192
COMPILED_FROM = 256  # draws left to the bound from which the kernel takes over the batches


def batch_search_applies(c: RansacComponents) -> bool:
    """Whether :func:`~stereovo.estimation.kernels.batch_search.batch_search` computes exactly what
    the loop's steps compute for ``c``: uniform draws, with or without the rigidity check, full
    verification by the Mahalanobis inlier count, the consensus refit on the judge's own gate (which
    draws nothing) or no local optimiser, a bound that only a new best moves (the uniform adaptive bound or a fixed
    budget), no listeners and no feedback."""
    term = c.termination
    return (
        type(c.sampler) is UniformSampler
        and (type(c.sample_check) is RigidityCheck or c.sample_check is None)
        and type(c.verifier) is FullVerification
        and type(c.residual_model) is MahalanobisResidual and type(c.quality) is InlierCount and c.threshold_sq > 0
        and (c.local_optimizer is None
             or (type(c.local_optimizer) is ConsensusRefit and c.local_optimizer.refiner.gate is None))
        and ((type(term) is AdaptiveTermination and not term.probability.guided) or type(term) is FixedBudget)
        and not c.listeners
    )


class _BatchSearch:
    """One run of :func:`compiled_batch_search`: the kernel's state and buffers beside the search's."""

    def __init__(self, search: RansacSearch) -> None:
        c = self.c = search.components
        self.search, problem, n = search, search.problem, search.n
        self.state = np.zeros(kernel.STATE_SIZE, dtype=np.int64)
        runner_up = c.runner_up_fraction if c.local_optimizer is not None and c.runner_up_fraction is not None else None
        rigidity = 0.0 if c.sample_check is None else float(c.sample_check.threshold_sq)
        refiner = None if c.local_optimizer is None else c.local_optimizer.refiner
        self.args = (
            problem.points_prev, problem.points_curr, problem.prev, problem.curr, problem.camera.parameters,
            problem.cov_prev, problem.cov_curr, problem.noise_sigma**2, float(c.threshold_sq),
            DEGENERATE_AREA_RATIO, int(c.polish_iterations), rigidity, -1.0 if runner_up is None else float(runner_up),
            0 if refiner is None else int(refiner.rounds), 0 if refiner is None else int(refiner.iterations),
            0.0 if refiner is None or refiner.huber_px is None else float(refiner.huber_px), LM_DAMPING, LM_TOLERANCE,
            int(c.batch_size),
        )

    def push(self) -> None:
        """The search's counts into the kernel's state."""
        s, search = self.state, self.search
        s[kernel.S_DRAWN], s[kernel.S_SCORED], s[kernel.S_CHECKS] = search.drawn, search.scored, search.checks
        s[kernel.S_DEGENERATE], s[kernel.S_REJECTED] = search.degenerate, search.rejected
        s[kernel.S_REQUIRED], s[kernel.S_NEXT_SIZE] = search.required, search.next_size
        s[kernel.S_BEST_COUNT] = np.count_nonzero(search.best_inliers)
        s[kernel.S_RUNNER_UP_RUNS] = s[kernel.S_REFIT_RUNS] = s[kernel.S_REFIT_IMPROVED] = 0

    def pull(self) -> None:
        """The kernel's counts back into the search."""
        s, search = self.state, self.search
        search.drawn, search.scored, search.checks = int(s[kernel.S_DRAWN]), int(s[kernel.S_SCORED]), int(s[kernel.S_CHECKS])
        search.degenerate, search.rejected = int(s[kernel.S_DEGENERATE]), int(s[kernel.S_REJECTED])
        search.next_size = int(s[kernel.S_NEXT_SIZE])
        if s[kernel.S_RUNNER_UP_RUNS]:  # the runner-up refits the kernel ran, none of which beat the best
            search.runner_up_runs += int(s[kernel.S_RUNNER_UP_RUNS])
            counts = self.c.local_optimizer.counts
            counts["refit_runs"] += int(s[kernel.S_REFIT_RUNS])
            counts["refit_improved"] += int(s[kernel.S_REFIT_IMPROVED])

    def run(self) -> None:
        search, rng, n = self.search, self.search.rng, self.search.n
        saved = rng.bit_generator.state
        u = rng.random((FIRST_UNIFORM_ROWS, SAMPLE_SIZE))
        rows = 2 * FIRST_UNIFORM_ROWS
        while not search.done:
            self.push()
            why, R, t, samples, residual_sq, scores = kernel.batch_search(
                u, self.state, float(search.best_score), *self.args)
            self.pull()
            if why == kernel.UNIFORMS_USED:
                # Uniforms for the next batches, as the sampler's draws would take them (Generator.random
                # fills its output in order): the generator goes back to where the rows used so far end,
                # and the rows left unused at the end are given back likewise.
                used = int(self.state[kernel.S_ROW])
                rng.bit_generator.state = saved
                rng.random((used, SAMPLE_SIZE))
                need = int(min(search.next_size, search.required - search.drawn))
                saved = rng.bit_generator.state
                u = rng.random((max(rows, need), SAMPLE_SIZE))
                rows = min(2 * rows, MAX_UNIFORM_ROWS)
                self.state[kernel.S_ROW] = 0
            elif why == kernel.EVENT:
                search.ctx.remember(R, residual_sq, np.arange(R.shape[0]))
                search.take_scores(R, t, samples, scores, R.shape[0] * n)
                search.end_batch()
        used = int(self.state[kernel.S_ROW])
        if used < u.shape[0]:
            rng.bit_generator.state = saved
            rng.random((used, SAMPLE_SIZE))


def compiled_batch_search(search: RansacSearch) -> None:
    """Run a fresh search to its end in :func:`~stereovo.estimation.kernels.batch_search.batch_search`,
    returning to Python only for a batch with a new best or a runner-up whose refit beats the best,
    and for the next block of uniforms: the loop's steps, bit for bit. Components it does not cover
    (:func:`batch_search_applies`) are left to the loop."""
    if not (COMPILED_BATCHES and batch_search_applies(search.components)):
        return
    # The first batch holds the first best, and often ends the search (low contamination): while
    # few draws are left, the loop's own steps cost less than setting the kernel up.
    search.step()
    while not search.done and search.required - search.drawn < COMPILED_FROM:
        search.step()
    if not search.done:
        _BatchSearch(search).run()
