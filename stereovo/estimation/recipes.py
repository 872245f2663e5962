"""The core's own methods (``ransac``, ``msac``, ``probabilistic``) and the recipe parts all methods share.

:func:`base_components` is the plain loop for a given residual model and quality: the
sampler by what the caller gives (uniform, guided, PROSAC), the stopping rule, the sample
check, the local refit and the final refinement the options ask for. Named methods replace
roles of it; importing this module registers the three core methods.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import numpy as np

from stereovo.estimation.estimator_options import EstimatorOptions, chi2_quantile
from stereovo.estimation.local_optimization import ConsensusRefit
from stereovo.estimation.loop import RansacComponents
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.refinement import ReprojectionRefiner
from stereovo.estimation.registry import register_method
from stereovo.estimation.sample_check import RigidityCheck
from stereovo.estimation.samplers import ProsacSampler, UniformSampler, WeightedSampler
from stereovo.estimation.scoring import (
    InlierCount,
    MahalanobisResidual,
    PixelMahalanobisResidual,
    ReprojectionResidual,
    TruncatedQuadratic,
)
from stereovo.estimation.termination import AdaptiveTermination, FixedBudget


def default_sampler(problem: StereoProblem, priors: np.ndarray | None, order: np.ndarray | None):
    """Uniform, prior-weighted (guided) or PROSAC sampling, by what the caller supplied."""
    if order is not None:
        return ProsacSampler(order)
    if priors is not None:
        return WeightedSampler(priors)
    return UniformSampler(problem.n)


def default_termination(options: EstimatorOptions, sampler=None):
    """A fixed budget, or the adaptive bound with the ``sampler``'s all-inlier chance (prior-aware)."""
    if options.budget is not None:
        return FixedBudget(int(options.budget))
    return AdaptiveTermination(options.confidence, int(options.max_iterations), sampler=sampler)


def final_refiner(options: EstimatorOptions) -> ReprojectionRefiner | None:
    """The final step the options ask for.

    With ``refine``: the iterated two-image LM refinement (refine, re-select the inliers, repeat
    until they settle, at most ``refine_rounds`` rounds). Else, with ``least_squares_refit``: the
    papers' last step, one least-squares refit of the best model on its inliers (LM on their
    stereo reprojection error, as OpenCV's RANSAC refits on its inliers) and one re-selection of
    the inliers under the method's gate. Else None: the best hypothesis as it is.
    """
    if options.refine:
        return ReprojectionRefiner(iterations=options.refine_iterations, rounds=int(options.refine_rounds))
    if options.least_squares_refit:
        return ReprojectionRefiner(iterations=options.refine_iterations, rounds=1)
    return None


def sample_check(options: EstimatorOptions) -> RigidityCheck | None:
    """The rigidity check the options ask for (None without ``rigidity_gate_probability``)."""
    if options.rigidity_gate_probability is None:
        return None
    return RigidityCheck(chi2_quantile(options.rigidity_gate_probability, 1))


def base_components(
    problem: StereoProblem,
    options: EstimatorOptions,
    priors: np.ndarray | None,
    order: np.ndarray | None,
    residual_model,
    quality,
    threshold_sq: float,
) -> RansacComponents:
    """The plain loop with the given judge; named methods replace roles of this."""
    sampler = default_sampler(problem, priors, order)
    termination = default_termination(options, sampler)
    return RansacComponents(
        sampler=sampler,
        residual_model=residual_model,
        quality=quality,
        threshold_sq=threshold_sq,
        termination=termination,
        # the adaptive bound reads each new best's inlier mask for a guided sampler's q
        listeners=[termination] if isinstance(termination, AdaptiveTermination) else [],
        local_optimizer=ConsensusRefit() if options.local_refit else None,
        refiner=final_refiner(options),
        batch_size=int(options.batch_size),
        # An adaptive search may be over after a few hypotheses; a budget draws them all anyway.
        first_batch_size=int(options.first_batch_size) if options.budget is None else None,
        polish_iterations=int(options.polish_iterations),
        min_inliers=int(options.min_inliers),
        sample_check=sample_check(options),
    )


@register_method(
    "ransac",
    "minimal 3-point fits, inlier count under a stereo reprojection gate, exact (without replacement) stop",
    "Fischler & Bolles 1981",
)
def _build_ransac(problem, options, priors, order, extra) -> RansacComponents:
    return base_components(
        problem, options, priors, order, ReprojectionResidual(), InlierCount(), options.reprojection_threshold_sq
    )


@register_method(
    "msac",
    "minimal 3-point fits, truncated quadratic cost under a stereo reprojection gate",
    "Torr & Zisserman 2000",
)
def _build_msac(problem, options, priors, order, extra) -> RansacComponents:
    return base_components(
        problem, options, priors, order, ReprojectionResidual(), TruncatedQuadratic(), options.reprojection_threshold_sq
    )


@functools.lru_cache(maxsize=64)
def _pixel_gated_refiner(options: EstimatorOptions, dof: int = 4) -> ReprojectionRefiner | None:
    """``probabilistic``'s final refinement, which re-selects its inliers with the pixel gate.

    ``dof``: the whitened pixel residual's degrees of freedom, ``camera.measurement_dof`` (3 with
    one v per rectified match, 4 with independent vL and vR), which sets the gate's quantile.

    The 3-D gate misses about a tenth of the inliers, mostly far points (triangulation's skewed
    depth error), and those carry the rotation; the pixel gate keeps them. The local refit keeps
    the 3-D gate: with the pixel gate there too, frames with a moving object failed more often
    (eps 0.8 on the baseline grid: 75 instead of 85 % success).
    """
    refiner = final_refiner(options)
    if refiner is None:
        return None
    threshold = chi2_quantile(options.refine_gate_probability, int(dof))
    return dataclasses.replace(refiner, gate=(PixelMahalanobisResidual(threshold), threshold))


PROBABILISTIC_RECIPE: dict[str, Any] = {
    "polish_iterations": 2, "local_refit": True, "rigidity_gate_probability": 0.999, "refine": True,
}
"""``probabilistic``'s defaults: the project's tuned recipe, every enhancement on (each still an option)."""


@register_method(
    "probabilistic",
    "Mahalanobis-gated consensus with triangulation covariances, chi-square(3) gate; "
    "final inliers by a chi-square gate on the whitened pixel residuals (3 dof: one v per rectified match); "
    "the project's tuned recipe",
    "Brink et al.",
    defaults=PROBABILISTIC_RECIPE,
)
def _build_probabilistic(problem, options, priors, order, extra) -> RansacComponents:
    threshold = options.mahalanobis_threshold_sq
    components = base_components(
        problem, options, priors, order, MahalanobisResidual(threshold), InlierCount(), threshold
    )
    components.refiner = _pixel_gated_refiner(options, problem.camera.measurement_dof)
    return components
