"""BANSAC (Piedade & Miraldo, "BANSAC: A dynamic BAyesian Network for adaptive SAmple Consensus",
ICCV 2023): per-correspondence inlier beliefs updated after every hypothesis, sampled from, and a
stopping rule built from them. A sampler and a termination of the shared loop, method ``bansac``.

The update, per hypothesis t with minimal sample ``S_t``, inlier verdicts ``c_i^t`` (residual under
the gate) and support fraction ``r_t`` (inliers / N), on the beliefs ``p_i = P(i is an inlier)``:

- the hypothesis is correct (its sample all-inlier) with the belief ``delta_t = prod_{j in S_t} p_j``;
- if correct, it calls an outlier an outlier and finds an inlier with chance ``rho`` (``recall``: a
  hypothesis from a minimal sample of noisy stereo points misses many inliers); if not, it calls any
  point an inlier with chance ``r_t``, whatever the point is. So the verdict's likelihoods are
  ``P(c = in | inlier) = delta rho + (1 - delta) r``, ``P(c = in | outlier) = (1 - delta) r``, and
  the complements for ``c = out``;
- the first-order dynamic Bayesian network's step is Bayes' rule with these:
  ``p_i <- p_i L_in / (p_i L_in + (1 - p_i) L_out)`` for the verdict observed;
- the sample's own three points are left out (a hypothesis always fits its own sample: its verdict
  on them carries no information), and beliefs are clipped to ``[1e-4, 1 - 1e-4]``.

Hypotheses of one batch are applied one after another, in the order drawn. Sampling: three distinct
points, P(i) proportional to ``p_i`` (guided sampling on the current beliefs).

Stopping rule: under the current beliefs, the chance that at least one sample drawn so far was
all-inlier, ``1 - prod_t (1 - prod_{j in S_t} p_j)``; stop once it reaches ``confidence``. Beliefs
move after each batch, so this is recomputed over every sample drawn (O(hypotheses) per batch).

Initial beliefs: ``initial_probability`` for every point (no priors), or priors scaled so that the
largest is ``prior_ceiling`` (priors are sampling weights, whose scale is arbitrary).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from stereovo.estimation.local_optimization import ConsensusRefit
from stereovo.estimation.loop import LoopState
from stereovo.estimation.samplers import SAMPLE_SIZE, WeightedSampler

BELIEF_FLOOR = 1e-4
DEFAULT_RECALL = 0.5
PRIOR_CEILING = 0.6  # the largest prior's belief: at 0.95 the beliefs lock onto the first consensus (eps 0.5, 20 frames: 85 % success; 0.6: 95 %)
FEEDBACK_BATCH = 4  # hypotheses per batch of the ``bansac`` method: the beliefs move between batches


def initial_beliefs(n: int, priors: np.ndarray | None, initial_probability: float, prior_ceiling: float) -> np.ndarray:
    """``(n,)`` inlier beliefs: the constant without priors, else priors scaled to a maximum of
    ``prior_ceiling`` (floored at :data:`BELIEF_FLOOR`)."""
    if priors is None:
        return np.full(n, float(initial_probability))
    w = np.asarray(priors, dtype=float)
    return np.clip(prior_ceiling * w / w.max(), BELIEF_FLOOR, 1 - BELIEF_FLOOR)


def bansac_update(p: np.ndarray, sample: np.ndarray, verdicts: np.ndarray, recall: float = DEFAULT_RECALL) -> np.ndarray:
    """One hypothesis' update of the beliefs ``p (N,)`` (module docstring), returned as a new array.

    Args:
        p: current beliefs in (0, 1).
        sample: the hypothesis' minimal sample, three indices.
        verdicts: ``(N,)`` bool, the hypothesis' inlier mask.
        recall: ``rho``, the share of inliers a correct hypothesis finds.
    """
    delta = float(np.prod(p[sample]))
    r = float(np.count_nonzero(verdicts)) / verdicts.shape[0]
    in_if_inlier, in_if_outlier = delta * recall + (1 - delta) * r, (1 - delta) * r
    l_in = np.where(verdicts, in_if_inlier, 1 - in_if_inlier)
    l_out = np.where(verdicts, in_if_outlier, 1 - in_if_outlier)
    posterior = p * l_in / np.maximum(p * l_in + (1 - p) * l_out, 1e-300)
    posterior[sample] = p[sample]
    return np.clip(posterior, BELIEF_FLOOR, 1 - BELIEF_FLOOR)


class BansacSampler:
    """Guided sampling on beliefs that every verified hypothesis updates (module docstring).

    Attributes:
        beliefs: ``(N,)`` current inlier beliefs.
        history: ``(T, 3)`` every minimal sample fitted so far (the stopping rule reads them).
    """

    def __init__(self, n: int, priors: np.ndarray | None = None, initial_probability: float = 0.5,
                 prior_ceiling: float = PRIOR_CEILING, recall: float = DEFAULT_RECALL) -> None:
        if n < SAMPLE_SIZE:
            raise ValueError(f"need at least {SAMPLE_SIZE} correspondences to sample, got {n}")
        for name, value in (("initial_probability", initial_probability), ("prior_ceiling", prior_ceiling),
                            ("recall", recall)):
            if not 0 < value <= 1:
                raise ValueError(f"BansacSampler: {name} must be in (0, 1), got {value!r}")
        self.n, self.recall = n, float(recall)
        self.beliefs = initial_beliefs(n, priors, initial_probability, prior_ceiling)
        self._history: list[np.ndarray] = []
        self.updates = 0

    @property
    def history(self) -> np.ndarray:
        return np.concatenate(self._history) if self._history else np.zeros((0, SAMPLE_SIZE), dtype=np.int64)

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        return WeightedSampler(self.beliefs).draw(batch, rng)

    def on_hypotheses(self, R, t, inlier_masks: np.ndarray, residual_sq: np.ndarray, state: LoopState) -> None:
        p = self.beliefs
        for sample, verdicts in zip(state.samples, inlier_masks):
            p = bansac_update(p, sample, verdicts, self.recall)
        self.beliefs = p
        self.updates += len(inlier_masks)
        self._history.append(np.asarray(state.samples, dtype=np.int64))

    def stop_confidence(self) -> float:
        """``1 - prod_t (1 - prod_{j in S_t} p_j)`` over the samples fitted so far."""
        history = self.history
        if history.shape[0] == 0:
            return 0.0
        all_inlier = np.prod(self.beliefs[history], axis=1)
        return float(-np.expm1(np.sum(np.log1p(-np.minimum(all_inlier, 1 - 1e-12)))))

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        """Chance that one draw from the current beliefs is three points of ``inliers (N,)`` bool
        (sequential draws without replacement, with the inliers' mean weight removed per draw)."""
        w = self.beliefs
        total, inside = float(w.sum()), float(w[inliers].sum())
        k = int(np.count_nonzero(inliers))
        if k < SAMPLE_SIZE:
            return 0.0
        mean = inside / k
        q = 1.0
        for j in range(SAMPLE_SIZE):
            q *= (inside - j * mean) / (total - j * mean)
        return q

    def counters(self) -> dict[str, float]:
        return {"bansac_updates": self.updates, "bansac_stop_confidence": self.stop_confidence()}


@dataclass
class BansacTermination:
    """BANSAC's stop: once the beliefs say an all-inlier sample was drawn with ``confidence``.

    ``required`` answers the hypotheses drawn so far when the rule is met (the loop then stops),
    else one more batch's worth; ``max_iterations`` caps the search, ``min_iterations`` floors it.
    """

    sampler: BansacSampler
    confidence: float = 0.99
    max_iterations: int = 10_000
    min_iterations: int = 1
    stopped_by_rule: bool = field(default=False, init=False)

    def __post_init__(self) -> None:
        if not 0 < self.confidence < 1:
            raise ValueError(f"BansacTermination: confidence must be in (0, 1), got {self.confidence!r}")
        if not 1 <= self.min_iterations <= self.max_iterations:
            raise ValueError(
                f"BansacTermination: need 1 <= min_iterations <= max_iterations, got "
                f"{self.min_iterations} and {self.max_iterations}"
            )

    def required(self, n_inliers: int, n: int) -> int:
        drawn = self.sampler.history.shape[0]
        self.stopped_by_rule = drawn >= self.min_iterations and self.sampler.stop_confidence() >= self.confidence
        return 0 if self.stopped_by_rule else self.max_iterations

    def counters(self) -> dict[str, int]:
        return {"bansac_stopped_by_rule": int(self.stopped_by_rule)}


# ----------------------------------------------------------------------------- the method

from stereovo.estimation.methods import (  # noqa: E402  (the method needs the sampler above)
    EstimatorOptions,
    declare_options,
    declared_option,
    method_spec,
    register_method,
)
from stereovo.options import Number  # noqa: E402

BELIEF_OPTIONS = ("initial_probability", "prior_ceiling")
declare_options({
    "initial_probability": Number(low=0.0, high=1.0, low_open=True, high_open=True),
    "prior_ceiling": Number(low=0.0, high=1.0, low_open=True, high_open=True),
    "bansac_recall": Number(low=0.0, high=1.0, low_open=True),
})


def belief_options(extra: dict) -> dict[str, float]:
    """The belief options of ``bansac`` / ``ars`` from a method's ``extra`` options, checked."""
    defaults = {"initial_probability": 0.5, "prior_ceiling": PRIOR_CEILING}
    return {name: float(declared_option(name).check(name, extra.get(name, defaults[name]))) for name in BELIEF_OPTIONS}


def judged_components(problem, options: EstimatorOptions, priors, order, sampler):
    """The ``probabilistic`` method's recipe (Mahalanobis gate, rigidity check, pixel-gated
    refinement) with ``sampler`` in place of its own."""
    if order is not None:
        raise ValueError("this method samples by inlier beliefs: give priors (or nothing), not an order")
    components = method_spec("probabilistic").build(problem, options, priors, None, {})
    components.sampler = sampler
    # Belief-driven samplers draw from the first consensus found, and a minimal stereo fit finds
    # only part of its inliers: refitting each new best on its consensus gives it its full support
    # (eps 0.7, informative priors, 20 frames: bansac 45 -> 80 % success, ars 90 -> 100 %).
    components.local_optimizer = components.local_optimizer or ConsensusRefit()
    return components


@register_method(
    "bansac",
    "guided sampling on per-point inlier beliefs updated after every hypothesis by a dynamic Bayesian "
    "network, stopped when the beliefs say an all-inlier sample was drawn; the probabilistic method's judge",
    "Piedade & Miraldo, ICCV 2023",
    extra_options=BELIEF_OPTIONS + ("bansac_recall",),
)
def _build_bansac(problem, options, priors, order, extra):
    recall = float(declared_option("bansac_recall").check("bansac_recall", extra.get("bansac_recall", DEFAULT_RECALL)))
    sampler = BansacSampler(problem.n, priors, recall=recall, **belief_options(extra))
    components = judged_components(problem, options, priors, order, sampler)
    # the beliefs learn between batches: small ones (the paper updates after every hypothesis)
    components.batch_size, components.first_batch_size = min(int(options.batch_size), FEEDBACK_BATCH), None
    if options.budget is None:
        adaptive = components.termination
        components.termination = BansacTermination(sampler, options.confidence, int(options.max_iterations))
        components.listeners = [listener for listener in components.listeners if listener is not adaptive]
    return components
