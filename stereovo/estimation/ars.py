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
is ``prior_ceiling`` (as :mod:`stereovo.estimation.bansac`). Termination: the loop's adaptive bound.
"""

from __future__ import annotations

import itertools

import numpy as np

from stereovo.estimation.bansac import BELIEF_FLOOR, PRIOR_CEILING, initial_beliefs
from stereovo.estimation.loop import LoopState
from stereovo.estimation.samplers import SAMPLE_SIZE

CANDIDATES = 8
_TRIPLES = np.array(list(itertools.combinations(range(CANDIDATES), SAMPLE_SIZE)), dtype=np.int64)


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
        self.beliefs = initial_beliefs(n, priors, initial_probability, prior_ceiling)
        self._tie_break: np.ndarray | None = None
        self._tried: set[tuple[int, int, int]] = set()
        self._pending: dict[tuple[int, int, int], np.ndarray] = {}
        self._best_support = -1
        self.successes = 0

    def _most_probable_untried(self) -> np.ndarray:
        p = self.beliefs
        k = min(CANDIDATES, self.n)
        # the k most probable points, equal beliefs in the run's random order
        top = np.lexsort((self._tie_break, -p))[:k]
        triples = top[_TRIPLES[np.all(_TRIPLES < k, axis=1)]]
        value = np.prod(p[triples], axis=1)
        for j in np.argsort(-value, kind="stable"):
            key = tuple(sorted(int(i) for i in triples[j]))
            if key not in self._tried:
                return triples[j]
        # every candidate triple tried: the best one again (its beliefs keep falling, others rise past)
        return triples[int(np.argmax(value))]

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        if self._tie_break is None:
            self._tie_break = rng.permutation(self.n)
        out = np.empty((batch, SAMPLE_SIZE), dtype=np.int64)
        for row in range(batch):
            sample = self._most_probable_untried()
            key = tuple(sorted(int(i) for i in sample))
            self._tried.add(key)
            self._pending[key] = self.beliefs[sample].copy()
            self.beliefs = baysac_failure_update(self.beliefs, sample)
            out[row] = sample
        return out

    def on_hypotheses(self, R, t, inlier_masks: np.ndarray, residual_sq: np.ndarray, state: LoopState) -> None:
        support = np.count_nonzero(inlier_masks, axis=1)
        for sample, count in zip(state.samples, support):
            key = tuple(sorted(int(i) for i in sample))
            before = self._pending.pop(key, None)
            if count > self._best_support:
                self._best_support = int(count)
                if before is not None:  # a success: the failure update assumed at the draw is undone
                    self.beliefs[sample] = before
                    self.successes += 1
        self._pending.clear()

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        """Whether the next (deterministic) draw lies in ``inliers (N,)`` bool: 1.0 or 0.0."""
        return float(np.all(inliers[self._most_probable_untried()]))

    def counters(self) -> dict[str, int]:
        return {"ars_successes": self.successes, "ars_tried": len(self._tried)}


# ----------------------------------------------------------------------------- the method

from stereovo.estimation.bansac import BELIEF_OPTIONS, belief_options, judged_components  # noqa: E402
from stereovo.estimation.methods import register_method  # noqa: E402


@register_method(
    "ars",
    "always the most probable untried sample, inlier probabilities updated by Bayes' rule after each "
    "failure (adaptive reordering); adaptive stop; the probabilistic method's judge",
    "Wei, Matas & Barath, ICCV 2023",
    extra_options=BELIEF_OPTIONS,
)
def _build_ars(problem, options, priors, order, extra):
    return judged_components(problem, options, priors, order, ArsSampler(problem.n, priors, **belief_options(extra)))
