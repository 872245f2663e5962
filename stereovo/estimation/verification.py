"""Verification: how a batch of hypotheses is scored against the correspondences.

``FullVerification`` scores every hypothesis on every point. Cheaper
strategies (T(d,d), SPRT, preemptive breadth-first scoring) live beside it
and share its interface: scores ``(H,)`` with ``-inf`` for rejected
hypotheses, plus the number of point-hypothesis residual evaluations spent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.scoring import Quality, ResidualModel


@dataclass
class ScoringContext:
    """What every verifier and local optimiser needs to judge a hypothesis."""

    problem: StereoProblem
    residual_model: ResidualModel
    quality: Quality
    threshold_sq: float

    def residuals(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        return self.residual_model.squared(self.problem, R, t)

    def _scored_residuals(self, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cap = self.threshold_sq if self.quality.saturates else None
        sq = self.residual_model.squared(self.problem, R, t, cap=cap)
        return self.quality.score(sq, self.threshold_sq), sq

    def score(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Scores ``(H,)`` of hypotheses on all points."""
        return self._scored_residuals(R, t)[0]

    def score_and_inliers(self, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Scores ``(H,)`` and inlier masks ``(H, N)`` of hypotheses on all points."""
        scores, sq = self._scored_residuals(R, t)
        return scores, sq < self.threshold_sq


class Verifier(Protocol):
    def verify(
        self, ctx: ScoringContext, R: np.ndarray, t: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, int]:
        """Scores ``(H,)`` (``-inf`` = rejected) and the point checks spent."""
        ...


@dataclass
class FullVerification:
    """Score every hypothesis on all N correspondences."""

    def verify(
        self, ctx: ScoringContext, R: np.ndarray, t: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, int]:
        scores = ctx.score(R, t)
        return scores, R.shape[0] * ctx.problem.n
