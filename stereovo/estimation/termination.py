"""When to stop drawing hypotheses: the adaptive confidence bound or a fixed budget."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SAMPLE_SIZE = 3


def all_inlier_probability(n_inliers: int | np.ndarray, n: int, sample_size: int = SAMPLE_SIZE) -> np.ndarray:
    """Chance ``q`` that a uniform minimal sample is all-inlier, drawn without replacement.

    ``q = prod_{i<s} (I - i) / (N - i)`` (Schoenberger, Larsson & Pollefeys 2025), not ``w^s``.
    """
    I = np.asarray(n_inliers, dtype=float)
    q = np.ones_like(I)
    for i in range(sample_size):
        q = q * np.clip(I - i, 0, None) / max(n - i, 1)
    return q


def required_iterations(
    n_inliers: int | np.ndarray,
    n: int,
    confidence: float = 0.99,
    max_iterations: int = 10_000,
    sample_size: int = SAMPLE_SIZE,
) -> np.ndarray:
    """``k = ceil(log(1 - p) / log(1 - q))``, clipped to ``[1, max_iterations]``.

    ``I < s`` gives ``q = 0`` and ``max_iterations`` (never a division by log 1); ``I = N`` gives 1.
    """
    q = all_inlier_probability(n_inliers, n, sample_size)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.ceil(np.log1p(-confidence) / np.log1p(-np.minimum(q, 1.0)))
    k = np.where(q <= 0, max_iterations, np.where(q >= 1, 1, k))
    return np.clip(k, 1, max_iterations).astype(np.int64)


@dataclass
class AdaptiveTermination:
    """Stop once ``confidence`` guarantees an all-inlier sample given the best support so far."""

    confidence: float = 0.99
    max_iterations: int = 10_000
    min_iterations: int = 1

    def __post_init__(self) -> None:
        if not 0 < self.confidence < 1:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence}")
        if self.max_iterations < 1 or self.min_iterations < 1 or self.min_iterations > self.max_iterations:
            raise ValueError(
                f"need 1 <= min_iterations <= max_iterations, got {self.min_iterations} and {self.max_iterations}"
            )

    def required(self, n_inliers: int, n: int) -> int:
        # Scalar arithmetic of required_iterations: the loop asks after every batch.
        q = 1.0
        for i in range(SAMPLE_SIZE):
            q *= max(n_inliers - i, 0) / max(n - i, 1)
        if q <= 0.0:
            k = self.max_iterations
        elif q >= 1.0:
            k = 1
        else:
            k = min(max(math.ceil(math.log1p(-self.confidence) / math.log1p(-q)), 1), self.max_iterations)
        return max(int(k), self.min_iterations)


@dataclass
class FixedBudget:
    """Draw exactly ``budget`` hypotheses, whatever the support: the environment's default."""

    budget: int = 32

    def __post_init__(self) -> None:
        if self.budget < 1:
            raise ValueError(f"hypothesis budget must be >= 1, got {self.budget}")

    @property
    def max_iterations(self) -> int:
        return self.budget

    def required(self, n_inliers: int, n: int) -> int:
        return self.budget
