"""Residual models and hypothesis quality measures, vectorised over hypotheses and points.

A *residual model* turns motions ``(H, 3, 3), (H, 3)`` into squared residuals
``(H, N)`` in its own units with a default inlier gate; a *quality* turns those
into one score per hypothesis (higher is better). Classical variants pick one
of each: RANSAC = count, MSAC = truncated quadratic, the probabilistic RANSAC
of Brink et al. = count under the Mahalanobis gate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np
from scipy.stats import chi2

from stereovo.estimation.kernels.mahalanobis import mahalanobis_sq, mahalanobis_sq_and_exact, pixel_mahalanobis_sq
from stereovo.estimation.kernels.scores import count_below
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.reprojection import reprojection_sq

CHI2_3_95 = float(chi2.ppf(0.95, 3))  # 7.81: Mahalanobis gate on 3-D residuals
CHI2_4_99 = float(chi2.ppf(0.99, 4))  # 13.28: pixel Mahalanobis gate, independent vL and vR (4 dof)
CHI2_3_99 = float(chi2.ppf(0.99, 3))  # 11.34: pixel Mahalanobis gate, one v per match (3 dof)


class ResidualModel(Protocol):
    """Squared residuals of every correspondence under every hypothesis."""

    name: str
    threshold_sq: float  # inlier gate on the squared residual, in the model's units

    def squared(self, problem: StereoProblem, R: np.ndarray, t: np.ndarray, cap: float | None = None) -> np.ndarray:
        """``(H, N)`` squared residuals for motions ``R (H, 3, 3)``, ``t (H, 3)``.

        With a ``cap``, a residual at or above it may be returned as any value >= cap (a model
        may bound rather than compute it); values below the cap are exact.
        """
        ...


def squared_and_exact(
    model: ResidualModel, problem: StereoProblem, R: np.ndarray, t: np.ndarray, cap: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """``(scored, exact)``, each ``(H, N)``: ``model.squared`` under ``cap`` and without one, in one
    pass where the model allows it. A model whose ``bounds_at_cap`` is False computes every residual
    whatever the cap, so one array serves as both (read-only); one with ``squared_and_exact`` fills
    both at once; any other model is called twice. A sampler's feedback reads the exact residuals of
    the batch the loop has just scored, and this spares it the second pass."""
    if cap is None or not getattr(model, "bounds_at_cap", True):
        sq = model.squared(problem, R, t, cap=cap)
        return sq, sq
    both = getattr(model, "squared_and_exact", None)
    if both is not None:
        return both(problem, R, t, cap)
    return model.squared(problem, R, t, cap=cap), model.squared(problem, R, t)


@dataclass(frozen=True)
class MahalanobisResidual:
    """Brink et al.: ``r_i = Y_i - (R X_i + t)`` under ``R Sigma_X R^T + Sigma_Y``; unit-free, chi-square(3).

    The two covariances are the camera's triangulation covariance evaluated at the landmark's
    fused estimate from both observations under the hypothesis (whose disparity in each frame is
    the mean of the two observations carried there), not at the two noisy triangulations: evaluated there, a far match
    whose depths disagree gets a covariance inflated by the disagreement and the gate passes
    too many (0.937 instead of 0.90 at 45-60 m). See ``mahalanobis_sq``.
    """

    threshold_sq: float = CHI2_3_95
    name: str = "mahalanobis"
    bounds_at_cap: ClassVar[bool] = True

    def squared(self, problem: StereoProblem, R: np.ndarray, t: np.ndarray, cap: float | None = None) -> np.ndarray:
        return mahalanobis_sq(
            np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(t, dtype=float),
            problem.points_prev, problem.points_curr, problem.camera.parameters, problem.noise_sigma**2,
            0.0 if cap is None else float(cap),
        )

    def squared_and_exact(self, problem: StereoProblem, R: np.ndarray, t: np.ndarray,
                          cap: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`squared` under ``cap`` and without one, ``(H, N)`` each, from one pass."""
        return mahalanobis_sq_and_exact(
            np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(t, dtype=float),
            problem.points_prev, problem.points_curr, problem.camera.parameters, problem.noise_sigma**2, float(cap),
        )


@dataclass(frozen=True)
class PixelMahalanobisResidual:
    """The k-1 point moved and projected into both images at k, whitened; unit-free, chi-square with
    ``camera.measurement_dof`` degrees of freedom: 3 for one v per rectified match
    (``v_measurement="shared"``, the default threshold), 4 for independent vL and vR.

    The residual ``pi(R X_i + t) - m_i`` (pixels) has covariance ``sigma^2 I + J R Sigma_X R^T J^T``
    (with one v, its vL and vR rows are the same measurement):
    the pixel noise at k plus the triangulation noise of ``X_i`` carried through the motion and the
    projection. Unlike the 3-D Mahalanobis distance this linearises the smooth map from the pixels at
    k-1 to the predicted pixels at k rather than triangulation itself, whose depth error is skewed
    for far points, so its chi-square gate keeps the inliers it promises (far points included).
    """

    threshold_sq: float = CHI2_3_99
    name: str = "pixel-mahalanobis"
    bounds_at_cap: ClassVar[bool] = False  # every residual is computed, whatever the cap

    def squared(self, problem: StereoProblem, R: np.ndarray, t: np.ndarray, cap: float | None = None) -> np.ndarray:
        return pixel_mahalanobis_sq(
            np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(t, dtype=float),
            problem.points_prev, problem.cov_prev, problem.curr,
            problem.camera.parameters,
            problem.noise_sigma**2,
        )


@dataclass(frozen=True)
class ReprojectionResidual:
    """Pixels^2: the k-1 point moved by the hypothesis and projected into both images at k."""

    threshold_sq: float = 9.0  # (3 px)^2; estimate_motion scales it with the pixel noise
    name: str = "reprojection"
    bounds_at_cap: ClassVar[bool] = False  # every residual is computed, whatever the cap

    def squared(self, problem: StereoProblem, R: np.ndarray, t: np.ndarray, cap: float | None = None) -> np.ndarray:
        return reprojection_sq(problem.camera, R, t, problem.points_prev, problem.curr)


class Quality(Protocol):
    """Score ``(H,)`` (higher is better) from squared residuals ``(H, N)`` and the gate.

    A quality that depends on a residual only through ``min(e^2, T^2)`` sets ``saturates = True``;
    it is then scored on residuals capped at the gate (see :meth:`ResidualModel.squared`).
    """

    name: str
    saturates: bool

    def score(self, residual_sq: np.ndarray, threshold_sq: float) -> np.ndarray: ...


@dataclass(frozen=True)
class InlierCount:
    """RANSAC (Fischler & Bolles 1981): the number of residuals under the gate."""

    name: str = "count"
    saturates: bool = True

    def score(self, residual_sq: np.ndarray, threshold_sq: float) -> np.ndarray:
        sq = np.asarray(residual_sq)
        if sq.ndim == 2 and sq.dtype == np.float64:  # a batch: counted compiled, the same integers
            return count_below(np.ascontiguousarray(sq), float(threshold_sq))
        return np.sum(sq < threshold_sq, axis=-1, dtype=float)


@dataclass(frozen=True)
class TruncatedQuadratic:
    """MSAC (Torr & Zisserman 2000): minus the sum of ``min(e^2, T^2)``, normalised by T^2.

    Normalising makes the score read as "inliers minus their mean squared misfit", so it
    is comparable across gates and never below ``-N``.
    """

    name: str = "msac"
    saturates: bool = True

    def score(self, residual_sq: np.ndarray, threshold_sq: float) -> np.ndarray:
        return -np.sum(np.minimum(residual_sq, threshold_sq), axis=-1) / threshold_sq

