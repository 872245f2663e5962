"""Local optimisation run on each new best hypothesis.

``ConsensusRefit`` is the cheapest useful one: a few Levenberg-Marquardt steps
of the symmetric reprojection error on the hypothesis' own consensus, kept
only if it scores better. It matters here because
minimal fits on triangulated points are poorly conditioned, so the consensus
of a raw hypothesis understates the true inlier set and the adaptive bound
would otherwise be fed too small an inlier count.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from stereovo.estimation.roles.refinement import ReprojectionRefiner
from stereovo.estimation.roles.verification import ScoringContext


@dataclass(frozen=True)
class ConsensusRefit:
    """Refit on the consensus set and keep the result if its score is higher."""

    refiner: ReprojectionRefiner = ReprojectionRefiner(iterations=3, rounds=2)
    subsumed_by_refinement: bool = True  # the final refinement refits on the consensus too
    # this run's counts (a recipe builds its optimiser per estimate); mutable inside the frozen class
    counts: dict = field(default_factory=lambda: {"refit_runs": 0, "refit_improved": 0}, repr=False, compare=False)

    def improve(self, ctx: ScoringContext, R: np.ndarray, t: np.ndarray, inliers: np.ndarray, score: float,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
        if np.count_nonzero(inliers) < 3:
            return R, t, inliers, score, 0
        self.counts["refit_runs"] += 1
        R_new, t_new, _, residual_sq = self.refiner.refine_with_residuals(
            ctx.problem, R, t, inliers, ctx.residual_model, ctx.threshold_sq
        )
        checks = ctx.problem.n * self.refiner.rounds
        if residual_sq is not None:  # the refit's last gate residuals, in the context's model
            new_score = float(ctx.quality.score(residual_sq[None], ctx.threshold_sq)[0])
            new_inliers = residual_sq < ctx.threshold_sq
        else:
            scores, masks = ctx.score_and_inliers(R_new[None], t_new[None])
            new_score, new_inliers = float(scores[0]), masks[0]
            checks += ctx.problem.n
        if new_score > score:
            self.counts["refit_improved"] += 1
            return R_new, t_new, new_inliers, new_score, checks
        return R, t, inliers, score, checks

    def counters(self) -> dict[str, int | float]:
        """``refit_runs``: consensus refits run; ``refit_improved``: those that replaced the best."""
        return dict(self.counts)
