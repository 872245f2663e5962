"""Preemptive RANSAC (Nister 2003, 2005): breadth-first scoring of a fixed hypothesis set.

Nister, ICCV 2003; docs/algorithms.md, `preemptive`. All M hypotheses are generated up front (the loop
hands them over in one batch: ``batch_size = M`` and a ``FixedBudget(M)``);
observations are taken in one random order and after observation i only the
best ``f(i) = floor(M 2^(-floor(i / B)))`` hypotheses are kept. The run ends
when ``f(i) = 1`` or the observations are exhausted; the best survivor wins.

Per-observation score: ``rho = -min(e^2, T^2) / T^2``, the robust truncated
quadratic normalised like the MSAC quality, so the winner's accumulated score
over all N observations *is* its MSAC score. Vectorised over blocks of B
observations, inside which the survivor set is constant: one residual call
per block (at most ``log2 M`` blocks).

This module also declares the ``preemptive_*`` options and registers ``preemptive``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stereovo.estimation.estimator_options import MAX_COUNT, OptionReads
from stereovo.estimation.recipes import base_components, reprojection_judge
from stereovo.estimation.registry import register_method
from stereovo.estimation.roles.partial import residuals_on
from stereovo.estimation.roles.scoring import TruncatedQuadratic
from stereovo.estimation.roles.termination import AdaptiveTermination, FixedBudget
from stereovo.estimation.roles.verification import ScoringContext
from stereovo.options import Integer


def preemption_function(i: np.ndarray, M: int, B: int) -> np.ndarray:
    """``f(i) = floor(M 2^(-floor(i / B)))``: hypotheses scored on observation i (1-based)."""
    return np.floor(M * 2.0 ** (-np.floor(np.asarray(i) / B))).astype(np.int64)


def preemptive_evaluations(n: int, M: int, B: int, hypotheses: int | None = None) -> int:
    """Residual evaluations of one preemptive run on n observations: ``sum_i min(f(i), H)``.

    The run scores observations ``i = 1, 2, ...`` while ``i <= n`` and ``f(i) > 1``.
    """
    H = M if hypotheses is None else hypotheses
    i = np.arange(1, n + 1)
    f = np.minimum(preemption_function(i, M, B), H)
    alive = np.cumprod(f > 1).astype(bool)  # stop at the first f(i) = 1
    return int(np.sum(f[alive]))


@dataclass
class PreemptiveVerification:
    """Score a fixed hypothesis set breadth-first and keep only the winner.

    Args:
        hypotheses: M, the size of the hypothesis set.
        block: B, observations between halvings of the survivors (100).

    ``verify`` returns ``-inf`` for every hypothesis but the winner, whose score is its
    ``ctx.quality`` on all N correspondences (observations it never reached are
    evaluated for it alone and counted). ``last_preemption_evaluations`` is the
    breadth-first part, ``sum_i f(i)`` exactly.
    """

    hypotheses: int = 500
    block: int = 100

    def __post_init__(self) -> None:
        for name, value in (("preemptive_hypotheses", self.hypotheses), ("preemptive_block", self.block)):
            if int(value) != value or value < 1:
                raise ValueError(f"option {name} must be an integer >= 1, got {value!r}")
        self.hypotheses, self.block = int(self.hypotheses), int(self.block)
        self.last_preemption_evaluations = 0
        self.last_observations = 0  # observations the breadth-first phase reached
        self.n_evaluations = 0  # over the run (the loop hands the whole set over once)
        self.n_hypotheses = 0

    def verify(
        self, ctx: ScoringContext, R: np.ndarray, t: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, int]:
        H, n = R.shape[0], ctx.problem.n
        M, B = self.hypotheses, self.block
        T2 = ctx.threshold_sq
        order = rng.permutation(n)
        sq_store = np.full((H, n), np.nan)
        total = np.zeros(H)
        alive = np.arange(H)
        evaluations = 0
        seen = 0  # observations scored so far (i - 1 in the paper's 1-based notation)
        j = 0
        while seen < n:
            f = int(min(M * 2.0**-j, H)) if j < 63 else 0
            if f <= 1:
                break
            if alive.size > f:
                # Keep the f best by the accumulated score (argpartition: order within is irrelevant).
                alive = alive[np.argpartition(-total[alive], f - 1)[:f]]
            last = min((j + 1) * B - 1, n)  # block j covers observations max(1, jB) .. (j+1)B - 1
            cols = order[seen:last]
            sq = residuals_on(ctx, R[alive], t[alive], cols)
            sq_store[alive[:, None], cols[None, :]] = sq
            total[alive] -= np.sum(np.minimum(sq, T2), axis=1) / T2
            evaluations += alive.size * cols.size
            seen = last
            j += 1
        winner = int(alive[np.argmax(total[alive])])
        self.last_preemption_evaluations = evaluations
        self.last_observations = seen
        self.n_evaluations += evaluations
        self.n_hypotheses += H
        extra = 0
        if seen < n:  # the breadth-first phase stopped early: finish the winner's residuals only
            rest = order[seen:]
            sq_store[winner, rest] = residuals_on(ctx, R[winner : winner + 1], t[winner : winner + 1], rest)[0]
            extra = rest.size
        scores = np.full(H, -np.inf)
        scores[winner] = float(ctx.quality.score(sq_store[winner : winner + 1], T2)[0])
        return scores, evaluations + extra

    def counters(self) -> dict[str, int | float]:
        """``preemptive_hypotheses`` verified, ``preemptive_evaluations`` (breadth-first residuals,
        ``sum_i f(i)``), ``preemptive_observations`` (observations the breadth-first phase reached)."""
        return {
            "preemptive_hypotheses": self.n_hypotheses,
            "preemptive_evaluations": self.n_evaluations,
            "preemptive_observations": self.last_observations,
        }


DEFAULT_HYPOTHESES = PreemptiveVerification.hypotheses  # Nister's M without a budget


@register_method(
    "preemptive",
    "fixed set of M hypotheses scored breadth-first, halving the survivors every B observations",
    "Nister 2003",
    extra_options={
        # None: DEFAULT_HYPOTHESES, or the shared budget when one is given
        "preemptive_hypotheses": Integer(low=1, high=MAX_COUNT, allow_none=True, default=None),
        "preemptive_block": Integer(low=1, high=MAX_COUNT, default=PreemptiveVerification.block),
    },
    # M hypotheses in one batch: M is the cap (the budget, else its own count), and a batch size, a first
    # batch and a runner-up have no role; the refinement refits the one batch's best in the local refit's place
    reads=OptionReads(judge="reprojection", refinement="plain", stop="preemptive", batches="one-set"),
)
def _build_preemptive(problem, options, priors, order, extra):
    m = extra["preemptive_hypotheses"]
    if m is None:
        m = DEFAULT_HYPOTHESES if options.budget is None else int(options.budget)
    elif options.budget is not None and m != options.budget:
        raise ValueError(f"preemptive: budget={options.budget} and preemptive_hypotheses={m} disagree; give one")
    components = base_components(problem, options, priors, order, *reprojection_judge(options, TruncatedQuadratic()))
    components.verifier = PreemptiveVerification(m, extra["preemptive_block"])
    # Nister's M is a fixed hypothesis count. Given as a budget it is the stop itself; as the
    # method's own M it is the search's cap: the adaptive bound, clipped to M, never ends the one
    # batch of M early, and lets the loop fail a returned model whose inliers would need more than
    # M draws for the confidence (fail_at_cap, docs/algorithms.md "What "ok" means").
    if options.budget is not None:
        components.termination = FixedBudget(m)
    else:
        components.termination = AdaptiveTermination(options.confidence, m, sampler=components.sampler)
    components.batch_size = m  # the whole hypothesis set reaches the verifier at once
    components.first_batch_size = None
    return components
