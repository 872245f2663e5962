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

from stereovo.estimation import kernels
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.reprojection import gauss_newton_steps
from stereovo.estimation.scoring import (
    MahalanobisResidual,
    PixelMahalanobisResidual,
    ReprojectionResidual,
    ResidualModel,
)

# Gates whose residual kernel the compiled refinement loop calls itself (exactly these classes: a
# subclass may compute its residuals otherwise, and takes the Python loop).
_COMPILED_GATES = {
    ReprojectionResidual: kernels.GATE_REPROJECTION,
    MahalanobisResidual: kernels.GATE_MAHALANOBIS,
    PixelMahalanobisResidual: kernels.GATE_PIXEL_MAHALANOBIS,
}


_DAMPING = 1e-6  # LM damping relative to the normal equations' diagonal
_TOLERANCE = 1e-12  # a step below this (rad, m) ends a round's LM


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

    def refine(
        self,
        problem: StereoProblem,
        R: np.ndarray,
        t: np.ndarray,
        inliers: np.ndarray,
        residual_model: ResidualModel,
        threshold_sq: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the refined ``(R, t)`` and its inlier mask ``(N,)`` under ``threshold_sq``
        (or under the refiner's own gate)."""
        return self.refine_with_residuals(problem, R, t, inliers, residual_model, threshold_sq)[:3]

    def refine_with_residuals(
        self,
        problem: StereoProblem,
        R: np.ndarray,
        t: np.ndarray,
        inliers: np.ndarray,
        residual_model: ResidualModel,
        threshold_sq: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """:meth:`refine`, plus the squared residuals ``(N,)`` of the returned motion under the
        caller's ``residual_model``, or None where they were not computed here (the motion is the
        one given, or the refiner's own gate selected the inliers). A caller that scores the
        result with that model reads them instead of computing them again."""
        gate_model = residual_model if self.gate is None else self.gate[0]
        if type(gate_model) in _COMPILED_GATES:
            R, t, inliers, residual_sq = self._refine_compiled(problem, R, t, inliers, residual_model, threshold_sq)
        else:
            R, t, inliers, residual_sq = self._refine_in_python(problem, R, t, inliers, residual_model, threshold_sq)
        return R, t, inliers, (residual_sq if self.gate is None else None)

    def _refine_compiled(
        self,
        problem: StereoProblem,
        R: np.ndarray,
        t: np.ndarray,
        inliers: np.ndarray,
        residual_model: ResidualModel,
        threshold_sq: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """The rounds in one compiled call, for a gate with a residual kernel: per round the
        Python loop spends about as long on its bookkeeping as the kernels spend on a few hundred
        inliers. Residuals are the gate's, as in :meth:`_refine_in_python`."""
        gate_model, gate_threshold_sq = (residual_model, threshold_sq) if self.gate is None else self.gate
        R, t, inliers, residual_sq, computed = kernels.refine_rounds(
            np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(t, dtype=float),
            problem.points_prev, problem.points_curr, problem.prev, problem.curr, problem.camera.parameters,
            problem.cov_prev, problem.cov_curr, problem.noise_sigma**2, np.asarray(inliers, dtype=bool),
            _COMPILED_GATES[type(gate_model)], float(gate_threshold_sq), self.gate is not None,
            int(self.rounds), int(self.iterations), 0.0 if self.huber_px is None else float(self.huber_px),
            _DAMPING, _TOLERANCE,
        )
        return R, t, inliers, (residual_sq if computed else None)

    def _refine_in_python(
        self,
        problem: StereoProblem,
        R: np.ndarray,
        t: np.ndarray,
        inliers: np.ndarray,
        residual_model: ResidualModel,
        threshold_sq: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """The rounds for any residual model, one kernel call at a time; the residuals returned
        are those of the model that selected the inliers (the gate's, if the refiner has one)."""
        n_inliers = int(np.count_nonzero(inliers))
        residual_sq = None
        if self.gate is not None:
            residual_model, threshold_sq = self.gate
            # Start from the refiner's own gate: the caller's inliers were selected by another rule.
            regated_sq = residual_model.squared(problem, R[None], t[None])[0]
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
                damping=_DAMPING,
                huber=self.huber_px,
                tolerance=_TOLERANCE,
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


def _hat(v: np.ndarray) -> np.ndarray:
    """``(M, 3, 3)`` cross-product matrices of ``v (M, 3)``."""
    H = np.zeros(v.shape[:-1] + (3, 3))
    H[..., 0, 1], H[..., 0, 2] = -v[..., 2], v[..., 1]
    H[..., 1, 0], H[..., 1, 2] = v[..., 2], -v[..., 0]
    H[..., 2, 0], H[..., 2, 1] = -v[..., 1], v[..., 0]
    return H


def _projection_jacobian(camera, P: np.ndarray) -> np.ndarray:
    """``(M, 4, 3)``: d(uL, vL, uR, vR)/dP of points ``P (M, 3)`` in front of the camera."""
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    iz = 1.0 / z
    J = np.zeros((P.shape[0], 4, 3))
    J[:, 0, 0] = J[:, 2, 0] = camera.fx * iz
    J[:, 1, 1] = J[:, 3, 1] = camera.fy * iz
    J[:, 0, 2] = -camera.fx * x * iz * iz
    J[:, 2, 2] = -camera.fx * (x - camera.baseline) * iz * iz
    J[:, 1, 2] = J[:, 3, 2] = -camera.fy * y * iz * iz
    return J


def motion_error_jacobian(t: np.ndarray) -> np.ndarray:
    """``(6, 6)`` map from the left perturbation ``delta = (rho, omega)`` of ``(R, t)``
    (``T <- exp(delta^) T``, the refinement's parametrisation) to the error vector
    ``e = (log(R' R^T), t' - t)``, to first order: ``e = (omega, rho - t^ omega)``."""
    M = np.zeros((6, 6))
    M[0:3, 3:6] = np.eye(3)
    M[3:6, 0:3] = np.eye(3)
    M[3:6, 3:6] = -_hat(np.asarray(t, dtype=float)[None])[0]
    return M


def pose_covariance(problem: StereoProblem, R: np.ndarray, t: np.ndarray, inliers: np.ndarray) -> np.ndarray | None:
    """Covariance ``(6, 6)`` of the error of the motion fitted by least squares on ``inliers``.

    The error vector is ``e = (log(R_est R_true^T), t_est - t_true)``: rotation first (rad, the
    world-side, left-multiplied form), then translation (m). The fit is the refinement's: the
    symmetric stereo reprojection error (the k-1 point into both images at k, the k point into
    both images at k-1, :class:`ReprojectionRefiner`) with equal weights. Both of its residual
    blocks carry the noise of both frames: the forward residual
    ``pi(R X(m_prev) + t) - m_curr`` moves with ``m_curr`` and, through triangulation, with
    ``m_prev``; the backward one the other way round. So the frame-k reprojection Jacobian's
    ``sigma^2 (J^T J)^-1`` would be overconfident; the consistent first-order covariance of the
    minimiser (the estimate's implicit function of the measurements) is the sandwich

        ``Cov(delta) = A^-1 (sigma^2 sum_i J_i^T F_i F_i^T J_i) A^-1``, ``A = sum_i J_i^T J_i``,

    ``J_i (8, 6)`` the residuals' pose Jacobian, ``F_i`` their Jacobian with respect to the
    pixels the match measured in both frames (``(uL, uR, v)`` each, or ``(uL, vL, uR, vR)``
    under ``camera.v_measurement="independent"``), ``sigma`` the pixel noise. It is carried to
    ``e`` by :func:`motion_error_jacobian`. Returns None if fewer than 3 inliers or the normal
    equations are singular. A motion that was not refined (``refine=False``) gets the
    covariance of the least-squares fit it would have been refined to.
    """
    rows = np.flatnonzero(np.asarray(inliers, dtype=bool))
    if rows.size < 3:
        return None
    camera = problem.camera
    R = np.asarray(R, dtype=float)
    t = np.asarray(t, dtype=float)
    X, Y = problem.points_prev[rows], problem.points_curr[rows]
    mp, mc = problem.prev[rows], problem.curr[rows]
    P = X @ R.T + t  # the k-1 point in frame k
    Q = (Y - t) @ R  # the k point in frame k-1: R^T (Y - t)
    if np.any(P[:, 2] <= kernels.MIN_DEPTH) or np.any(Q[:, 2] <= kernels.MIN_DEPTH):
        keep = (P[:, 2] > kernels.MIN_DEPTH) & (Q[:, 2] > kernels.MIN_DEPTH)  # no Jacobian behind the camera
        if np.count_nonzero(keep) < 3:
            return None
        X, Y, mp, mc, P, Q = X[keep], Y[keep], mp[keep], mc[keep], P[keep], Q[keep]
    m = X.shape[0]
    Jp, Jq = _projection_jacobian(camera, P), _projection_jacobian(camera, Q)
    # pose Jacobians: forward d/d delta of P = [I | -P^]; backward R^T [-I | Y^]
    G_fwd = np.concatenate([np.broadcast_to(np.eye(3), (m, 3, 3)), -_hat(P)], axis=2)
    G_bwd = R.T @ np.concatenate([np.broadcast_to(-np.eye(3), (m, 3, 3)), _hat(Y)], axis=2)
    J = np.concatenate([Jp @ G_fwd, Jq @ G_bwd], axis=1)  # (m, 8, 6)
    # measurement Jacobians: the measured pixels of each frame and where they enter the residual rows
    T_prev, T_curr = camera.measurement_jacobian(mp), camera.measurement_jacobian(mc)
    k = T_prev.shape[2]
    E = np.eye(4) if k == 4 else np.array([[1.0, 0, 0], [0, 0, 1], [0, 1, 0], [0, 0, 1]])  # (uL, uR, v) -> rows
    F = np.zeros((m, 8, 2 * k))
    F[:, 0:4, 0:k] = Jp @ (R @ T_prev)  # forward rows vs the k-1 pixels (through triangulation)
    F[:, 0:4, k:] = -E  # ... and the k pixels they are compared with
    F[:, 4:8, k:] = Jq @ (R.T @ T_curr)  # backward rows vs the k pixels
    F[:, 4:8, 0:k] = -E
    A = np.einsum("mri,mrj->ij", J, J)
    B = np.swapaxes(J, 1, 2) @ F  # (m, 6, 2k): the gradient's sensitivity to each measured pixel
    S = problem.noise_sigma**2 * np.einsum("mik,mjk->ij", B, B)
    try:
        A_inv = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return None
    cov_delta = A_inv @ S @ A_inv
    M = motion_error_jacobian(t)
    cov = M @ cov_delta @ M.T
    cov = 0.5 * (cov + cov.T)
    if not np.all(np.isfinite(cov)):
        return None
    return cov
