"""R-RANSAC with the T(d,d) pre-test (Matas & Chum 2002, 2004): ALGORITHMS.md section 4.

Before a hypothesis is scored on all N correspondences it must explain d
randomly chosen ones (never its own sample, which it fits by construction).
Most contaminated hypotheses fail on the first point and cost one check
instead of N; a good hypothesis survives only with probability
``alpha ~ w^d``, so the stopping bound is stretched by ``1 / alpha``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from stereovo.estimation.partial import residuals_at
from stereovo.estimation.solvers import SAMPLE_SIZE
from stereovo.estimation.termination import all_inlier_probability
from stereovo.estimation.verification import ScoringContext


def random_points_excluding(samples: np.ndarray, n: int, d: int, rng: np.random.Generator) -> np.ndarray:
    """``(H, d)`` distinct random correspondences per row, none of them in that row's ``samples (H, 3)``.

    Uniform over the ``n - 3`` other points: random keys with the sample's own keys set
    to +inf, then the d smallest (``argpartition``), vectorised over the whole batch.
    """
    H = samples.shape[0]
    keys = rng.random((H, n))
    keys[np.arange(H)[:, None], samples] = np.inf
    chosen = np.argpartition(keys, d - 1, axis=1)[:, :d]
    # argpartition leaves the d smallest unordered; order them by key so the
    # "first" point of the test really is a uniformly random one.
    return np.take_along_axis(chosen, np.argsort(np.take_along_axis(keys, chosen, axis=1), axis=1), axis=1)


@dataclass
class TddVerification:
    """The T(d,d) pre-test, then full verification of the survivors.

    Args:
        d: points of the pre-test (d = 1 is the paper's optimum for its cost model).

    Cost accounting: a hypothesis that fails at its j-th pre-test point costs j
    checks; one that passes costs ``N`` (its d pre-test points plus the other N - d),
    i.e. ``d + P(pass) (N - d)`` per hypothesis on average.
    """

    d: int = 1
    uses_samples: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if int(self.d) != self.d or self.d < 1:
            raise ValueError(f"option tdd_d must be an integer >= 1, got {self.d!r}")
        self.d = int(self.d)
        self.n_passed = 0  # hypotheses that survived the pre-test (for tests and reports)
        self.n_tested = 0

    def verify(
        self, ctx: ScoringContext, R: np.ndarray, t: np.ndarray, rng: np.random.Generator, samples: np.ndarray
    ) -> tuple[np.ndarray, int]:
        """Scores ``(H,)`` (``-inf`` = failed the pre-test) and the point checks spent."""
        H, n = R.shape[0], ctx.problem.n
        d = min(self.d, n - SAMPLE_SIZE)
        scores = np.full(H, -np.inf)
        if d < 1:  # nothing outside the sample to pre-test on
            scores = ctx.score(R, t)
            return scores, H * n
        idx = random_points_excluding(samples, n, d, rng)
        consistent = residuals_at(ctx, R, t, idx) < ctx.threshold_sq  # (H, d)
        passed = np.all(consistent, axis=1)
        # A failing hypothesis stops at its first inconsistent point.
        first_fail = np.argmin(consistent, axis=1) + 1
        checks = int(np.sum(first_fail[~passed]))
        if np.any(passed):
            scores[passed] = ctx.score(R[passed], t[passed])
            checks += int(np.count_nonzero(passed)) * n
        self.n_passed += int(np.count_nonzero(passed))
        self.n_tested += H
        return scores, checks


@dataclass
class TddTermination:
    """``k = log(1 - p) / log(1 - q alpha)``: RANSAC's bound with the pre-test's pass rate.

    ``q`` is the all-inlier probability of a minimal sample (without replacement) and
    ``alpha = prod_{j<d} (I - 3 - j) / (N - 3 - j)`` the chance that a good hypothesis'
    d pre-test points, drawn without replacement from the N - 3 others, are inliers.
    """

    confidence: float = 0.99
    max_iterations: int = 10_000
    d: int = 1

    def required(self, n_inliers: int, n: int) -> int:
        q = float(all_inlier_probability(n_inliers, n))
        alpha = 1.0
        for j in range(self.d):
            alpha *= max(n_inliers - SAMPLE_SIZE - j, 0) / max(n - SAMPLE_SIZE - j, 1)
        p = q * alpha
        if p <= 0:
            return self.max_iterations
        if p >= 1:
            return 1
        k = int(np.ceil(np.log1p(-self.confidence) / np.log1p(-p)))
        return int(np.clip(k, 1, self.max_iterations))
