"""The core's own methods (``ransac``, ``msac``, ``probabilistic``), the recipe parts all methods
share, and the ``method+enhancement`` variants.

:func:`base_components` is the plain loop for a given residual model and quality: the
sampler by what the caller gives (uniform, guided, PROSAC), the stopping rule, the sample
check, the local refit and the final refinement the options ask for. Named methods
(:mod:`stereovo.estimation.methods`) replace roles of it; importing this module registers the
three core methods. :func:`register_enhanced_variants` registers :data:`ENHANCED_VARIANTS` once
their bases are registered (the methods package calls it last).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import numpy as np

from stereovo.estimation.compiled_search import compiled_batch_search
from stereovo.estimation.estimator_options import EstimatorOptions, OptionReads, chi2_quantile
from stereovo.estimation.loop import RansacComponents
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.registry import register_method, register_variant
from stereovo.estimation.roles.local_optimization import ConsensusRefit
from stereovo.estimation.roles.refinement import ReprojectionRefiner
from stereovo.estimation.roles.sample_check import RigidityCheck
from stereovo.estimation.roles.samplers import ProsacSampler, UniformSampler, WeightedSampler
from stereovo.estimation.roles.scoring import (
    InlierCount,
    MahalanobisResidual,
    PixelMahalanobisResidual,
    ReprojectionResidual,
    TruncatedQuadratic,
)
from stereovo.estimation.roles.termination import AdaptiveTermination, FixedBudget


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
        local_optimizer=ConsensusRefit() if options.local_refit else None,
        refiner=final_refiner(options),
        batch_size=int(options.batch_size),
        # An adaptive search may be over after a few hypotheses; a budget draws them all anyway.
        first_batch_size=int(options.first_batch_size) if options.budget is None else None,
        polish_iterations=int(options.polish_iterations),
        runner_up_fraction=options.runner_up_refit,
        min_inliers=int(options.min_inliers),
        fail_at_cap=bool(options.fail_at_cap),
        sample_check=sample_check(options),
    )


def reprojection_judge(options: EstimatorOptions, quality) -> tuple[ReprojectionResidual, Any, float]:
    """``(residual_model, quality, threshold_sq)`` judging by the stereo reprojection gate
    (``options.reprojection_threshold_sq``) with ``quality``: the judge of most classical methods."""
    return ReprojectionResidual(options.reprojection_threshold_sq), quality, options.reprojection_threshold_sq


REPROJECTION_READS = OptionReads(judge="reprojection", refinement="plain", stop="adaptive")
"""What a recipe of :func:`base_components` judged by :func:`reprojection_judge` reads: no
``gate_probability`` nor ``refine_gate_probability``; under a fixed budget nothing of the adaptive stop."""

PROBABILISTIC_READS = OptionReads(judge="mahalanobis", refinement="pixel-gated", stop="adaptive")
"""What ``probabilistic``'s recipe and those built on its judge read: the 3-D gate's ``gate_probability``,
the pixel gate's ``refine_gate_probability`` when a final refinement runs; under a fixed budget nothing of
the adaptive stop."""


def _reprojection_recipe(quality):
    """The plain loop judged by the stereo reprojection gate with ``quality`` (a class)."""

    def build(problem, options, priors, order, extra) -> RansacComponents:
        return base_components(problem, options, priors, order, *reprojection_judge(options, quality()))

    return build


register_method(
    "ransac",
    "minimal 3-point fits, inlier count under a stereo reprojection gate, exact (without replacement) stop",
    "Fischler & Bolles 1981",
    reads=REPROJECTION_READS,
)(_reprojection_recipe(InlierCount))
register_method(
    "msac", "minimal 3-point fits, truncated quadratic cost under a stereo reprojection gate", "Torr & Zisserman 2000",
    reads=REPROJECTION_READS,
)(_reprojection_recipe(TruncatedQuadratic))


@functools.lru_cache(maxsize=64)
def _pixel_gated_refiner(options: EstimatorOptions, dof: int = 4) -> ReprojectionRefiner | None:
    """``probabilistic``'s final refinement, which re-selects its inliers with the pixel gate.

    ``dof``: the whitened pixel residual's degrees of freedom, ``camera.measurement_dof`` (3 with
    one v per rectified match, 4 with independent vL and vR), which sets the gate's quantile.

    The 3-D gate misses about a tenth of the inliers, mostly far points (triangulation's skewed
    depth error), and those carry the rotation; the pixel gate keeps them. The local refit keeps
    the 3-D gate: with the pixel gate there too, frames with a moving object failed more often
    (docs/algorithms.md, "Measurements behind the code").
    """
    refiner = final_refiner(options)
    if refiner is None:
        return None
    threshold = chi2_quantile(options.refine_gate_probability, int(dof))
    return dataclasses.replace(refiner, gate=(PixelMahalanobisResidual(threshold), threshold))


PROBABILISTIC_RECIPE: dict[str, Any] = {
    "polish_iterations": 2, "local_refit": True, "runner_up_refit": 0.5, "rigidity_gate_probability": 0.999,
    "refine": True,
}
"""``probabilistic``'s defaults: the project's tuned recipe, every enhancement on (each still an option)."""


@register_method(
    "probabilistic",
    "Mahalanobis-gated consensus with triangulation covariances, chi-square(3) gate; "
    "final inliers by a chi-square gate on the whitened pixel residuals (3 dof: one v per rectified match); "
    "the project's tuned recipe",
    "Brink et al.",
    defaults=PROBABILISTIC_RECIPE,
    reads=PROBABILISTIC_READS,
)
def build_probabilistic(problem, options, priors, order, extra) -> RansacComponents:
    threshold = options.mahalanobis_threshold_sq
    components = base_components(
        problem, options, priors, order, MahalanobisResidual(threshold), InlierCount(), threshold
    )
    components.refiner = _pixel_gated_refiner(options, problem.camera.measurement_dof)
    # uniform draws run their batches compiled (the loop's steps, bit for bit); other samplers decline
    components.search_runner = compiled_batch_search
    return components


VARIANT_ENHANCEMENTS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("ransac", ("polish",)),
    ("ransac", ("refit",)),
    ("ransac", ("rigidity",)),
    ("ransac", ("lm",)),
    ("ransac", ("polish", "refit", "lm")),  # what ``ransac`` ran before it became the paper's recipe
    ("msac", ("polish", "lm")),  # the environment's recipe
    ("lo-ransac", ("polish", "lm")),
    ("inlier-detection", ("lm",)),
)
"""``(base method, enhancements)`` of the ``method+enhancement...`` variants: the baseline report's
"+ enhancement" rows beside the papers' recipes, so that each addition's gain is measured on the same frames."""

ENHANCED_VARIANTS: tuple[str, ...] = tuple("+".join((base, *enhancements)) for base, enhancements in VARIANT_ENHANCEMENTS)
"""The variants' registered names (:func:`~stereovo.estimation.registry.register_variant`)."""


def register_enhanced_variants() -> tuple[str, ...]:
    """Register :data:`VARIANT_ENHANCEMENTS` (their bases must be registered); returns their names."""
    return tuple(register_variant(base, *enhancements) for base, enhancements in VARIANT_ENHANCEMENTS)
