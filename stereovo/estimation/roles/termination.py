"""When to stop drawing hypotheses: the adaptive confidence bound or a fixed budget."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from stereovo.estimation.kernels.stopping import adaptive_bound
from stereovo.estimation.roles.solvers import SAMPLE_SIZE


def all_inlier_probability(n_inliers: int | np.ndarray, n: int, sample_size: int = SAMPLE_SIZE) -> np.ndarray:
    """Chance ``q`` that a uniform minimal sample is all-inlier, drawn without replacement.

    ``q = prod_{i<s} (I - i) / (N - i)`` (Schoenberger, Larsson & Pollefeys 2025), not ``w^s``.
    Elementwise over an array of counts; a 0-d array for one count.
    """
    I = np.asarray(n_inliers, dtype=float)
    q = np.ones_like(I)
    for i in range(sample_size):
        q = q * np.maximum(I - i, 0.0) / max(n - i, 1)
    return q


def required_iterations(
    n_inliers: int | np.ndarray,
    n: int,
    confidence: float = 0.99,
    max_iterations: int = 10_000,
    sample_size: int = SAMPLE_SIZE,
) -> int | np.ndarray:
    """``k = ceil(log(1 - p) / log(1 - q))``, clipped to ``[1, max_iterations]``.

    ``I < s`` gives ``q = 0`` and ``max_iterations`` (never a division by log 1); ``I = N`` gives 1.
    One count gives an ``int`` (scalar arithmetic: the loop asks after every batch); an array of
    counts gives an int64 array of the same shape.
    """
    # one count, the loop's case after every batch: np.ndim costs more than the cached bound
    if not isinstance(n_inliers, (int, np.integer)) and np.ndim(n_inliers) > 0:
        counts = np.asarray(n_inliers)
        bounds = [required_iterations(int(i), n, confidence, max_iterations, sample_size) for i in counts.ravel()]
        return np.array(bounds, dtype=np.int64).reshape(counts.shape)
    return _required_for_count(int(n_inliers), int(n), float(confidence), int(max_iterations), int(sample_size))


@functools.lru_cache(maxsize=4096)
def _required_for_count(n_inliers: int, n: int, confidence: float, max_iterations: int, sample_size: int) -> int:
    # The loop asks after every batch, mostly with a count it asked before: cache the bound. The one
    # formula, compiled, which the compiled search calls too.
    return int(adaptive_bound(float(n_inliers), n, confidence, max_iterations, sample_size))


def iterations_for(q: float, confidence: float, max_iterations: int) -> int:
    """``k = ceil(log(1 - p) / log(1 - q))`` in ``[1, max_iterations]`` for one draw's all-inlier chance ``q``."""
    if not q > 0.0:
        return max_iterations
    if q >= 1.0:
        return 1
    return min(max(math.ceil(math.log1p(-confidence) / math.log1p(-q)), 1), max_iterations)


def check_bound(confidence: float, max_iterations: int) -> None:
    """The arguments every adaptive bound shares: ``confidence`` in (0, 1), ``max_iterations`` >= 1.

    Raises:
        ValueError: naming the argument and its value.
    """
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    if max_iterations < 1:
        raise ValueError(f"max_iterations must be >= 1, got {max_iterations}")


class SampleProbability:
    """``q`` of one draw of a given sampler for the best model's inliers (a loop listener).

    Uniform sampling (no sampler, or one whose class sets ``uniform = True``) has the count
    formula :func:`all_inlier_probability`; any other sampler is asked, on every new best, for
    ``sampler.all_inlier_probability(inliers)``: guided weights, a learned policy's priors.
    Before the first best a guided sampler's ``q`` is 0 (keep drawing).

    A sampler whose draws change along a known schedule (PROSAC's growing prefix) has no one ``q``:
    given ``confidence``, ``draws`` is its ``required_draws(inliers, confidence)``, the fewest draws
    from the first after which an all-inlier one was drawn with that confidence, and ``q`` the
    per-draw chance that would need as many, ``1 - (1 - confidence)^(1 / draws)`` (the geometric
    mean of the schedule's miss chances up to there). Without ``confidence``, ``q`` is the next
    draw's chance.
    """

    def __init__(self, sampler=None, confidence: float | None = None) -> None:
        self.sampler = sampler
        self.guided = (
            sampler is not None and not getattr(sampler, "uniform", False)
            and callable(getattr(sampler, "all_inlier_probability", None))
        )
        self.confidence = confidence
        self.scheduled = self.guided and confidence is not None and callable(getattr(sampler, "required_draws", None))
        self.q = 0.0  # the guided q of the latest best (unused for uniform sampling)
        self.draws = math.inf  # a scheduled sampler's required draws for the latest best
        self.updates = 0
        self._by_count: dict[tuple[int, int], float] = {}  # the count formula's q per (I, N): asked every batch

    def on_new_best(self, inliers: np.ndarray, state) -> None:
        if self.scheduled:
            self.draws = float(self.sampler.required_draws(inliers, self.confidence))
            self.q = -math.expm1(math.log1p(-self.confidence) / self.draws) if self.draws < math.inf else 0.0
            self.updates += 1
        elif self.guided:
            self.q = float(self.sampler.all_inlier_probability(inliers))
            self.updates += 1

    def of(self, n_inliers: int, n: int) -> float:
        """``q`` for the best model (``n_inliers`` of ``n``): the sampler's if guided, else the count formula."""
        if self.guided:
            return self.q
        q = self._by_count.get((n_inliers, n))
        if q is None:
            if len(self._by_count) > 64:
                self._by_count.clear()
            q = self._by_count[(n_inliers, n)] = float(all_inlier_probability(n_inliers, n))
        return q


@dataclass
class AdaptiveTermination:
    """Stop once ``confidence`` guarantees an all-inlier sample given the best support so far.

    ``k = ceil(log(1 - p) / log(1 - q))`` with ``q`` the chance that one draw *of the sampler in
    use* is all-inlier given the best model's inliers: the without-replacement count formula for
    uniform sampling (bit for bit the bound without a sampler), the sampler's own
    ``all_inlier_probability(inliers)`` otherwise. A sampler whose draws follow a schedule (PROSAC's
    growing prefix: :class:`SampleProbability`) stops after its ``required_draws``, counted from the
    first draw. With a guided sampler it reads the inlier mask in ``on_new_best``, which the loop
    calls on its termination (:class:`stereovo.estimation.loop.RansacComponents`).
    """

    confidence: float = 0.99
    max_iterations: int = 10_000
    min_iterations: int = 1
    sampler: object = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not 0 < self.confidence < 1:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence}")
        if self.max_iterations < 1 or self.min_iterations < 1 or self.min_iterations > self.max_iterations:
            raise ValueError(
                f"need 1 <= min_iterations <= max_iterations, got {self.min_iterations} and {self.max_iterations}"
            )
        self.probability = SampleProbability(self.sampler, self.confidence)

    def on_new_best(self, inliers: np.ndarray, state) -> None:
        self.probability.on_new_best(inliers, state)

    def required(self, n_inliers: int, n: int) -> int:
        if not self.probability.guided:
            return max(required_iterations(n_inliers, n, self.confidence, self.max_iterations), self.min_iterations)
        if self.probability.scheduled:  # counted from the first draw, as the schedule's product is
            k = self.max_iterations if self.probability.draws >= self.max_iterations else int(self.probability.draws)
        else:
            k = iterations_for(self.probability.q, self.confidence, self.max_iterations)
        return max(k, self.min_iterations)

    def counters(self) -> dict[str, int | float]:
        """``stop_guided``: 1 if the bound used the sampler's q; ``stop_q``: the guided q of the final best."""
        if not self.probability.guided:
            return {"stop_guided": 0}
        return {"stop_guided": 1, "stop_q": self.probability.q}


@dataclass
class FixedBudget:
    """Draw exactly ``budget`` hypotheses, whatever the support: the environment's default."""

    budget: int = 32
    is_budget: bool = True  # the loop's cap is the stop itself: reaching it confirms nothing and fails nothing

    def __post_init__(self) -> None:
        if self.budget < 1:
            raise ValueError(f"hypothesis budget must be >= 1, got {self.budget}")

    @property
    def max_iterations(self) -> int:
        return self.budget

    def required(self, n_inliers: int, n: int) -> int:
        return self.budget
