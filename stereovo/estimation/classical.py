"""The classical RANSAC family as short recipes over the shared loop (docs/algorithms.md, "Methods").

Each method below is a composition of core roles registered by name; the
role classes live in their own modules (:mod:`.mlesac`, :mod:`.prosac`,
:mod:`.tdd`, :mod:`.sprt`, :mod:`.lo`, :mod:`.preemptive`, :mod:`.clique`).
Unless a method says otherwise it judges hypotheses like ``ransac`` (stereo
reprojection gate, ``6 * noise_sigma`` px), accepts ``priors=`` (guided
sampling) or ``order=`` (PROSAC sampling) through :func:`base_components`, and
honours the shared options (``budget`` replaces the method's stopping rule by
a fixed hypothesis count; its verifier and sampler stay).

Method-specific options (keyword arguments of ``estimate_motion``):

- ``mlesac``: ``mlesac_em_iterations`` (5), ``mlesac_em_tolerance`` (1e-4).
- ``guided-mlesac``: none; ``priors=`` is required (the gamma_i).
- ``prosac``: ``prosac_beta`` (0.05), ``prosac_psi`` (0.05), ``prosac_min_n`` (20),
  ``prosac_t_n`` (200000); ``order=`` is required.
- ``r-ransac``: ``tdd_d`` (1).
- ``waldsac``: ``sprt_t_m`` (500), ``sprt_epsilon0`` (0.1), ``sprt_delta0`` (0.01), ``sprt_chunk`` (16).
- ``lo-ransac``: ``lo_inner_iterations`` (10), ``lo_sample_cap`` (12),
  ``lo_threshold_multiplier`` (3), ``lo_steps`` (4).
- ``preemptive``: ``preemptive_hypotheses`` (M = 500, or ``budget``), ``preemptive_block`` (B = 100).
- ``inlier-detection``: ``clique_c`` (3), ``clique_exact_max`` (60), ``clique_time_limit_s`` (0.5),
  ``clique_graph_max`` (2000: above this N the graph is built on a random subset of that many).
- ``usac``: the ``sprt_*``, ``lo_*`` and ``prosac_*`` options.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stereovo.estimation.clique import GRAPH_MAX, detect_inliers
from stereovo.estimation.lo import InnerRansacLO
from stereovo.estimation.loop import RansacComponents
from stereovo.estimation.methods import (
    MAX_COUNT,
    EstimatorOptions,
    base_components,
    declare_options,
    declared_option,
    final_refiner,
    register_estimator,
    register_method,
    register_variant,
)
from stereovo.estimation.mlesac import GuidedMlesacQuality, MlesacQuality
from stereovo.estimation.preemptive import PreemptiveVerification
from stereovo.estimation.prosac import ProsacTermination
from stereovo.estimation.samplers import SAMPLE_SIZE, ProsacSampler
from stereovo.estimation.scoring import InlierCount, MahalanobisResidual, ReprojectionResidual, TruncatedQuadratic
from stereovo.estimation.sprt import SprtTermination, SprtVerification
from stereovo.estimation.tdd import TddTermination, TddVerification
from stereovo.estimation.termination import FixedBudget
from stereovo.options import Integer, Number

# ----------------------------------------------------------------------------- option parsing


declare_options({
    "mlesac_em_iterations": Integer(low=1, high=MAX_COUNT),
    "mlesac_em_tolerance": Number(low=0.0, low_open=True),
    "prosac_beta": Number(low=0.0, high=1.0, low_open=True, high_open=True),
    "prosac_psi": Number(low=0.0, high=1.0, low_open=True, high_open=True),
    "prosac_min_n": Integer(low=4, high=MAX_COUNT),
    "prosac_t_n": Number(low=1.0, high=1e15),
    "tdd_d": Integer(low=1, high=MAX_COUNT),
    "sprt_t_m": Number(low=0.0, high=1e15, low_open=True),
    "sprt_epsilon0": Number(low=0.0, high=1.0, low_open=True, high_open=True),
    "sprt_delta0": Number(low=0.0, high=1.0, low_open=True, high_open=True),
    "sprt_chunk": Integer(low=1, high=MAX_COUNT),
    "lo_inner_iterations": Integer(low=1, high=MAX_COUNT),
    "lo_sample_cap": Integer(low=4, high=MAX_COUNT),
    "lo_threshold_multiplier": Number(low=1.0, high=1e6),
    "lo_steps": Integer(low=1, high=MAX_COUNT),
    "preemptive_hypotheses": Integer(low=1, high=MAX_COUNT),
    "preemptive_block": Integer(low=1, high=MAX_COUNT),
    "clique_c": Number(low=0.0, high=1e6, low_open=True),
    "clique_exact_max": Integer(low=0, high=MAX_COUNT),
    "clique_time_limit_s": Number(low=0.0, high=1e6, low_open=True, unit="s"),
    "clique_graph_max": Integer(low=SAMPLE_SIZE, high=20_000),  # 20,000: a 400 MB graph at most
})
"""The method options' declarations (:mod:`stereovo.options`), checked by ``estimate_motion`` (and the
environment) before a method runs, whether or not the recipe uses the option on that call (``usac``
checks its ``prosac_*`` options without an order, as ``prosac`` does)."""


def _number(extra: dict, name: str, default, integer: bool = False, low=None, high=None, low_open: bool = False):
    """A method option from ``extra`` (or its ``default``), as int or float; ValueError names it.

    A declared option (above) is held to its declaration, the one rule ``estimate_motion`` has
    already applied; the bounds given here are the rule only for an option without one.
    """
    value = extra.get(name, default)
    rule = declared_option(name)
    if rule is None:
        rule = (Integer(low=low) if integer else
                Number(low=None if low is None else float(low), high=None if high is None else float(high),
                       low_open=low_open, high_open=high is not None))
    value = rule.check(name, value)
    return int(value) if integer else float(value)


def _reprojection_judge(options: EstimatorOptions, quality):
    return ReprojectionResidual(options.reprojection_threshold_sq), quality, options.reprojection_threshold_sq


def _prosac_termination(sampler: ProsacSampler, options: EstimatorOptions, extra: dict) -> ProsacTermination:
    return ProsacTermination(
        sampler,
        options.confidence,
        int(options.max_iterations),
        beta=_number(extra, "prosac_beta", 0.05, low=0, high=1, low_open=True),
        psi=_number(extra, "prosac_psi", 0.05, low=0, high=1, low_open=True),
        min_n=_number(extra, "prosac_min_n", 20, integer=True, low=4),
    )


def _sprt_verifier(problem, extra: dict) -> SprtVerification:
    return SprtVerification(
        problem.n,
        t_m=_number(extra, "sprt_t_m", 500.0, low=0, low_open=True),
        epsilon0=_number(extra, "sprt_epsilon0", 0.1, low=0, high=1, low_open=True),
        delta0=_number(extra, "sprt_delta0", 0.01, low=0, high=1, low_open=True),
        chunk=_number(extra, "sprt_chunk", 16, integer=True, low=1),
    )


def _inner_ransac_lo(extra: dict) -> InnerRansacLO:
    return InnerRansacLO(
        inner_iterations=_number(extra, "lo_inner_iterations", 10, integer=True, low=1),
        sample_cap=_number(extra, "lo_sample_cap", 12, integer=True, low=4),
        threshold_multiplier=_number(extra, "lo_threshold_multiplier", 3.0, low=1),
        steps=_number(extra, "lo_steps", 4, integer=True, low=1),
    )


@dataclass
class EarliestTermination:
    """Stop as soon as any of several rules allows it (USAC: SPRT's bound and PROSAC's)."""

    rules: tuple

    @property
    def max_iterations(self) -> int:
        return min(rule.max_iterations for rule in self.rules)

    def required(self, n_inliers: int, n: int) -> int:
        return min(rule.required(n_inliers, n) for rule in self.rules)

    def counters(self) -> dict[str, int | float]:
        """The rules' own counters, merged."""
        merged: dict[str, int | float] = {}
        for rule in self.rules:
            if callable(getattr(rule, "counters", None)):
                merged.update(rule.counters())
        return merged


_PROSAC_OPTIONS = ("prosac_beta", "prosac_psi", "prosac_min_n", "prosac_t_n")
_SPRT_OPTIONS = ("sprt_t_m", "sprt_epsilon0", "sprt_delta0", "sprt_chunk")
_LO_OPTIONS = ("lo_inner_iterations", "lo_sample_cap", "lo_threshold_multiplier", "lo_steps")

# ----------------------------------------------------------------------------- recipes


@register_method(
    "mlesac",
    "mixture likelihood (Gaussian Mahalanobis inliers + uniform outliers), inlier fraction by EM per hypothesis",
    "Torr & Zisserman 2000",
    extra_options=("mlesac_em_iterations", "mlesac_em_tolerance"),
)
def _build_mlesac(problem, options, priors, order, extra) -> RansacComponents:
    quality = MlesacQuality.for_problem(
        problem,
        em_iterations=_number(extra, "mlesac_em_iterations", 5, integer=True, low=1),
        em_tolerance=_number(extra, "mlesac_em_tolerance", 1e-4, low=0, low_open=True),
    )
    threshold = options.mahalanobis_threshold_sq
    return base_components(problem, options, priors, order, MahalanobisResidual(threshold), quality, threshold)


@register_method(
    "guided-mlesac",
    "MLESAC with a prior inlier probability gamma_i per match (priors=, required), sampling by gamma_i",
    "Tordoff & Murray 2005",
    inputs="priors",
)
def _build_guided_mlesac(problem, options, priors, order, extra) -> RansacComponents:
    if priors is None:
        raise ValueError(
            "method 'guided-mlesac' needs priors=: one inlier probability gamma_i per correspondence "
            "(e.g. calibrated match scores; clipped to (0, 1))"
        )
    quality = GuidedMlesacQuality.for_problem(problem, priors)
    threshold = options.mahalanobis_threshold_sq
    # P(i) proportional to the clipped gamma_i; the adaptive stop uses this sampler's all-inlier chance
    components = base_components(problem, options, quality.gamma, None, MahalanobisResidual(threshold), quality, threshold)
    return components


@register_method(
    "prosac",
    "progressive sampling from the top of order= (required), PROSAC's non-randomness and maximality stop",
    "Chum & Matas 2005",
    extra_options=_PROSAC_OPTIONS,
    inputs="order",
)
def _build_prosac(problem, options, priors, order, extra) -> RansacComponents:
    if order is None:
        raise ValueError("method 'prosac' needs order=: a permutation of range(N), best correspondence first")
    components = base_components(problem, options, None, None, *_reprojection_judge(options, InlierCount()))
    sampler = ProsacSampler(order, t_n=_number(extra, "prosac_t_n", 200_000, low=1))
    stop = _prosac_termination(sampler, options, extra)
    components.sampler = sampler
    components.listeners.append(stop)  # lowers sampler.n_max to n* even under a fixed budget
    if options.budget is None:
        components.termination = stop
    return components


@register_method(
    "r-ransac",
    "randomized RANSAC: T(d,d) pre-test on d random points before full scoring, bound stretched by 1/alpha",
    "Matas & Chum 2002",
    extra_options=("tdd_d",),
)
def _build_r_ransac(problem, options, priors, order, extra) -> RansacComponents:
    d = _number(extra, "tdd_d", 1, integer=True, low=1)
    components = base_components(problem, options, priors, order, *_reprojection_judge(options, InlierCount()))
    verifier = TddVerification(d)
    components.verifier = verifier
    components.listeners.append(verifier)  # the best model's inliers decide which hypotheses are good
    if options.budget is None:
        stop = TddTermination(options.confidence, int(options.max_iterations), d, verifier, components.sampler)
        _replace_termination(components, stop)
    return components


def _replace_termination(components: RansacComponents, stop) -> None:
    """Make ``stop`` the recipe's termination, also in place of the old one among the listeners
    (an adaptive bound listens for the sampler's all-inlier chance)."""
    listeners = [listener for listener in components.listeners if listener is not components.termination]
    components.termination = stop
    components.listeners = listeners + ([stop] if hasattr(stop, "on_new_best") else [])


@register_method(
    "waldsac",
    "randomized RANSAC with the SPRT: early rejection, adaptive epsilon/delta, SPRT-aware stopping",
    "Matas & Chum 2005; Chum & Matas 2008",
    extra_options=_SPRT_OPTIONS,
)
def _build_waldsac(problem, options, priors, order, extra) -> RansacComponents:
    components = base_components(problem, options, priors, order, *_reprojection_judge(options, InlierCount()))
    verifier = _sprt_verifier(problem, extra)
    components.verifier = verifier
    components.listeners.append(verifier)
    if options.budget is None:
        _replace_termination(
            components, SprtTermination(verifier, options.confidence, int(options.max_iterations), components.sampler)
        )
    return components


@register_method(
    "lo-ransac",
    "MSAC with LO+ on every new best: inner RANSAC on non-minimal samples, shrinking-gate least squares",
    "Chum, Matas & Kittler 2003; Lebeda, Matas & Chum 2012",
    extra_options=_LO_OPTIONS,
)
def _build_lo_ransac(problem, options, priors, order, extra) -> RansacComponents:
    components = base_components(problem, options, priors, order, *_reprojection_judge(options, TruncatedQuadratic()))
    components.local_optimizer = _inner_ransac_lo(extra)  # replaces the light consensus refit
    return components


@register_method(
    "preemptive",
    "fixed set of M hypotheses scored breadth-first, halving the survivors every B observations",
    "Nister 2003",
    extra_options=("preemptive_hypotheses", "preemptive_block"),
)
def _build_preemptive(problem, options, priors, order, extra) -> RansacComponents:
    m = _number(extra, "preemptive_hypotheses", 500 if options.budget is None else options.budget, integer=True, low=1)
    if options.budget is not None and "preemptive_hypotheses" in extra and m != options.budget:
        raise ValueError(f"preemptive: budget={options.budget} and preemptive_hypotheses={m} disagree; give one")
    block = _number(extra, "preemptive_block", 100, integer=True, low=1)
    components = base_components(problem, options, priors, order, *_reprojection_judge(options, TruncatedQuadratic()))
    components.verifier = PreemptiveVerification(m, block)
    components.termination = FixedBudget(m)
    components.batch_size = m  # the whole hypothesis set reaches the verifier at once
    components.first_batch_size = None
    return components


@register_method(
    "usac",
    "USAC-like: PROSAC sampling if order= (else uniform/guided), SPRT verification, LO+, SPRT/PROSAC stop",
    "Raguram et al. 2013",
    extra_options=_SPRT_OPTIONS + _LO_OPTIONS + _PROSAC_OPTIONS,
)
def _build_usac(problem, options, priors, order, extra) -> RansacComponents:
    components = base_components(problem, options, priors, None, *_reprojection_judge(options, TruncatedQuadratic()))
    verifier = _sprt_verifier(problem, extra)
    components.verifier = verifier
    components.local_optimizer = _inner_ransac_lo(extra)
    components.listeners.append(verifier)
    rules = []
    if options.budget is None:
        sprt_stop = SprtTermination(verifier, options.confidence, int(options.max_iterations), components.sampler)
        components.listeners.append(sprt_stop)
        rules.append(sprt_stop)
    if order is not None:
        sampler = ProsacSampler(order, t_n=_number(extra, "prosac_t_n", 200_000, low=1))
        prosac_stop = _prosac_termination(sampler, options, extra)
        components.sampler = sampler
        components.listeners.append(prosac_stop)
        rules.append(prosac_stop)
    if options.budget is None:
        stop = EarliestTermination(tuple(rules)) if len(rules) > 1 else rules[0]
        components.listeners = [listener for listener in components.listeners if listener is not components.termination]
        components.termination = stop  # its rules listen already
    return components


@register_estimator(
    "inlier-detection",
    "maximum clique of rigid-distance-consistent matches (depth-aware), fit on it, reprojection re-gating",
    "Hirschmueller et al. 2002; Howard 2008",
    extra_options=("clique_c", "clique_exact_max", "clique_time_limit_s", "clique_graph_max"),
)
def _run_inlier_detection(problem, options, priors, order, extra, rng):
    if priors is not None or order is not None:
        raise ValueError(
            "method 'inlier-detection' does not sample hypotheses: priors= and order= have no role in it; pass neither"
        )
    return detect_inliers(
        problem,
        options.reprojection_threshold_sq,
        min_inliers=int(options.min_inliers),
        # Howard's own last step is the reprojection fit on the clique; the LM refinement is an enhancement
        refiner=final_refiner(options) if options.refine else None,
        c=_number(extra, "clique_c", 3.0, low=0, low_open=True),
        exact_max=_number(extra, "clique_exact_max", 60, integer=True, low=0),
        time_limit_s=_number(extra, "clique_time_limit_s", 0.5, low=0, low_open=True),
        rng=rng,
        graph_max=_number(extra, "clique_graph_max", GRAPH_MAX, integer=True, low=SAMPLE_SIZE),
        gate_sq=options.mahalanobis_threshold_sq,
        confidence=options.confidence,
    )


# ----------------------------------------------------------------------------- "+ enhancement" variants

ENHANCED_VARIANTS: tuple[str, ...] = tuple(
    register_variant(base, *enhancements)
    for base, enhancements in (
        ("ransac", ("polish",)),
        ("ransac", ("refit",)),
        ("ransac", ("rigidity",)),
        ("ransac", ("lm",)),
        ("ransac", ("polish", "refit", "lm")),  # what ``ransac`` ran before it became the paper's recipe
        ("msac", ("polish", "lm")),  # the environment's recipe
        ("lo-ransac", ("polish", "lm")),
        ("inlier-detection", ("lm",)),
    )
)
"""The registered ``method+enhancement...`` variants (:func:`~stereovo.estimation.methods.register_variant`):
the baseline report's "+ enhancement" rows beside the papers' recipes, so that each addition's gain is
measured on the same frames."""
