"""Verification: how a batch of hypotheses is scored against the correspondences.

``FullVerification`` scores every hypothesis on every point. Cheaper
strategies (T(d,d), SPRT, preemptive breadth-first scoring) live beside it
and share its interface: scores ``(H,)`` with ``-inf`` for rejected
hypotheses, plus the number of point-hypothesis residual evaluations spent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.scoring import Quality, ResidualModel, squared_and_exact


@dataclass
class ScoringContext:
    """What every verifier and local optimiser needs to judge a hypothesis."""

    problem: StereoProblem
    residual_model: ResidualModel
    quality: Quality
    threshold_sq: float
    # keep the uncapped residuals of each batch scored on all points, for a sampler's feedback
    # (:meth:`exact_residuals`): one pass computes both where the residual model allows it
    keep_exact: bool = False
    # the hypotheses last scored on all points and their residuals: the loop reads the new best's
    # inliers from them instead of computing its residuals again
    # (R of the batch, residuals (M, N), row of each hypothesis in them or None for row i = hypothesis i)
    _last_scored: tuple | None = field(default=None, repr=False, compare=False)
    _last_exact: tuple | None = field(default=None, repr=False, compare=False)  # (R of the batch, residuals (H, N))

    def residuals(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        return self.residual_model.squared(self.problem, R, t)

    def exact_residuals(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """:meth:`residuals` ``(H, N)`` of the batch ``R, t``: those kept when it was just scored on
        all points with ``keep_exact`` (read-only), else computed now. The same values either way."""
        last = self._last_exact
        if last is not None and last[0] is R:
            return last[1]
        return self.residuals(R, t)

    def inliers_of(self, R: np.ndarray, t: np.ndarray, i: int) -> tuple[np.ndarray, bool]:
        """Inlier mask ``(N,)`` of hypothesis ``i`` of the batch ``R, t``, and whether its residuals
        had to be computed (False when the batch was just scored on all points: residuals capped
        at the gate still compare with it exactly)."""
        last = self._last_scored
        if last is not None and last[0] is R:
            rows = last[2] if len(last) > 2 else None
            row = i if rows is None else int(rows[i])
            if row >= 0:
                return last[1][row] < self.threshold_sq, False
        return self.residuals(R[i : i + 1], t[i : i + 1])[0] < self.threshold_sq, True

    def remember(self, R: np.ndarray, residual_sq: np.ndarray, rows: np.ndarray) -> None:
        """Keep the full residuals ``(M, N)`` an early-rejection verifier computed for some hypotheses
        of the batch ``R``: hypothesis i's are row ``rows[i]`` (-1: none), for :meth:`inliers_of`.
        Residuals capped at the gate are fine: they compare with it exactly."""
        self._last_scored = (R, residual_sq, rows)

    def _scored_residuals(self, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cap = self.threshold_sq if self.quality.saturates else None
        if self.keep_exact:
            sq, exact = squared_and_exact(self.residual_model, self.problem, R, t, cap)
            self._last_exact = (R, exact)
        else:
            sq = self.residual_model.squared(self.problem, R, t, cap=cap)
        self._last_scored = (R, sq)
        return self.quality.score(sq, self.threshold_sq), sq

    def score_with_residuals(self, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Scores ``(H,)`` and the squared residuals ``(H, N)`` they came from (capped at the gate
        when the quality saturates)."""
        return self._scored_residuals(R, t)

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
