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

This module also registers ``ars`` (its belief options as :mod:`~stereovo.estimation.methods.bansac` declares them).
"""

from __future__ import annotations

import itertools

import numpy as np

from stereovo.estimation.kernels import beliefs as belief_kernels
from stereovo.estimation.loop import LoopState
from stereovo.estimation.methods.bansac import (
    BELIEF_FLOOR,
    BELIEF_SAMPLER_READS,
    CEILING_RULE,
    PRIOR_CEILING,
    belief_options,
    initial_beliefs,
    judged_components,
)
from stereovo.estimation.registry import register_method
from stereovo.estimation.roles.solvers import SAMPLE_SIZE

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


# ----------------------------------------------------------------------------- the method



@register_method(
    "ars",
    "always the most probable untried sample, inlier probabilities updated by Bayes' rule after each "
    "failure (adaptive reordering); adaptive stop; the probabilistic method's judge",
    "Wei, Matas & Barath, ICCV 2023",
    extra_options={"initial_probability": None, "prior_ceiling": CEILING_RULE},
    inputs="priors-optional",
    reads=BELIEF_SAMPLER_READS,
)
def _build_ars(problem, options, priors, order, extra):
    return judged_components(problem, options, priors, order, ArsSampler(problem.n, priors, **belief_options(extra)))
