"""The adaptive reordering sampler of ARS-MAGSAC (Wei, Matas & Barath, "Adaptive Reordering Sampler
with Neurally Guided MAGSAC", ICCV 2023), method ``ars``.

It always draws the sample most likely to be all-inlier, and after each unsuccessful hypothesis
updates the inlier probabilities of that sample's points by Bayes' rule (the BaySAC update,
Botterill, Mills & Green, BMVC 2009, on which ARS builds): with ``p_i = P(i is an inlier)`` and the
sample ``S``, the event "S is not all-inlier" has probability ``1 - prod_{j in S} p_j``, so

    p_i <- p_i (1 - prod_{j in S, j != i} p_j) / (1 - prod_{j in S} p_j)    for i in S,

and every other point keeps its probability (independent beliefs). "Unsuccessful" is a hypothesis
that does not raise the best support seen so far; a successful one keeps its sample's beliefs.

Choosing the sample: the product ``p_i p_j p_k`` is largest for the three most probable points; a
sample already tried is known not to be all-inlier (or already found), so the sampler takes the most
probable untried triple among the :data:`CANDIDATES` most probable points (ties between equal
beliefs broken by a random permutation drawn once per run). Within one batch, each drawn sample is
assumed to fail (its update applied at once) so that the next row is the next most probable; the
feedback hook undoes the update for the sample that raised the best support.

Initial probabilities: ``initial_probability`` without priors, else priors scaled so that the largest
is ``prior_ceiling`` (as :mod:`stereovo.estimation.methods.bansac`). Termination: the loop's adaptive bound.

**The direct search.** :func:`compiled_ars_search` (the components' ``search_runner``) takes the
loop's steps with each batch judged in one compiled pass (the capped score, the inliers and the
fed-back verdicts, :func:`stereovo.estimation.kernels.bansac_runner.judged_batch`) where the loop
runs the Mahalanobis kernel twice: the loop's results bit for bit
(``tests/stereovo/estimation/methods/test_bansac_runner.py``); :data:`COMPILED_SEARCH` False runs
the loop, the reference.

This module also registers ``ars`` (its belief options as :mod:`~stereovo.estimation.methods.bansac` declares them).
"""

from __future__ import annotations

import itertools

import numpy as np

from stereovo.estimation.kernels import bansac_runner as runner_kernels
from stereovo.estimation.kernels import beliefs as belief_kernels
from stereovo.estimation.loop import LoopState, RansacComponents, RansacSearch, local_refit_redundant
from stereovo.estimation.methods.bansac import (
    BELIEF_FLOOR,
    CEILING_RULE,
    PRIOR_CEILING,
    belief_options,
    initial_beliefs,
    judged_components,
)
from stereovo.estimation.registry import register_method
from stereovo.estimation.roles.local_optimization import ConsensusRefit
from stereovo.estimation.roles.sample_check import RigidityCheck
from stereovo.estimation.roles.scoring import InlierCount, MahalanobisResidual
from stereovo.estimation.roles.solvers import SAMPLE_SIZE, minimal_hypotheses
from stereovo.estimation.roles.verification import FullVerification

CANDIDATES = 8
CANDIDATE_TRIPLES = np.array(list(itertools.combinations(range(CANDIDATES), SAMPLE_SIZE)), dtype=np.int64)
TABLE_START = 1024  # slots of the tried-sample table at the start (doubled whenever it would pass half full)


def baysac_failure_update(p: np.ndarray, sample: np.ndarray) -> np.ndarray:
    """``p (N,)`` after learning that ``sample`` (three indices) is not all-inlier (module docstring)."""
    out = p.copy()
    ps = p[sample]
    everyone = float(np.prod(ps))
    others = everyone / ps
    out[sample] = np.clip(ps * (1 - others) / max(1 - everyone, 1e-300), BELIEF_FLOOR, 1 - BELIEF_FLOOR)
    return out


class ArsSampler:
    """Most probable untried sample, BaySAC update after every failure (module docstring).

    The draw, its update and the feedback run compiled (:mod:`stereovo.estimation.kernels.beliefs`),
    the tried samples in a hash table of int64 codes; the draws are bit for bit those of the numpy
    formulation (:func:`baysac_failure_update` on a set of tuples).

    Attributes:
        beliefs: ``(N,)`` current inlier probabilities.
    """

    def __init__(self, n: int, priors: np.ndarray | None = None, initial_probability: float = 0.5,
                 prior_ceiling: float = PRIOR_CEILING) -> None:
        if n < SAMPLE_SIZE:
            raise ValueError(f"need at least {SAMPLE_SIZE} correspondences to sample, got {n}")
        for name, value in (("initial_probability", initial_probability), ("prior_ceiling", prior_ceiling)):
            if not 0 < value < 1:
                raise ValueError(f"ArsSampler: {name} must be in (0, 1), got {value!r}")
        self.n = n
        self.beliefs = np.ascontiguousarray(initial_beliefs(n, priors, initial_probability, prior_ceiling))
        self._tie_break: np.ndarray | None = None
        self._table = np.full(TABLE_START, belief_kernels.EMPTY, dtype=np.int64)
        self._tried = 0
        # draws since the last feedback, in order: their codes and beliefs before their update
        self._pending_codes: list[np.ndarray] = []
        self._pending_before: list[np.ndarray] = []
        self._best_support = -1
        self.successes = 0

    def _room_for(self, batch: int) -> None:
        """Keep the tried-sample table at most half full after ``batch`` more codes."""
        size = self._table.shape[0]
        while 2 * (self._tried + batch) > size:
            size *= 2
        if size != self._table.shape[0]:
            self._table = belief_kernels.rehashed(self._table, size)

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        if self._tie_break is None:
            self._tie_break = np.ascontiguousarray(rng.permutation(self.n), dtype=np.int64)
        self._room_for(batch)
        samples, codes, before, added = belief_kernels.ars_draw(
            self.beliefs, self._tie_break, CANDIDATE_TRIPLES, self._table, min(CANDIDATES, self.n), int(batch), BELIEF_FLOOR
        )
        self._tried += int(added)
        self._pending_codes.append(codes)
        self._pending_before.append(before)
        return samples

    def on_hypotheses(self, R, t, inlier_masks: np.ndarray, residual_sq: np.ndarray, state: LoopState) -> None:
        support = np.count_nonzero(inlier_masks, axis=1).astype(np.int64)
        if self._pending_codes:
            codes, before = np.concatenate(self._pending_codes), np.concatenate(self._pending_before)
        else:
            codes, before = np.zeros(0, dtype=np.int64), np.zeros((0, SAMPLE_SIZE))
        self._best_support, successes = belief_kernels.ars_feedback(
            self.beliefs, np.ascontiguousarray(state.samples, dtype=np.int64), support, codes, before,
            self._best_support,
        )
        self._best_support = int(self._best_support)
        self.successes += int(successes)
        self._pending_codes, self._pending_before = [], []

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        """Whether the next (deterministic) draw lies in ``inliers (N,)`` bool: 1.0 or 0.0."""
        if self._tie_break is None:
            raise RuntimeError("ArsSampler: the next draw is defined only after the first draw (its tie-break)")
        sample = belief_kernels.ars_next(self.beliefs, self._tie_break, CANDIDATE_TRIPLES, self._table, min(CANDIDATES, self.n))
        return float(np.all(inliers[sample]))

    def counters(self) -> dict[str, int]:
        return {"ars_successes": self.successes, "ars_tried": self._tried}


# ----------------------------------------------------------------------------- the direct search


COMPILED_SEARCH = True  # False: ars steps the shared loop (the reference the direct search is held to)
# the class the direct search feeds back, bound here: another sampler put in ArsSampler's place is left to the loop
SEARCHED_SAMPLER = ArsSampler


def compiled_search_applies(c: RansacComponents) -> bool:
    """Whether :func:`compiled_ars_search` computes exactly what the loop's steps compute for ``c``:
    ARS's sampler, the ``probabilistic`` judge (Mahalanobis count, full verification), with or
    without the rigidity check, with the consensus refit (which draws nothing) or no local optimiser;
    any termination and listeners (they are called as the loop calls them)."""
    return (
        type(c.sampler) is SEARCHED_SAMPLER
        and type(c.verifier) is FullVerification
        and type(c.residual_model) is MahalanobisResidual and type(c.quality) is InlierCount and c.threshold_sq > 0
        and (c.sample_check is None or type(c.sample_check) is RigidityCheck)
        and (c.local_optimizer is None or type(c.local_optimizer) is ConsensusRefit)
    )


def compiled_ars_search(search: RansacSearch) -> None:
    """Run a fresh search of ``ars`` to its end: the loop's steps (its batch schedule, draws, checks,
    new bests, runner-up refits, listeners and bound, as :meth:`RansacSearch.step` takes them), with
    each batch judged in one compiled pass
    (:func:`stereovo.estimation.kernels.bansac_runner.judged_batch`): the loop scores on capped
    residuals and computes every residual again, uncapped, for the sampler's feedback, with the
    Mahalanobis kernel's per-batch loop; one vectorised pass gives the scores, the inliers and the
    verdicts, bit for bit. Components it does not cover (:func:`compiled_search_applies`) are left
    to the loop, untouched."""
    c = search.components
    if not compiled_search_applies(c):
        return
    problem, n, term = search.problem, search.n, c.termination
    constants = runner_kernels.search_constants(problem.points_prev, problem.points_curr)
    sigma_sq, threshold_sq = problem.noise_sigma**2, float(c.threshold_sq)
    listening = [*c.listeners, *([] if any(x is term for x in c.listeners) else [term])]
    best_listeners = [listener for listener in listening if hasattr(listener, "on_new_best")]
    batch_listeners = [listener for listener in listening if hasattr(listener, "on_batch")]
    size = min(c.first_batch_size, c.batch_size) if c.first_batch_size else c.batch_size
    while not search.done:
        batch = int(min(size, search.required - search.drawn))
        size = min(2 * size, c.batch_size)
        samples = c.sampler.draw(batch, search.rng)
        search.drawn += batch
        if c.sample_check is not None:
            keep = c.sample_check.accept(problem, samples)
            search.rejected += batch - int(np.count_nonzero(keep))
            samples = samples[keep]
        R, t, valid = minimal_hypotheses(problem, samples, c.polish_iterations)
        n_valid = int(np.count_nonzero(valid))
        search.degenerate += len(valid) - n_valid
        if n_valid:
            if n_valid < len(valid):
                R, t, samples = R[valid], t[valid], samples[valid]
            scores, inliers, verdicts = runner_kernels.judged_batch(
                R, t, problem.points_prev, problem.points_curr, problem.camera.parameters, sigma_sq, threshold_sq,
                constants,
            )
            search.scored += R.shape[0]
            search.checks += R.shape[0] * n
            i = int(np.argmax(scores))
            earlier_best = search.best_score > -np.inf
            new_best = bool(scores[i] > search.best_score)
            if new_best:
                _take_new_best(search, R, t, inliers, i, float(scores[i]), best_listeners)
            if c.runner_up_fraction is not None and c.local_optimizer is not None and earlier_best:
                _refit_runner_up(search, R, t, scores, inliers, i if new_best else -1, best_listeners)
            search.checks += R.shape[0] * n
            state = LoopState(search.drawn, search.best_score, samples=samples, best_inliers=search.best_inliers)
            c.sampler.on_hypotheses(R, t, verdicts, None, state)
        if batch_listeners:
            state = search.state
            for listener in batch_listeners:
                listener.on_batch(state)
        if search.best_score > -np.inf:
            bound = term.required(int(np.count_nonzero(search.best_inliers)), n)
            search.required = min(bound, term.max_iterations)


def _take_new_best(search: RansacSearch, R, t, inliers, i: int, score: float, listeners) -> None:
    """Hypothesis ``i`` of the batch as the new best, with the loop's local refit and listeners."""
    c, n = search.components, search.n
    search.best_R, search.best_t, search.best_score = R[i], t[i], score
    search.best_inliers = inliers[i].copy()  # from the scored residuals: no point checks
    search.found_at = search.drawn
    if c.local_optimizer is not None and not local_refit_redundant(c, search.drawn, search.best_inliers, n):
        search.best_R, search.best_t, search.best_inliers, search.best_score, spent = c.local_optimizer.improve(
            search.ctx, search.best_R, search.best_t, search.best_inliers, search.best_score, search.rng
        )
        search.local_runs += 1
        search.checks += spent
    state = search.state
    for listener in listeners:
        listener.on_new_best(search.best_inliers, state)


def _refit_runner_up(search: RansacSearch, R, t, scores, inliers, new_best: int, listeners) -> None:
    """The loop's runner-up refit: the batch's best hypothesis other than ``new_best`` (-1: none),
    refitted if its consensus is near the best's, made the best if it then scores higher."""
    c = search.components
    if new_best >= 0:
        if scores.shape[0] < 2:
            return
        scores = scores.copy()
        scores[new_best] = -np.inf
    j = int(np.argmax(scores))
    if scores[j] == -np.inf:
        return
    count = np.count_nonzero(inliers[j])
    if count < SAMPLE_SIZE or count < c.runner_up_fraction * np.count_nonzero(search.best_inliers):
        return
    R_j, t_j, inliers_j, score_j, spent = c.local_optimizer.improve(
        search.ctx, R[j], t[j], inliers[j].copy(), float(scores[j]), search.rng
    )
    search.runner_up_runs += 1
    search.checks += spent
    if score_j > search.best_score:
        search.runner_up_wins += 1
        search.best_R, search.best_t, search.best_inliers, search.best_score = R_j, t_j, inliers_j, score_j
        search.found_at = search.drawn
        state = search.state
        for listener in listeners:
            listener.on_new_best(search.best_inliers, state)


# ----------------------------------------------------------------------------- the method



@register_method(
    "ars",
    "always the most probable untried sample, inlier probabilities updated by Bayes' rule after each "
    "failure (adaptive reordering); adaptive stop; the probabilistic method's judge",
    "Wei, Matas & Barath, ICCV 2023",
    extra_options={"initial_probability": None, "prior_ceiling": CEILING_RULE},
)
def _build_ars(problem, options, priors, order, extra):
    components = judged_components(problem, options, priors, order, ArsSampler(problem.n, priors, **belief_options(extra)))
    if COMPILED_SEARCH:
        components.search_runner = compiled_ars_search
    return components
