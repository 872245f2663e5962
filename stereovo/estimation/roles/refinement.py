"""Refinement of one motion on its inliers: Levenberg-Marquardt over se(3).

Minimises the symmetric stereo reprojection error (the k-1 point into both
images at k, the k point into both images at k-1) over the inliers, then
re-selects inliers and repeats, because a better model admits inliers the first
gate missed. The re-selection uses the caller's gate unless the refiner carries
its own (the probabilistic RANSAC judges hypotheses by 3-D Mahalanobis distance
but selects the final inliers in pixels, see :class:`PixelMahalanobisResidual`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stereovo.estimation.kernels.refinement import (
    GATE_MAHALANOBIS,
    GATE_PIXEL_MAHALANOBIS,
    GATE_REPROJECTION,
    refine_rounds,
)
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.reprojection import gauss_newton_steps
from stereovo.estimation.roles.scoring import (
    MahalanobisResidual,
    PixelMahalanobisResidual,
    ReprojectionResidual,
    ResidualModel,
)

# Gates whose residual kernel the compiled refinement loop calls itself (exactly these classes: a
# subclass may compute its residuals otherwise, and takes the Python loop).
_COMPILED_GATES = {
    ReprojectionResidual: GATE_REPROJECTION,
    MahalanobisResidual: GATE_MAHALANOBIS,
    PixelMahalanobisResidual: GATE_PIXEL_MAHALANOBIS,
}


LM_DAMPING = 1e-6  # LM damping relative to the normal equations' diagonal
LM_TOLERANCE = 1e-12  # a step below this (rad, m) ends a round's LM
_NO_RESIDUALS = np.empty(0)  # the compiled rounds' "no start residuals given"

# A refinement's result: R (3, 3), t (3,), inliers (N,) bool, and the squared residuals (N,) or None.
RefinedFit = tuple[np.ndarray, np.ndarray, np.ndarray, "np.ndarray | None"]


@dataclass(frozen=True)
class ReprojectionRefiner:
    """LM on the symmetric reprojection error of the inliers, alternating with inlier re-selection.

    Args:
        iterations: LM iterations per round.
        rounds: at most this many refine / re-select rounds (they stop once the inliers stay the same).
        huber_px: Huber threshold (pixels) on each point's residual norm; None for plain least squares.
        gate: optional ``(residual_model, threshold_sq)`` for re-selecting inliers after each round,
            in place of the caller's.
    """

    iterations: int = 6
    rounds: int = 3
    huber_px: float | None = None
    gate: tuple[ResidualModel, float] | None = None

    def refine(self, problem: StereoProblem, R: np.ndarray, t: np.ndarray, inliers: np.ndarray,
               residual_model: ResidualModel, threshold_sq: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the refined ``(R, t)`` and its inlier mask ``(N,)`` under ``threshold_sq``
        (or under the refiner's own gate)."""
        return self.refine_with_residuals(problem, R, t, inliers, residual_model, threshold_sq)[:3]

    def refine_with_residuals(self, problem: StereoProblem, R: np.ndarray, t: np.ndarray, inliers: np.ndarray,
                              residual_model: ResidualModel, threshold_sq: float, start_sq: np.ndarray | None = None,
                              gate_residuals: bool = False) -> RefinedFit:
        """:meth:`refine`, plus the squared residuals ``(N,)`` of the returned motion under the
        caller's ``residual_model``, or None where they were not computed here (the motion is the
        one given, or the refiner's own gate selected the inliers). A caller that scores the
        result with that model reads them instead of computing them again.

        ``start_sq``: the refiner's own gate's residuals ``(N,)`` of ``(R, t)``, where the caller
        has them (its first re-selection reads them instead of computing them). With
        ``gate_residuals`` the residuals returned are the gate's (the model that selected the
        returned inliers: the refiner's own, else the caller's), or None where not computed."""
        gate_model = residual_model if self.gate is None else self.gate[0]
        if type(gate_model) in _COMPILED_GATES:
            R, t, inliers, residual_sq = self._refine_compiled(problem, R, t, inliers, residual_model, threshold_sq,
                                                               start_sq)
        else:
            R, t, inliers, residual_sq = self._refine_in_python(problem, R, t, inliers, residual_model, threshold_sq,
                                                                start_sq)
        return R, t, inliers, (residual_sq if self.gate is None or gate_residuals else None)

    def _refine_compiled(self, problem: StereoProblem, R: np.ndarray, t: np.ndarray, inliers: np.ndarray,
                         residual_model: ResidualModel, threshold_sq: float,
                         start_sq: np.ndarray | None = None) -> RefinedFit:
        """The rounds in one compiled call, for a gate with a residual kernel: per round the
        Python loop spends about as long on its bookkeeping as the kernels spend on a few hundred
        inliers. Residuals are the gate's, as in :meth:`_refine_in_python`."""
        gate_model, gate_threshold_sq = (residual_model, threshold_sq) if self.gate is None else self.gate
        R, t, inliers, residual_sq, computed = refine_rounds(
            np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(t, dtype=float),
            problem.points_prev, problem.points_curr, problem.prev, problem.curr, problem.camera.parameters,
            problem.cov_prev, problem.cov_curr, problem.noise_sigma**2, np.asarray(inliers, dtype=bool),
            _COMPILED_GATES[type(gate_model)], float(gate_threshold_sq), self.gate is not None,
            int(self.rounds), int(self.iterations), 0.0 if self.huber_px is None else float(self.huber_px),
            LM_DAMPING, LM_TOLERANCE, _NO_RESIDUALS if start_sq is None or self.gate is None else start_sq,
        )
        return R, t, inliers, (residual_sq if computed else None)

    def _refine_in_python(self, problem: StereoProblem, R: np.ndarray, t: np.ndarray, inliers: np.ndarray,
                          residual_model: ResidualModel, threshold_sq: float,
                          start_sq: np.ndarray | None = None) -> RefinedFit:
        """The rounds for any residual model, one kernel call at a time; the residuals returned
        are those of the model that selected the inliers (the gate's, if the refiner has one)."""
        n_inliers = int(np.count_nonzero(inliers))
        residual_sq = None
        if self.gate is not None:
            residual_model, threshold_sq = self.gate
            # Start from the refiner's own gate: the caller's inliers were selected by another rule.
            regated_sq = residual_model.squared(problem, R[None], t[None])[0] if start_sq is None else start_sq
            regated = regated_sq < threshold_sq
            n_regated = int(np.count_nonzero(regated))
            if n_regated >= n_inliers // 2:
                inliers, n_inliers, residual_sq = regated, n_regated, regated_sq
        for _ in range(self.rounds):
            if n_inliers < 3:
                break
            # Outliers get weight 0, which the kernel skips: same sums as on the gathered inliers, no copies.
            R_new, t_new, _ = gauss_newton_steps(
                problem.camera,
                R[None],
                t[None],
                problem.points_prev,
                problem.points_curr,
                problem.prev,
                problem.curr,
                weights=inliers.astype(float),
                iterations=self.iterations,
                damping=LM_DAMPING,
                huber=self.huber_px,
                tolerance=LM_TOLERANCE,
            )
            new_sq = residual_model.squared(problem, R_new, t_new)[0]
            new_inliers = new_sq < threshold_sq
            n_new = int(np.count_nonzero(new_inliers))
            if n_new < n_inliers // 2:
                break  # refinement ran away from the consensus: keep what we had
            R, t, residual_sq = R_new[0], t_new[0], new_sq
            same = n_new == n_inliers and not np.any(new_inliers != inliers)
            inliers, n_inliers = new_inliers, n_new
            if same:
                break
        return R, t, inliers, residual_sq
