"""MLESAC and Guided-MLESAC qualities (Torr & Zisserman 2000; Tordoff & Murray 2005): docs/algorithms.md, `mlesac`.

Torr & Zisserman 2000 score a hypothesis by the likelihood of its residuals
under a mixture of a Gaussian (inliers) and a uniform density (outliers),
with the mixing weight gamma fitted by EM per hypothesis. Tordoff & Murray
2005 (Guided-MLESAC) replace the global gamma by a prior ``gamma_i`` per
correspondence from its match score.

Units (our choice, documented): residuals are the Mahalanobis ones of
:class:`~stereovo.estimation.roles.scoring.MahalanobisResidual`,
``r_i = Y_i - (R X_i + t)`` in metres with covariance
``S_i = R S_X,i R^T + S_Y,i``, so the inlier density is
``p_in = (2 pi)^(-3/2) |S_i|^(-1/2) exp(-d_i^2 / 2)`` in m^-3. Outliers are
uniform in *measurement* space: a mismatched point lands anywhere in the
stereo measurement box ``(uL, v, uR)`` of volume
``v = width x height x (largest disparity)`` px^3, which the triangulation
carries into metric space with density ``1 / (v |det J_i|)`` m^-3,
``|det J_i| = Z_i^4 / (fx^2 fy b)`` (m^3 / px^3) the Jacobian of
``(uL, v, uR) -> (x, y, Z)`` at ``Y_i``. Both densities are then in m^-3, and
their ratio does not depend on depth: a bounding-box volume in m^3 instead
(also admissible) makes every near point, measured precisely, outweigh many
far ones, and MLESAC then prefers a near moving object to the static scene.
``|S_i|`` is taken at ``R = I`` (``|S_X,i + S_Y,i|``): the quality only sees
squared Mahalanobis distances, frame-to-frame rotations are a few degrees,
and the determinant only weighs each point against the outlier density.
Everything is kept in logs (``np.logaddexp``), so nothing under- or overflows.

One absurd row must not fail a frame (a usable match far off the image, e.g.
``(1e8, 1e8, 1e8 - 50, 1e8)`` in both frames): both densities stay finite and
bounded. The outlier box's disparity side is at most the image width and each
point's depth is taken within what such disparities allow; a summed covariance
whose smallest eigenvalue is lost to rounding (an enormous lateral position
makes it numerically singular) gets its eigenvalues floored at
``COVARIANCE_FLOOR`` times the largest before its determinant is taken; squared
distances that come back negative or NaN from such a covariance count as 0 and
infinity (an outlier).

This module also declares the options of ``mlesac`` and ``guided-mlesac`` and registers them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stereovo.estimation.estimator_options import MAX_COUNT, OptionReads
from stereovo.estimation.kernels.logaddexp import logaddexp_2d, mixture_logaddexp
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.recipes import base_components
from stereovo.estimation.registry import register_method
from stereovo.estimation.roles.scoring import MahalanobisResidual
from stereovo.options import Integer, Number

_GAMMA_CLIP = 1e-6  # keeps log(gamma) and log(1 - gamma) finite
COVARIANCE_FLOOR = 1e-12
"""Smallest eigenvalue of a summed covariance, relative to its largest, that its determinant uses:
float64 keeps about 16 digits of a 3x3 matrix, so a smaller eigenvalue is rounding, not measurement."""


def inlier_log_normaliser(problem: StereoProblem) -> np.ndarray:
    """``(N,)`` ``log((2 pi)^(-3/2) |S_X,i + S_Y,i|^(-1/2))`` in log m^-3 (finite for every row).

    A row without a finite covariance (no depth: the in-frame environment judges the whole frame)
    gets the normaliser of a unit determinant. Its residual is infinite under every motion, so its
    inlier density is 0 whatever the normaliser, and it counts as an outlier."""
    S = problem.cov_prev + problem.cov_curr
    finite = np.isfinite(S).all(axis=(1, 2))
    if finite.all():
        return _gaussian_log_normaliser(S)
    out = np.full(S.shape[0], -1.5 * np.log(2 * np.pi))
    if finite.any():
        out[finite] = _gaussian_log_normaliser(S[finite])
    return out


def _gaussian_log_normaliser(S: np.ndarray) -> np.ndarray:
    """:func:`inlier_log_normaliser` of finite covariances ``S (M, 3, 3)``."""
    sign, logdet = np.linalg.slogdet(S)
    eig = np.linalg.eigvalsh(S)  # ascending
    # Only numerically singular rows change: the others keep slogdet's value bit for bit.
    bad = (sign <= 0) | ~np.isfinite(logdet) | ~(eig[:, 0] > COVARIANCE_FLOOR * eig[:, 2])
    if np.any(bad):
        top = np.maximum(eig[bad, 2:], np.finfo(float).tiny)
        logdet = logdet.copy()
        logdet[bad] = np.sum(np.log(np.maximum(eig[bad], COVARIANCE_FLOOR * top)), axis=1)
    return -1.5 * np.log(2 * np.pi) - 0.5 * logdet


def outlier_log_density(problem: StereoProblem) -> np.ndarray:
    """``(N,)`` log density (log m^-3) of a uniform outlier in measurement space, mapped to metres at ``Y_i``.

    Bounded: the box's disparity side lies in [1 px, image width], and each depth in the range
    such disparities triangulate to, so one absurd row can widen the box at most to the image
    width and its own density stays within the range of real matches'.
    """
    cam = problem.camera
    disparity = cam.disparity(problem.curr)
    finite = disparity[np.isfinite(disparity)]
    largest = min(max(float(np.max(finite)) if finite.size else 1.0, 1.0), float(cam.width))
    log_volume = np.log(cam.width) + np.log(cam.height) + np.log(largest)
    focal_baseline = cam.fx * cam.baseline
    # a row without depth is an outlier under every motion (its inlier density is 0), so the depth its
    # outlier density is taken at only shifts every hypothesis' likelihood alike: the farthest allowed
    depth = np.clip(np.nan_to_num(problem.points_curr[:, 2], nan=np.inf), focal_baseline / cam.width,
                    focal_baseline / cam.min_disparity)
    log_det_jacobian = 4 * np.log(depth) - 2 * np.log(cam.fx) - np.log(cam.fy) - np.log(cam.baseline)
    return -log_volume - log_det_jacobian


def _finite_sq(residual_sq: np.ndarray) -> np.ndarray:
    """Squared distances made safe for the densities: NaN (a singular covariance) is an outlier
    (inf), a negative value (rounding in such a covariance's solve) is 0."""
    return np.maximum(np.nan_to_num(residual_sq, nan=np.inf), 0.0)


def log_add_exp(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.logaddexp(a, b)`` bit for bit, for ``(H, N)`` arrays after broadcasting, compiled
    (:func:`stereovo.estimation.kernels.logaddexp.logaddexp_2d`; other shapes: numpy's own), for
    Guided-MLESAC's per-point mixture: numpy's ``exp`` and ``log1p`` an entry cost the most there,
    and under most hypotheses most residuals lie so far outside the gate that the exp underflows,
    where the kernel skips both."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    shape = np.broadcast_shapes(a.shape, b.shape)
    if len(shape) != 2:
        return np.logaddexp(a, b)
    # the EM's arguments already have the full shape; others are expanded (a copy, not a view)
    a = a if a.shape == shape else np.broadcast_to(a, shape).copy()
    b = b if b.shape == shape else np.broadcast_to(b, shape).copy()
    return logaddexp_2d(a, b)


def mixture_log_likelihood(gamma: np.ndarray, log_p_in: np.ndarray, log_p_out: float | np.ndarray) -> np.ndarray:
    """``L (H,) = sum_i log(gamma p_in,i + (1 - gamma) p_out)`` for one global ``gamma`` per hypothesis.

    Args:
        gamma: ``(H,)`` mixing weights.
        log_p_in: ``(H, N)`` log inlier densities.
        log_p_out: scalar or ``(N,)`` log outlier density, same units.
    """
    g = np.clip(np.asarray(gamma, dtype=float), _GAMMA_CLIP, 1 - _GAMMA_CLIP)
    return np.sum(_mixture_terms(g, log_p_in, log_p_out, False), axis=-1)


def _mixture_terms(g: np.ndarray, log_p_in: np.ndarray, log_p_out, responsibilities: bool) -> np.ndarray:
    """``(H, N)`` ``logaddexp(log g + log p_in, log(1 - g) + log p_out)`` for ``g (H,)`` (clipped), or
    with ``responsibilities`` the log responsibilities ``log g + log p_in`` minus it: numpy's values
    bit for bit (the logarithms of ``g`` by numpy's own log, the rest in
    :func:`~stereovo.estimation.kernels.logaddexp.mixture_logaddexp`)."""
    log_p_in = np.atleast_2d(np.asarray(log_p_in, dtype=float))
    log_p_out = np.broadcast_to(np.asarray(log_p_out, dtype=float), log_p_in.shape[-1:]).copy()
    log_p_in = np.broadcast_to(log_p_in, (g.shape[0], log_p_in.shape[-1]))
    log_g, log_1mg = np.log(g), np.log1p(-g)
    return mixture_logaddexp(log_g, log_1mg, log_p_in, log_p_out, responsibilities)


def mlesac_em(
    log_p_in: np.ndarray,
    log_p_out: float | np.ndarray,
    iterations: int = 5,
    tolerance: float = 1e-4,
    gamma0: float = 0.5,
    return_history: bool = False,
):
    """Fit the inlier fraction gamma of each hypothesis by EM (vectorised over hypotheses).

    E-step ``z_i = gamma p_in,i / (gamma p_in,i + (1 - gamma) p_out)``, M-step ``gamma = mean z``;
    stop after ``iterations`` or once every ``|delta gamma| < tolerance``. EM never lowers L.

    Args:
        log_p_in: ``(H, N)`` log inlier densities of the residuals.
        log_p_out: scalar or ``(N,)`` log outlier density, same units.

    Returns:
        ``(gamma (H,), L (H,))``, plus the list of ``(gamma, L)`` per iteration (the start
        included) when ``return_history``.
    """
    log_p_in = np.atleast_2d(log_p_in)
    gamma = np.full(log_p_in.shape[0], float(gamma0))
    history = [(gamma.copy(), mixture_log_likelihood(gamma, log_p_in, log_p_out))] if return_history else None
    for _ in range(iterations):
        z = np.exp(_mixture_terms(np.clip(gamma, _GAMMA_CLIP, 1 - _GAMMA_CLIP), log_p_in, log_p_out, True))
        new = np.mean(z, axis=1)
        change = np.max(np.abs(new - gamma))
        gamma = new
        if return_history:
            history.append((gamma.copy(), mixture_log_likelihood(gamma, log_p_in, log_p_out)))
        if change < tolerance:
            break
    L = mixture_log_likelihood(gamma, log_p_in, log_p_out)
    return (gamma, L, history) if return_history else (gamma, L)


@dataclass(frozen=True)
class MlesacQuality:
    """MLESAC: the mixture log-likelihood at the EM gamma (higher is better).

    Built per problem: ``log_normaliser`` ``(N,)`` and ``log_p_out`` fix the units (module
    docstring). ``score`` takes squared Mahalanobis distances ``(H, N)``; the inlier gate
    is not used by the score (it still defines the inlier mask and the stopping bound).
    """

    log_normaliser: np.ndarray
    log_p_out: np.ndarray  # (N,)
    em_iterations: int = 5
    em_tolerance: float = 1e-4
    name: str = "mlesac"
    saturates: bool = False  # the mixture likelihood needs every residual exactly

    @classmethod
    def for_problem(cls, problem: StereoProblem, em_iterations: int = 5, em_tolerance: float = 1e-4) -> "MlesacQuality":
        return cls(inlier_log_normaliser(problem), outlier_log_density(problem), em_iterations, em_tolerance)

    def log_p_in(self, residual_sq: np.ndarray) -> np.ndarray:
        return self.log_normaliser - 0.5 * _finite_sq(residual_sq)

    def gamma(self, residual_sq: np.ndarray) -> np.ndarray:
        """The EM inlier fraction ``(H,)`` of each hypothesis."""
        return mlesac_em(self.log_p_in(residual_sq), self.log_p_out, self.em_iterations, self.em_tolerance)[0]

    def score(self, residual_sq: np.ndarray, threshold_sq: float) -> np.ndarray:
        return mlesac_em(self.log_p_in(residual_sq), self.log_p_out, self.em_iterations, self.em_tolerance)[1]


@dataclass(frozen=True)
class GuidedMlesacQuality:
    """Guided-MLESAC: the mixture log-likelihood with a fixed prior ``gamma_i`` per correspondence."""

    log_normaliser: np.ndarray
    log_p_out: np.ndarray  # (N,)
    gamma: np.ndarray  # (N,) in (0, 1)
    name: str = "guided-mlesac"
    saturates: bool = False

    @classmethod
    def for_problem(cls, problem: StereoProblem, gamma: np.ndarray) -> "GuidedMlesacQuality":
        g = np.clip(np.asarray(gamma, dtype=float), _GAMMA_CLIP, 1 - _GAMMA_CLIP)
        return cls(inlier_log_normaliser(problem), outlier_log_density(problem), g)

    def score(self, residual_sq: np.ndarray, threshold_sq: float) -> np.ndarray:
        log_p_in = self.log_normaliser - 0.5 * _finite_sq(residual_sq)
        return np.sum(log_add_exp(np.log(self.gamma) + log_p_in, np.log1p(-self.gamma) + self.log_p_out), axis=-1)


MLESAC_READS = OptionReads(judge="mahalanobis", refinement="plain", stop="adaptive")
"""Both MLESACs judge by the 3-D Mahalanobis gate and end with the plain refinement (no pixel gate)."""


@register_method(
    "mlesac",
    "mixture likelihood (Gaussian Mahalanobis inliers + uniform outliers), inlier fraction by EM per hypothesis",
    "Torr & Zisserman 2000",
    extra_options={
        "mlesac_em_iterations": Integer(low=1, high=MAX_COUNT, default=MlesacQuality.em_iterations),
        "mlesac_em_tolerance": Number(low=0.0, low_open=True, default=MlesacQuality.em_tolerance),
    },
    reads=MLESAC_READS,
)
def _build_mlesac(problem, options, priors, order, extra):
    quality = MlesacQuality.for_problem(
        problem, em_iterations=extra["mlesac_em_iterations"], em_tolerance=float(extra["mlesac_em_tolerance"])
    )
    threshold = options.mahalanobis_threshold_sq
    return base_components(problem, options, priors, order, MahalanobisResidual(threshold), quality, threshold)


@register_method(
    "guided-mlesac",
    "MLESAC with a prior inlier probability gamma_i per match (priors=, required), sampling by gamma_i",
    "Tordoff & Murray 2005",
    inputs="priors",
    reads=MLESAC_READS,
)
def _build_guided_mlesac(problem, options, priors, order, extra):
    if priors is None:
        raise ValueError(
            "method 'guided-mlesac' needs priors=: one inlier probability gamma_i per correspondence "
            "(e.g. calibrated match scores; clipped to (0, 1))"
        )
    quality = GuidedMlesacQuality.for_problem(problem, priors)
    threshold = options.mahalanobis_threshold_sq
    # P(i) proportional to the clipped gamma_i; the adaptive stop uses this sampler's all-inlier chance
    return base_components(problem, options, quality.gamma, None, MahalanobisResidual(threshold), quality, threshold)
