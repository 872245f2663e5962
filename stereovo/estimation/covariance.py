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
    cov = 0.5 * (cov + cov.T)
    if not np.all(np.isfinite(cov)):
        return None
    return cov
