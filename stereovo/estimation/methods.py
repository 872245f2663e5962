"""Named estimators and the public entry point :func:`estimate_motion`.

A method is a short recipe: it picks a residual model, a quality, a verifier,
a local optimiser and a termination rule, and the shared loop runs it. New
methods register themselves with :func:`register_method`; the classical
family does so in :mod:`stereovo.estimation.classical`.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.options import Boolean, Integer, Number, Option, check_options
from stereovo.estimation.local_optimization import ConsensusRefit
from stereovo.estimation.loop import RansacComponents, RansacReport, run_ransac
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.refinement import ReprojectionRefiner, pose_covariance
from stereovo.estimation.sample_check import RigidityCheck
from stereovo.estimation.samplers import (
    SAMPLE_SIZE,
    ProsacSampler,
    UniformSampler,
    WeightedSampler,
    validate_order,
    validate_priors,
)
from stereovo.estimation.scoring import (
    InlierCount,
    MahalanobisResidual,
    PixelMahalanobisResidual,
    ReprojectionResidual,
    TruncatedQuadratic,
)
from stereovo.estimation.termination import AdaptiveTermination, FixedBudget
from scipy.stats import chi2


MAX_COUNT = 10**9
"""Upper bound of every hypothesis or iteration count option (a cap that keeps counts in int64 arithmetic)."""

NOISE_SIGMA_RANGE_PX = (1e-3, 1e3)
"""Accepted ``noise_sigma`` (px): a thousandth of a pixel (far below any real sensor, whose gates would
fall under the float64 resolution of pixel coordinates near 1e-12 px) to a thousand pixels (noise as
large as the image, beyond which the gates square into overflow)."""

ESTIMATOR_OPTION_RULES: dict[str, Option] = {
    "noise_sigma": Number(low=NOISE_SIGMA_RANGE_PX[0], high=NOISE_SIGMA_RANGE_PX[1], unit="px"),
    "confidence": Number(low=0.0, high=1.0, low_open=True, high_open=True),
    "max_iterations": Integer(low=1, high=MAX_COUNT),
    "budget": Integer(low=1, high=MAX_COUNT, allow_none=True),
    "batch_size": Integer(low=1, high=MAX_COUNT),
    "first_batch_size": Integer(low=1, high=MAX_COUNT),
    "threshold_px": Number(low=0.0, high=1e4, low_open=True, unit="px", allow_none=True),
    "gate_probability": Number(low=0.0, high=1.0, low_open=True, high_open=True),
    "refine_gate_probability": Number(low=0.0, high=1.0, low_open=True, high_open=True),
    "rigidity_gate_probability": Number(low=0.0, high=1.0, low_open=True, high_open=True, allow_none=True),
    "polish_iterations": Integer(low=0, high=1000),
    "refine": Boolean(),
    "refine_iterations": Integer(low=0, high=1000),
    "refine_rounds": Integer(low=1, high=1000),
    "local_refit": Boolean(),
    "least_squares_refit": Boolean(),
    "min_inliers": Integer(low=SAMPLE_SIZE, high=MAX_COUNT),
}
"""The declaration of every :class:`EstimatorOptions` field (:mod:`stereovo.options`), by name."""


@dataclass(frozen=True)
class EstimatorOptions:
    """Options shared by every method, validated on construction (COLMAP's ``Check()`` habit)
    against :data:`ESTIMATOR_OPTION_RULES`: counts are integers (not bools, not floats), switches are
    bools, numbers are finite and in range; an error names the option and the value.

    Attributes:
        noise_sigma: pixel noise standard deviation of the measurements (px), in [1e-3, 1e3]
            (:data:`NOISE_SIGMA_RANGE_PX`).
        confidence: probability of drawing at least one all-inlier sample (adaptive stop).
        max_iterations: hard cap on hypotheses drawn.
        budget: if set, draw exactly this many hypotheses (fixed budget) instead of stopping adaptively.
        batch_size: hypotheses fitted and scored per vectorised batch under a fixed ``budget``; the
            largest batch of an adaptive search.
        first_batch_size: the first batch of an adaptive search (no ``budget``), after which each
            batch doubles up to ``batch_size`` (16, 32, 64, 128, 128, ...): small first because at low
            contamination the stopping bound falls below a batch at once, large later because the
            bookkeeping between batches costs as much as several hypotheses.
        threshold_px: reprojection inlier gate (px); None means ``6 * noise_sigma`` (the k-1 point
            carries its own triangulation noise into frame k, so residuals exceed the pixel noise).
        gate_probability: chi-square(3) quantile of the Mahalanobis inlier gate.
        refine_gate_probability: chi-square quantile (3 dof with one v per match, 4 with independent
            vL and vR: ``camera.measurement_dof``) of the pixel Mahalanobis gate with which
            ``probabilistic`` re-selects inliers during its final refinement.
        rigidity_gate_probability: chi-square(1) quantile of the rigidity check (an enhancement,
            ``probabilistic``'s by default), which drops a minimal sample before fitting if a
            pairwise distance changes between the frames by more than its triangulation noise
            allows; None (the default) turns the check off.
        polish_iterations: Gauss-Newton steps on each minimal sample's reprojection error (an
            enhancement; 0, the default, keeps the paper's closed-form minimal fit).
        refine: end with the iterated two-image Levenberg-Marquardt refinement: refine on the
            inliers, re-select them, repeat until they settle (at most ``refine_rounds`` rounds; an
            enhancement, off by default).
        refine_iterations: LM iterations per refinement round.
        refine_rounds: at most this many refine / re-select-inliers rounds.
        local_refit: refit each new best on its consensus (a light local optimisation; an
            enhancement, off by default).
        least_squares_refit: without ``refine``, end as Fischler & Bolles do: refit the best model
            by least squares on its inliers (``refine_iterations`` LM steps on their stereo
            reprojection error, one round) and re-select the inliers once under the method's gate;
            False keeps the best hypothesis as it is.
        min_inliers: fewer inliers in the final model is reported as "no consensus".

    The defaults are the papers' recipes. Each registered method may declare its own defaults
    (:attr:`MethodSpec.defaults`, applied by :func:`estimate_motion` unless the caller gives the
    option): ``probabilistic`` declares its tuned recipe, and the ``+ enhancement`` variants
    (``ransac+polish``, ``ransac+lm``, ...) switch on the enhancements their names list
    (:data:`ENHANCEMENTS`).
    """

    noise_sigma: float = 0.5
    confidence: float = 0.99
    max_iterations: int = 10_000
    budget: int | None = None
    batch_size: int = 128
    first_batch_size: int = 16
    threshold_px: float | None = None
    gate_probability: float = 0.95
    refine_gate_probability: float = 0.99
    rigidity_gate_probability: float | None = None
    polish_iterations: int = 0
    refine: bool = False
    refine_iterations: int = 6
    refine_rounds: int = 3
    local_refit: bool = False
    least_squares_refit: bool = True
    min_inliers: int = 6

    def __post_init__(self) -> None:
        # One contract (stereovo.options): integers only, bools only, finite numbers in range;
        # values are normalised to plain Python types, never changed numerically.
        for name, rule in ESTIMATOR_OPTION_RULES.items():
            object.__setattr__(self, name, rule.check(name, getattr(self, name)))

    @property
    def reprojection_threshold_sq(self) -> float:
        px = 6.0 * self.noise_sigma if self.threshold_px is None else self.threshold_px
        return px * px

    @property
    def mahalanobis_threshold_sq(self) -> float:
        return _chi2_quantile(self.gate_probability, 3)

    @property
    def pixel_mahalanobis_threshold_sq(self) -> float:
        """The pixel gate for independent vL and vR (4 dof); ``probabilistic`` takes the dof of its
        camera's measurement model (``camera.measurement_dof``)."""
        return _chi2_quantile(self.refine_gate_probability, 4)


@functools.lru_cache(maxsize=64)
def _chi2_quantile(probability: float, dof: int) -> float:
    # scipy's ppf costs ~0.2 ms a call, a noticeable share of an easy frame's estimate
    return float(chi2.ppf(probability, dof))


MethodBuilder = Callable[[StereoProblem, EstimatorOptions, np.ndarray | None, np.ndarray | None, dict], RansacComponents]
# A method that is not a sampling loop (e.g. inlier detection by maximum clique) estimates directly:
# ``run(problem, options, priors, order, extra, rng) -> RansacReport``.
MethodRunner = Callable[
    [StereoProblem, EstimatorOptions, np.ndarray | None, np.ndarray | None, dict, np.random.Generator], RansacReport
]


@dataclass(frozen=True)
class MethodSpec:
    """A registered estimator: its recipe (or direct runner), a one-line description and its paper.

    Exactly one of ``build`` (a :class:`RansacComponents` recipe for the shared loop) and
    ``runner`` (a direct estimator returning the loop's :class:`RansacReport`) is set.
    """

    name: str
    description: str
    reference: str
    build: MethodBuilder | None
    extra_options: tuple[str, ...] = ()  # method-specific keyword options besides EstimatorOptions
    runner: MethodRunner | None = None
    # Declarations (stereovo.options) of the extra options that have one; a given value is checked
    # before the method runs, so that validity never depends on the frame (nor on a probe frame).
    option_rules: Mapping[str, Option] = dataclasses.field(default_factory=dict)
    # The method's own defaults for EstimatorOptions fields (e.g. probabilistic's tuned recipe, a
    # variant's enhancements): plain values, applied unless the caller gives the option.
    defaults: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    inputs: str = "any"  # what the sampler takes: "any" (priors=, order= or neither), "priors", "order", "none"

    def check_options(self, extra: Mapping[str, Any]) -> dict[str, Any]:
        """The given method options, validated against :attr:`option_rules` and normalised.

        Raises:
            ValueError: an option that is not the method's, or a value its declaration refuses.
        """
        unknown = set(extra) - set(self.extra_options)
        if unknown:
            allowed = sorted(_SHARED_OPTIONS | set(self.extra_options))
            raise ValueError(f"unknown option(s) {sorted(unknown)} for method {self.name!r}; known options: {allowed}")
        return {k: rule.check(k, v) if (rule := self.option_rule(k)) is not None else v for k, v in extra.items()}

    def option_rule(self, name: str) -> Option | None:
        """The declaration of the method option ``name``: the method's own, else the shared one
        (:func:`declare_options`); None if it has none (its recipe then checks it when building)."""
        return self.option_rules.get(name) or _DECLARED_OPTIONS.get(name)

    def check_inputs(self, priors: bool, order: bool) -> None:
        """Whether the method can run with (``True``) or without priors= and order=; ValueError says why not."""
        if priors and order:
            raise ValueError("give either priors (guided sampling) or order (PROSAC), not both")
        if self.inputs == "order" and not order:
            raise ValueError(f"method {self.name!r} needs order=: a permutation of range(N), best correspondence first")
        if self.inputs == "priors" and not priors:
            raise ValueError(
                f"method {self.name!r} needs priors=: one inlier probability gamma_i per correspondence "
                "(e.g. calibrated match scores; clipped to (0, 1))"
            )
        if self.inputs == "none" and (priors or order):
            raise ValueError(
                f"method {self.name!r} does not sample hypotheses: priors= and order= have no role in it; pass neither"
            )

    def run(
        self,
        problem: StereoProblem,
        options: EstimatorOptions,
        priors: np.ndarray | None,
        order: np.ndarray | None,
        extra: dict,
        rng: np.random.Generator,
    ) -> RansacReport:
        """Estimate on ``problem``: the shared loop on the recipe, or the direct runner."""
        if self.runner is not None:
            return self.runner(problem, options, priors, order, extra, rng)
        return run_ransac(problem, self.build(problem, options, priors, order, extra), rng)


_METHODS: dict[str, MethodSpec] = {}
_DECLARED_OPTIONS: dict[str, Option] = {}


def declare_options(rules: Mapping[str, Option]) -> None:
    """Declare method options by name, for every method that lists them in ``extra_options``
    (e.g. the ``sprt_*`` options of ``waldsac`` and ``usac``): each given value is then checked
    by its declaration before any method runs.

    Raises:
        ValueError: a name declared before with another rule.
    """
    for name, rule in rules.items():
        if _DECLARED_OPTIONS.get(name, rule) != rule:
            raise ValueError(f"option {name!r} is already declared as {_DECLARED_OPTIONS[name]!r}")
        _DECLARED_OPTIONS[name] = rule


def declared_option(name: str) -> Option | None:
    """The shared declaration of a method option (None if undeclared)."""
    return _DECLARED_OPTIONS.get(name)


def _register(spec: MethodSpec) -> None:
    if spec.name in _METHODS:
        raise ValueError(f"method {spec.name!r} is already registered")
    unknown = set(spec.defaults) - {f.name for f in dataclasses.fields(EstimatorOptions)}
    if unknown:
        raise ValueError(f"method {spec.name!r}: defaults {sorted(unknown)} are not EstimatorOptions fields")
    EstimatorOptions(**spec.defaults)  # each default obeys its declaration
    _METHODS[spec.name] = spec


def _option_names_and_rules(extra_options) -> tuple[tuple[str, ...], dict[str, Option]]:
    if isinstance(extra_options, Mapping):
        return tuple(extra_options), dict(extra_options)
    return tuple(extra_options), {}


def register_method(
    name: str, description: str, reference: str, extra_options: tuple[str, ...] | Mapping[str, Option] = (),
    inputs: str = "any", defaults: Mapping[str, Any] | None = None,
) -> Callable[[MethodBuilder], MethodBuilder]:
    """Decorator registering ``build(problem, options, priors, order, extra) -> RansacComponents``.

    ``extra_options``: the method's own option names, or a mapping of them to their declarations
    (:mod:`stereovo.options`), which are then checked before the method runs. ``inputs``: see
    :meth:`MethodSpec.check_inputs`. ``defaults``: :attr:`MethodSpec.defaults`.
    """

    def decorator(build: MethodBuilder) -> MethodBuilder:
        names, rules = _option_names_and_rules(extra_options)
        _register(MethodSpec(name, description, reference, build, names, option_rules=rules, inputs=inputs,
                             defaults=dict(defaults or {})))
        return build

    return decorator


def register_estimator(
    name: str, description: str, reference: str, extra_options: tuple[str, ...] | Mapping[str, Option] = (),
    inputs: str = "none",
) -> Callable[[MethodRunner], MethodRunner]:
    """Decorator registering a method that is not a sampling loop.

    The runner ``run(problem, options, priors, order, extra, rng) -> RansacReport`` reuses the
    core's fit, refinement and scoring; :func:`estimate_motion` wraps its report like the loop's.
    ``extra_options`` and ``inputs`` as :func:`register_method`'s (a direct runner samples nothing:
    ``inputs="none"`` by default).
    """

    def decorator(runner: MethodRunner) -> MethodRunner:
        names, rules = _option_names_and_rules(extra_options)
        _register(MethodSpec(name, description, reference, None, names, runner, option_rules=rules, inputs=inputs))
        return runner

    return decorator


def available_methods() -> dict[str, str]:
    """Registered method names mapped to ``"description; recipe (reference)"``: the recipe says
    which enhancements (:data:`ENHANCEMENTS`) the method uses by default, or that it has none."""
    return {name: f"{spec.description}; {recipe_note(spec.defaults)} ({spec.reference})" for name, spec in _METHODS.items()}


def method_spec(name: str) -> MethodSpec:
    if name not in _METHODS:
        raise ValueError(f"unknown method {name!r}; available: {', '.join(sorted(_METHODS))}")
    return _METHODS[name]


# ----------------------------------------------------------------------------- shared recipe parts


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


ENHANCEMENTS: dict[str, tuple[str, dict[str, Any]]] = {
    "polish": ("sample polish (2 Gauss-Newton steps of each minimal fit on its points' reprojection error)",
               {"polish_iterations": 2}),
    "refit": ("local refit (each new best refitted on its consensus)", {"local_refit": True}),
    "rigidity": ("rigidity check (samples whose pairwise distances change beyond their noise are dropped unfitted)",
                 {"rigidity_gate_probability": 0.999}),
    "lm": ("iterated two-image LM refinement (refine, re-select the inliers, until they settle)", {"refine": True}),
}
"""The project's additions to the papers' recipes, by the name a ``+`` variant gives them, with the
:class:`EstimatorOptions` values that switch each one on (any method accepts them as options)."""


def enhancements_used(values: Mapping[str, Any]) -> list[str]:
    """Names of :data:`ENHANCEMENTS` that the option ``values`` switch on (absent = the default, off)."""
    used = []
    if values.get("polish_iterations", 0):
        used.append("polish")
    if values.get("local_refit", False):
        used.append("refit")
    if values.get("rigidity_gate_probability") is not None:
        used.append("rigidity")
    if values.get("refine", False):
        used.append("lm")
    return used


def recipe_note(defaults: Mapping[str, Any]) -> str:
    """Which enhancements a method's ``defaults`` switch on, in words (for its description)."""
    used = enhancements_used(defaults)
    if not used:
        return "the paper's recipe, no enhancements"
    return "enhancements: " + ", ".join(ENHANCEMENTS[name][0] for name in used)


def register_variant(base: str, *enhancements: str) -> str:
    """Register ``base+e1+e2...``: method ``base`` with the named :data:`ENHANCEMENTS` switched on by
    default (for the baseline report's "+ enhancement" rows). Returns the variant's name."""
    unknown = [e for e in enhancements if e not in ENHANCEMENTS]
    if unknown or not enhancements:
        raise ValueError(f"enhancements must be some of {sorted(ENHANCEMENTS)}, got {list(enhancements)}")
    spec = method_spec(base)
    defaults = dict(spec.defaults)
    for name in enhancements:
        defaults.update(ENHANCEMENTS[name][1])
    name = "+".join((base, *enhancements))
    _register(dataclasses.replace(spec, name=name, defaults=defaults))
    return name


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
    return RigidityCheck(_chi2_quantile(options.rigidity_gate_probability, 1))


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
    threshold = _chi2_quantile(options.refine_gate_probability, int(dof))
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


# ----------------------------------------------------------------------------- public entry point


@dataclass
class MotionEstimate:
    """The result of :func:`estimate_motion`.

    Attributes:
        rotation, translation: ``(3, 3)`` and ``(3,)``, ``x_k = R x_{k-1} + t`` (identity on failure).
        inliers: ``(N,)`` bool mask of the final model's inliers (False on unusable rows).
        status: ``"ok"`` or ``"failed: <reason>"``.
        n_hypotheses: minimal samples drawn; n_scored: hypotheses verified;
        n_point_checks: point-hypothesis residual evaluations.
        time_s: wall time of the estimate in seconds.
        method: the method's name.
        score: the final model's quality under the method's own measure.
        report: the loop's full report on the usable rows (None when the frame failed before the
            loop); its masks have one entry per usable row.
        unusable: ``(N,)`` bool, the rows without depth (disparity at or below
            ``camera.min_disparity`` at k-1 or k, or no finite triangulation). They were never
            sampled and are never inliers; see :attr:`n_unusable`.
        covariance: ``(6, 6)`` covariance of the motion's error vector
            ``e = (log(R_est R_true^T), t_est - t_true)`` (rotation first, rad, in the world-side,
            left-multiplied form; then translation, m), propagated from the pixel noise of both
            frames through the least-squares fit on the final inliers
            (:func:`stereovo.estimation.refinement.pose_covariance`); None on a failed estimate.
        counters: the method's own counters (e.g. T(d,d) passes, SPRT tests, local optimisation
            runs), name -> number, as its components report them (``RansacReport.counters``);
            empty for a method that reports none.
    """

    rotation: np.ndarray
    translation: np.ndarray
    inliers: np.ndarray
    status: str
    n_hypotheses: int
    n_scored: int
    n_point_checks: int
    time_s: float
    method: str
    score: float = float("-inf")
    report: RansacReport | None = None
    unusable: np.ndarray | None = None
    covariance: np.ndarray | None = None
    counters: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.unusable is None:
            self.unusable = np.zeros(np.shape(self.inliers)[0], dtype=bool)

    @classmethod
    def from_report(cls, report: RansacReport, method: str, time_s: float) -> "MotionEstimate":
        """The public view of one run of the loop (or of a direct estimator)."""
        return cls(
            rotation=report.rotation,
            translation=report.translation,
            inliers=report.inliers,
            status=report.status,
            n_hypotheses=report.n_hypotheses,
            n_scored=report.n_scored,
            n_point_checks=report.n_point_checks,
            time_s=time_s,
            method=method,
            score=report.score,
            report=report,
            counters=dict(getattr(report, "counters", None) or {}),
        )

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def n_inliers(self) -> int:
        return int(np.count_nonzero(self.inliers))

    @property
    def n_unusable(self) -> int:
        """Number of rows without depth (:attr:`unusable`)."""
        return int(np.count_nonzero(self.unusable))


def as_generator(rng: np.random.Generator | int | np.random.SeedSequence | None) -> np.random.Generator:
    """The one way seeds become generators: an existing Generator is used as is."""
    if isinstance(rng, np.random.Generator):
        return rng
    return np.random.default_rng(rng)


_SHARED_OPTIONS = frozenset(f.name for f in dataclasses.fields(EstimatorOptions))


def _split_options(spec: MethodSpec, options: dict) -> tuple[EstimatorOptions, dict]:
    known = _SHARED_OPTIONS
    extra = spec.check_options({k: v for k, v in options.items() if k not in known})
    shared = EstimatorOptions(**{**spec.defaults, **{k: v for k, v in options.items() if k in known}})
    return shared, extra


def validate_options(
    method: str, options: Mapping[str, Any], priors: bool | None = None, order: bool | None = None
) -> tuple[EstimatorOptions, dict[str, Any]]:
    """Check a method call's settings without running it: the shared options, the method's own
    options and, when ``priors`` or ``order`` is given (whether priors= / order= will be passed),
    whether the method runs with that sampling input. What :func:`estimate_motion` accepts, this accepts.

    Returns:
        The :class:`EstimatorOptions` and the method's own options (validated, normalised).

    Raises:
        ValueError: an unknown method or option, a value its declaration refuses (naming both),
            or sampling inputs the method cannot use.
    """
    spec = method_spec(method)
    shared, extra = _split_options(spec, dict(options))
    if priors is not None or order is not None:
        spec.check_inputs(bool(priors), bool(order))
    return shared, extra


def estimate_motion(
    prev: np.ndarray,
    curr: np.ndarray,
    camera: StereoCamera,
    method: str = "probabilistic",
    priors: np.ndarray | None = None,
    order: np.ndarray | None = None,
    rng: np.random.Generator | int | None = 0,
    **options,
) -> MotionEstimate:
    """Estimate the motion ``x_k = R x_{k-1} + t`` between two stereo frames.

    Args:
        prev, curr: ``(N, 4)`` stereo measurements ``(uL, vL, uR, vR)`` in pixels at k-1 and k;
            row i of both is one putative match.
        camera: the rectified stereo rig.
        method: a name from :func:`available_methods`.
        priors: optional ``(N,)`` non-negative sampling weights (guided sampling).
        order: optional ``(N,)`` permutation, best match first (PROSAC sampling).
        rng: a ``numpy.random.Generator`` or a seed; the same seed gives the same result.
        **options: fields of :class:`EstimatorOptions` and the method's own options.

    Returns:
        A :class:`MotionEstimate`. Rows without depth (disparity at or below
        ``camera.min_disparity`` at k-1 or k) are outliers: the method runs on the other rows and
        the estimate names them (``unusable``, ``n_unusable``). A hopeless frame (fewer than 3
        or ``min_inliers`` usable rows, every sample degenerate, no consensus) gives
        ``status="failed: ..."`` with identity motion; it never raises.

    Raises:
        ValueError: malformed input (shapes, NaN/inf, mismatched N, complex or non-numeric
            values), bad priors/order, an unknown method or option.
    """
    start = time.perf_counter()
    spec = method_spec(method)
    shared, extra = _split_options(spec, options)
    problem = StereoProblem.build(prev, curr, camera, shared.noise_sigma)
    return _estimate(problem, spec, shared, extra, priors, order, rng, start)


def estimate_problem(
    problem: StereoProblem,
    method: str = "probabilistic",
    priors: np.ndarray | None = None,
    order: np.ndarray | None = None,
    rng: np.random.Generator | int | None = 0,
    **options,
) -> MotionEstimate:
    """:func:`estimate_motion` on an already built :class:`StereoProblem`.

    For callers that use the same frame's triangulated points elsewhere (the environment
    computes its observation features from them): the problem is built, validated and
    triangulated once. The result is identical to ``estimate_motion(problem.prev,
    problem.curr, problem.camera, ..., noise_sigma=problem.noise_sigma)``.

    Raises:
        ValueError: as :func:`estimate_motion`, and if a ``noise_sigma`` option differs from
            the one the problem was built with.
    """
    start = time.perf_counter()
    if not isinstance(problem, StereoProblem):
        raise ValueError(f"problem must be a StereoProblem, got {type(problem).__name__}")
    spec = method_spec(method)
    if "noise_sigma" in options and options["noise_sigma"] != problem.noise_sigma:
        raise ValueError(
            f"noise_sigma={options['noise_sigma']!r} differs from the problem's {problem.noise_sigma!r}, "
            "with which its covariances were computed"
        )
    shared, extra = _split_options(spec, {**options, "noise_sigma": problem.noise_sigma})
    return _estimate(problem, spec, shared, extra, priors, order, rng, start)


def _estimate(
    problem: StereoProblem,
    spec: MethodSpec,
    shared: EstimatorOptions,
    extra: dict,
    priors: np.ndarray | None,
    order: np.ndarray | None,
    rng: np.random.Generator | int | None,
    start: float,
) -> MotionEstimate:
    """Validate priors/order, run the method on ``problem``'s usable rows and scatter the result
    back to all N rows; ``start`` is the caller's perf_counter."""
    method = spec.name
    spec.check_inputs(priors is not None, order is not None)
    for name, value in (("priors", priors), ("order", order)):
        if value is not None and np.shape(value) != (problem.n,):
            raise ValueError(f"{name} must have shape ({problem.n},), one entry per correspondence, got {np.shape(value)}")
    generator = as_generator(rng)
    unusable = ~problem.usable_mask
    need = max(SAMPLE_SIZE, shared.min_inliers)

    def failed(reason: str) -> MotionEstimate:
        return MotionEstimate(
            np.eye(3), np.zeros(3), np.zeros(problem.n, dtype=bool), f"failed: {reason}",
            0, 0, 0, time.perf_counter() - start, method, unusable=unusable,
        )

    if problem.n < need:
        return failed(f"too few correspondences ({problem.n}, need {need})")
    if priors is not None:
        priors = np.ascontiguousarray(validate_priors(priors, problem.n))  # one layout for the compiled draws
    if order is not None:
        order = validate_order(order, problem.n)
    sub, rows = problem.usable_subproblem()
    if rows is not None:
        if rows.size < need:
            return failed(f"too few usable correspondences ({rows.size} of {problem.n} usable, need {need})")
        if priors is not None:
            priors = priors[rows]
            if np.count_nonzero(priors > 0) < SAMPLE_SIZE:
                return failed(
                    f"priors have fewer than {SAMPLE_SIZE} positive weights on the {rows.size} usable correspondences"
                )
        if order is not None:
            # the permutation's relative order of the usable rows, renumbered within the sub-problem
            position = np.cumsum(problem.usable) - 1
            order = position[order[problem.usable[order]]]
    report = spec.run(sub, shared, priors, order, extra, generator)
    estimate = MotionEstimate.from_report(report, method, 0.0)
    if estimate.ok:
        estimate.covariance = pose_covariance(sub, estimate.rotation, estimate.translation, estimate.inliers)
    if rows is not None:
        inliers = np.zeros(problem.n, dtype=bool)
        inliers[rows] = estimate.inliers
        estimate.inliers = inliers
        estimate.unusable = unusable
    estimate.time_s = time.perf_counter() - start
    return estimate
