"""The loop's search in one compiled call for the ``probabilistic`` judge with uniform draws.

:func:`compiled_batch_search` is a :attr:`~stereovo.estimation.loop.RansacComponents.search_runner`:
it runs a search's batches in :func:`stereovo.estimation.kernels.batch_search.batch_search` (draws,
checks, fits, scores, new bests with their consensus refit, runner-up refits, the bound), bit for bit
the loop's steps, and hands back to Python only for the next block of uniforms. Components it does not cover
(:func:`batch_search_applies`) are left to the loop, untouched; ``COMPILED_BATCHES = False`` leaves
every search to it, the reference the kernel is held to.
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


def batch_search_applies(c: RansacComponents) -> bool:
    """Whether :func:`~stereovo.estimation.kernels.batch_search.batch_search` computes exactly what
    the loop's steps compute for ``c``: uniform draws, with or without the rigidity check, full
    verification by the Mahalanobis inlier count, the consensus refit on the judge's own gate (which
    draws nothing) or no local optimiser, the uniform adaptive bound or a fixed budget (whose
    listeners do nothing), no other listeners and no feedback."""
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
    """One run of :func:`compiled_batch_search`: the kernel's state and best model beside the search's."""

    def __init__(self, search: RansacSearch) -> None:
        c = self.c = search.components
        self.search, problem = search, search.problem
        self.state = np.zeros(kernel.STATE_SIZE, dtype=np.int64)
        self.fstate = np.zeros(kernel.FLOAT_STATE_SIZE)
        self.best_R, self.best_t = np.empty((3, 3)), np.empty(3)
        self.best_inliers = np.empty(search.n, dtype=bool)
        term, refit = c.termination, c.local_optimizer
        refiner = None if refit is None else refit.refiner
        budget = int(term.budget) if type(term) is FixedBudget else 0
        self.args = (
            problem.points_prev, problem.points_curr, problem.prev, problem.curr, problem.camera.parameters,
            problem.cov_prev, problem.cov_curr, problem.noise_sigma**2, float(c.threshold_sq),
            DEGENERATE_AREA_RATIO, int(c.polish_iterations),
            0.0 if c.sample_check is None else float(c.sample_check.threshold_sq),
            refit is not None,
            # the loop's local_refit_redundant: a consensus refit repeats the final refinement's work
            refit is not None and c.refiner is not None and bool(refit.subsumed_by_refinement),
            -1.0 if refit is None or c.runner_up_fraction is None else float(c.runner_up_fraction),
            0 if refiner is None else int(refiner.rounds), 0 if refiner is None else int(refiner.iterations),
            0.0 if refiner is None or refiner.huber_px is None else float(refiner.huber_px), LM_DAMPING, LM_TOLERANCE,
            0.5 if budget else float(term.confidence), int(term.max_iterations),
            1 if budget else int(term.min_iterations), budget, int(c.batch_size),
        )

    def push(self) -> None:
        """The search's counts and best model into the kernel's."""
        s, search = self.state, self.search
        s[kernel.S_DRAWN], s[kernel.S_SCORED], s[kernel.S_CHECKS] = search.drawn, search.scored, search.checks
        s[kernel.S_DEGENERATE], s[kernel.S_REJECTED] = search.degenerate, search.rejected
        s[kernel.S_REQUIRED], s[kernel.S_NEXT_SIZE] = search.required, search.next_size
        s[kernel.S_FOUND_AT], s[kernel.S_LOCAL_RUNS] = search.found_at, search.local_runs
        s[kernel.S_RUNNER_UP_RUNS], s[kernel.S_RUNNER_UP_WINS] = search.runner_up_runs, search.runner_up_wins
        s[kernel.S_REFIT_RUNS] = s[kernel.S_REFIT_IMPROVED] = 0
        self.best_R[:], self.best_t[:], self.best_inliers[:] = search.best_R, search.best_t, search.best_inliers
        s[kernel.S_BEST_COUNT] = np.count_nonzero(self.best_inliers)
        self.fstate[kernel.F_BEST_SCORE] = search.best_score

    def pull(self) -> None:
        """The kernel's counts and best model back into the search (and the refit's counts into it)."""
        s, search = self.state, self.search
        search.drawn, search.scored, search.checks = int(s[kernel.S_DRAWN]), int(s[kernel.S_SCORED]), int(s[kernel.S_CHECKS])
        search.degenerate, search.rejected = int(s[kernel.S_DEGENERATE]), int(s[kernel.S_REJECTED])
        search.required, search.next_size = int(s[kernel.S_REQUIRED]), int(s[kernel.S_NEXT_SIZE])
        search.found_at, search.local_runs = int(s[kernel.S_FOUND_AT]), int(s[kernel.S_LOCAL_RUNS])
        search.runner_up_runs, search.runner_up_wins = int(s[kernel.S_RUNNER_UP_RUNS]), int(s[kernel.S_RUNNER_UP_WINS])
        if s[kernel.S_REFIT_RUNS]:
            counts = self.c.local_optimizer.counts
            counts["refit_runs"] += int(s[kernel.S_REFIT_RUNS])
            counts["refit_improved"] += int(s[kernel.S_REFIT_IMPROVED])
        search.best_R, search.best_t = self.best_R.copy(), self.best_t.copy()
        search.best_inliers, search.best_score = self.best_inliers.copy(), float(self.fstate[kernel.F_BEST_SCORE])

    def run(self) -> None:
        search, rng = self.search, self.search.rng
        saved = rng.bit_generator.state
        u = rng.random((FIRST_UNIFORM_ROWS, SAMPLE_SIZE))
        rows = 2 * FIRST_UNIFORM_ROWS
        self.push()
        while kernel.batch_search(u, self.state, self.fstate, self.best_R, self.best_t, self.best_inliers,
                                  *self.args) == kernel.UNIFORMS_USED:
            # Uniforms for the next batches, as the sampler's draws would take them (Generator.random
            # fills its output in order): the generator goes back to where the rows used so far end,
            # and the rows left unused at the end are given back likewise.
            rng.bit_generator.state = saved
            rng.random((int(self.state[kernel.S_ROW]), SAMPLE_SIZE))
            need = int(min(self.state[kernel.S_NEXT_SIZE], self.state[kernel.S_REQUIRED] - self.state[kernel.S_DRAWN]))
            saved = rng.bit_generator.state
            u = rng.random((max(rows, need), SAMPLE_SIZE))
            rows = min(2 * rows, MAX_UNIFORM_ROWS)
            self.state[kernel.S_ROW] = 0
        self.pull()
        used = int(self.state[kernel.S_ROW])
        if used < u.shape[0]:
            rng.bit_generator.state = saved
            rng.random((used, SAMPLE_SIZE))


def compiled_batch_search(search: RansacSearch) -> None:
    """Run a search to its end in :func:`~stereovo.estimation.kernels.batch_search.batch_search`, bit
    for bit the loop's steps (at eps 0.2 too, where a frame takes one or two batches, the call costs
    less than a step's Python). Components it does not cover (:func:`batch_search_applies`) are left
    to the loop."""
    if COMPILED_BATCHES and batch_search_applies(search.components) and not search.done:
        _BatchSearch(search).run()
