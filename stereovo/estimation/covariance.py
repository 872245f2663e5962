"""The covariance of an estimated motion, propagated from the pixel noise of both frames.

:func:`pose_covariance` is the first-order (sandwich) covariance of the least-squares fit that
:class:`~stereovo.estimation.roles.refinement.ReprojectionRefiner` minimises, carried to the error
vector ``e = (log(R_est R_true^T), t_est - t_true)`` by :func:`motion_error_jacobian`. Its sums
run in :mod:`stereovo.estimation.kernels.covariance`.
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels.base import MIN_DEPTH
from stereovo.estimation.kernels.covariance import pose_normal_equations
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.reprojection import gauss_newton_steps
from stereovo.geometry import so3_log

FIT_ITERATIONS = 20
"""Levenberg-Marquardt iterations of the least-squares fit that an unfitted motion's covariance is
taken about (:func:`pose_covariance` with ``fitted=False``); the fit stops earlier once converged."""


def _hat(v: np.ndarray) -> np.ndarray:
    """``(3, 3)`` cross-product matrix of ``v (3,)``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def motion_error_jacobian(t: np.ndarray) -> np.ndarray:
    """``(6, 6)`` map from the left perturbation ``delta = (rho, omega)`` of ``(R, t)``
    (``T <- exp(delta^) T``, the refinement's parametrisation) to the error vector
    ``e = (log(R' R^T), t' - t)``, to first order: ``e = (omega, rho - t^ omega)``."""
    M = np.zeros((6, 6))
    M[0:3, 3:6] = np.eye(3)
    M[3:6, 0:3] = np.eye(3)
    M[3:6, 3:6] = -_hat(np.asarray(t, dtype=float))
    return M


def pose_covariance(problem: StereoProblem, R: np.ndarray, t: np.ndarray, inliers: np.ndarray,
                    fitted: bool = True) -> np.ndarray | None:
    """Covariance ``(6, 6)`` of the error of the motion ``(R, t)`` on ``inliers``: that of their
    least-squares fit, plus, where ``(R, t)`` is not that fit (``fitted=False``), its offset from it.

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
    equations are singular.

    A motion that is not the least-squares fit of its inliers is offset from that fit by
    ``d = (log(R R_ls^T), t - t_ls)``, which the fit's covariance does not hold: its error is the
    fit's plus ``d``. With ``fitted=False`` the fit is computed here (Levenberg-Marquardt from
    ``(R, t)`` on the inliers, :data:`FIT_ITERATIONS`) and the covariance is the mean squared error
    ``Cov_ls + d d^T`` (both at the fit); :class:`~stereovo.estimation.api.MotionEstimate` always
    asks for it. Such motions: a method without a final refinement; a refinement rolled back
    because it scored worse under the method's gate; the papers' one least-squares refit
    (``least_squares_refit``), which fits the best hypothesis's consensus and then re-selects the
    inliers under the refit, so that the returned inliers (more rows than the fit saw) have another
    fit (``ransac`` on N 200, eps 0.3: median rotation error 0.056 deg, the fit of its returned
    inliers 0.020). Taken as the fit they were overconfident: mean normalised squared error about 100
    for ``ransac`` and 17 for ``probabilistic``'s rolled-back estimates, where 6 is consistent.
    """
    rows = np.flatnonzero(np.asarray(inliers, dtype=bool))
    if rows.size < 3:
        return None
    offset = None
    if not fitted:
        R_fit, t_fit, _ = gauss_newton_steps(
            problem.camera, np.asarray(R, dtype=float)[None], np.asarray(t, dtype=float)[None],
            problem.points_prev, problem.points_curr, problem.prev, problem.curr,
            weights=np.asarray(inliers, dtype=float), iterations=FIT_ITERATIONS,
        )
        if not (np.all(np.isfinite(R_fit)) and np.all(np.isfinite(t_fit))):
            return None
        offset = np.concatenate([so3_log(np.asarray(R, dtype=float) @ R_fit[0].T), np.asarray(t, dtype=float) - t_fit[0]])
        R, t = R_fit[0], t_fit[0]
    A, S, used = pose_normal_equations(
        np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(t, dtype=float),
        problem.points_prev, problem.points_curr, problem.prev, problem.curr, problem.camera.parameters,
        rows.astype(np.int64), MIN_DEPTH,
    )
    if used < 3:
        return None
    try:
        A_inv = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return None
    cov_delta = A_inv @ (problem.noise_sigma**2 * S) @ A_inv
    M = motion_error_jacobian(t)
    cov = M @ cov_delta @ M.T
    if offset is not None:
        cov = cov + np.outer(offset, offset)
    cov = 0.5 * (cov + cov.T)
    if not np.all(np.isfinite(cov)):
        return None
    return cov
