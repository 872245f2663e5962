"""The options every method shares: :class:`EstimatorOptions`, their declarations, the enhancements,
and which of them a method reads.

:data:`ESTIMATOR_OPTION_RULES` declares each field (:mod:`stereovo.options`), and
:class:`EstimatorOptions` is checked against it on construction; :data:`ENHANCEMENTS` names
the project's additions to the papers' recipes by the option values that switch them on;
:class:`OptionReads`, which each method declares when it registers, says which of the options it
would never read with the others' values (:meth:`OptionReads.unread`), so that such an option is
refused when given, never accepted and ignored.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any, Iterable, Mapping

from scipy.stats import chi2

from stereovo.estimation.roles.solvers import SAMPLE_SIZE
from stereovo.options import Boolean, Integer, Number, Option, OptionError, value_repr

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
    "runner_up_refit": Number(low=0.0, high=1.0, low_open=True, allow_none=True),
    "least_squares_refit": Boolean(),
    "min_inliers": Integer(low=SAMPLE_SIZE, high=MAX_COUNT),
    "fail_at_cap": Boolean(),
    "min_disparity_sigmas": Number(low=0.0, high=1e3),
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
        max_iterations: hard cap on the hypotheses an adaptive search draws (no ``budget``).
        budget: if set, draw exactly this many hypotheses (fixed budget) instead of stopping
            adaptively: the budget is the stop itself, drawn in full even above ``max_iterations``.
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
        runner_up_refit: None (the default), or a fraction in (0, 1]: from a search's
            second batch on, the local refit also runs on each batch's best hypothesis that is not
            a new best, when its consensus holds at least this fraction of the best model's
            inliers, and that refit becomes the best if it then scores higher (an enhancement,
            ``probabilistic``'s with 0.5; needs ``local_refit``; docs/algorithms.md, "The runner-up
            refit").
        least_squares_refit: without ``refine``, end as Fischler & Bolles do: refit the best model
            by least squares on its inliers (``refine_iterations`` LM steps on their stereo
            reprojection error, one round) and re-select the inliers once under the method's gate;
            False keeps the best hypothesis as it is.
        min_inliers: fewer inliers in the final model is reported as "no consensus".
        fail_at_cap: an adaptive search that reaches ``max_iterations`` before its stop is met,
            for the returned model's inliers too, fails ("no confident consensus"), as Fischler &
            Bolles allow; False returns its largest consensus, their other choice (on hostile
            frames most such estimates are wrong: docs/algorithms.md, "What "ok" means").
        min_disparity_sigmas: a row whose disparity at k-1 or k is at or below this many standard
            deviations of the disparity noise (``sqrt(2) noise_sigma``) has no resolvable depth and
            is unusable (:mod:`stereovo.estimation.problem`); 0 keeps every row with a disparity
            above ``camera.min_disparity``.

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
    runner_up_refit: float | None = None
    least_squares_refit: bool = True
    min_inliers: int = 6
    fail_at_cap: bool = True
    min_disparity_sigmas: float = 2.0

    def __post_init__(self) -> None:
        # One contract (stereovo.options): integers only, bools only, finite numbers in range;
        # values are normalised to plain Python types, never changed numerically.
        for name, rule in ESTIMATOR_OPTION_RULES.items():
            object.__setattr__(self, name, rule.check(name, getattr(self, name)))
        if self.runner_up_refit is not None and not self.local_refit:
            raise OptionError(f"runner_up_refit={self.runner_up_refit!r} needs local_refit=True (it runs the local "
                              f"refit on more hypotheses), got local_refit={self.local_refit!r}")

    @property
    def reprojection_threshold_sq(self) -> float:
        px = 6.0 * self.noise_sigma if self.threshold_px is None else self.threshold_px
        return px * px

    @property
    def mahalanobis_threshold_sq(self) -> float:
        return chi2_quantile(self.gate_probability, 3)


@functools.lru_cache(maxsize=64)
def chi2_quantile(probability: float, dof: int) -> float:
    """The chi-square(``dof``) quantile at ``probability``, the gates' squared thresholds."""
    # scipy's ppf costs a noticeable share of an easy frame's estimate per call (docs/performance.md)
    return float(chi2.ppf(probability, dof))


ENHANCEMENTS: dict[str, tuple[str, dict[str, Any]]] = {
    "polish": ("sample polish (2 Gauss-Newton steps of each minimal fit on its points' reprojection error)",
               {"polish_iterations": 2}),
    "refit": ("local refit (each new best refitted on its consensus)", {"local_refit": True}),
    "runner-up": ("runner-up refit (each batch's best hypothesis short of a new best refitted too when its "
                  "consensus holds half the best's)", {"local_refit": True, "runner_up_refit": 0.5}),
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
    if values.get("runner_up_refit") is not None:
        used.append("runner-up")
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


SHARED_OPTIONS = frozenset(f.name for f in dataclasses.fields(EstimatorOptions))
"""The :class:`EstimatorOptions` field names: the options every method accepts besides its own."""


# ----------------------------------------------------------------------------- which options a method reads

JUDGES: dict[str, str] = {
    "reprojection": "hypotheses judged by the stereo reprojection gate (threshold_px)",
    "mahalanobis": "hypotheses judged by the 3-D Mahalanobis gate (the chi-square(3) quantile gate_probability)",
    "clique": "inliers chosen as the maximum clique of rigid-distance-consistent matches, its motion fitted by a "
              "RANSAC under the 3-D Mahalanobis gate (gate_probability) and re-gated by the stereo reprojection "
              "gate (threshold_px)",
}
"""The judges a method may declare (:attr:`OptionReads.judge`), in words."""

REFINEMENTS: dict[str, str] = {
    "plain": "the iterated LM refinement with refine, else one least-squares refit with least_squares_refit, "
             "each re-selecting the inliers under the judge's gate",
    "pixel-gated": "as 'plain', re-selecting the inliers by the pixel Mahalanobis gate of refine_gate_probability",
    "lm-only": "the iterated LM refinement with refine, else none: the method's own fit is its last step",
}
"""The final refinements a method may declare (:attr:`OptionReads.refinement`), in words."""

STOPS: dict[str, str] = {
    "adaptive": "an adaptive stop (confidence, max_iterations, first_batch_size, fail_at_cap), which a fixed "
                "budget replaces",
    "prosac": "PROSAC's stop: adaptive without a budget; under a fixed budget it still lowers the sampler's "
              "prefix to the n* it picks with confidence",
    "prosac-given-order": "'prosac' when the method is given order=, else 'adaptive'",
    "clique-fit": "no hypothesis loop: the RANSAC of the fit inside the clique stops adaptively at confidence "
                  "under a cap of its own, whatever the budget",
}
"""The stops a method may declare (:attr:`OptionReads.stop`), in words."""


@dataclass(frozen=True)
class OptionReads:
    """Which of the shared options (:class:`EstimatorOptions`) a method's recipe reads, declared by
    the parts of the recipe that decide it; every method declares one when it registers
    (:func:`~stereovo.estimation.registry.register_method`), and its ``+`` variants keep it (an
    enhancement switches a part on or off by an option value, which :meth:`unread` reads; it never
    changes the judge, the refinement or the stop).

    Attributes:
        judge: how hypotheses are judged, a key of :data:`JUDGES`: ``"reprojection"`` never reads
            ``gate_probability``.
        refinement: the final refinement, a key of :data:`REFINEMENTS`: only ``"pixel-gated"`` reads
            ``refine_gate_probability`` (and only when a refinement runs); ``"lm-only"`` never reads
            ``least_squares_refit``, nor does any refinement with ``refine=True``.
        stop: the stopping rule, a key of :data:`STOPS`: under a fixed ``budget`` an ``"adaptive"``
            stop reads none of ``confidence``, ``max_iterations``, ``first_batch_size`` and
            ``fail_at_cap``; the PROSAC stop still reads ``confidence``; ``"clique-fit"`` reads
            ``confidence`` whatever the budget.
    """

    judge: str
    refinement: str
    stop: str

    def __post_init__(self) -> None:
        for name, known in (("judge", JUDGES), ("refinement", REFINEMENTS), ("stop", STOPS)):
            if getattr(self, name) not in known:
                raise ValueError(f"OptionReads.{name} must be one of {sorted(known)}, got {getattr(self, name)!r}")

    def unread(self, method: str, options: EstimatorOptions, given: Iterable[str],
               order: bool | None = None) -> dict[str, str]:
        """The names in ``given`` that ``method`` (declaring this) never reads with ``options``, each
        mapped to why; an empty dict when it reads them all.

        Args:
            method: the method's name (for the reasons). options: its options as it runs with them
                (the method's defaults under the given ones). given: the option names the caller
                gave; only these are looked at (a default is never refused).
            order: whether the method is given ``order=`` (PROSAC sampling); None when not known,
                which keeps an option that the method reads with an order.
        """
        given = set(given) & UNREAD_CANDIDATES
        if not given:
            return {}
        why: dict[str, str] = {}
        if options.budget is not None and self.stop != "clique-fit":
            budget = f"a fixed budget (budget={options.budget}) draws exactly that many hypotheses per frame"
            adaptive = "(budget=None switches to the adaptive stop)"
            why["max_iterations"] = f"{budget}, above any cap: max_iterations caps an adaptive search {adaptive}"
            why["first_batch_size"] = (f"{budget} in batches of batch_size: first_batch_size sizes an adaptive "
                                       f"search's first batch {adaptive}")
            why["fail_at_cap"] = (f"{budget}: the budget is the stop itself, never a cap reached before a stop, so "
                                  f"no estimate fails at it {adaptive}")
            # the PROSAC stop listens under a budget too: it picks the sampled prefix n* with confidence
            prosac = self.stop == "prosac" or (self.stop == "prosac-given-order" and order is not False)
            if not prosac:
                why["confidence"] = f"{budget}: no adaptive stop runs for confidence to set {adaptive}"
        if self.refinement == "lm-only":
            why["least_squares_refit"] = (f"method {method!r} ends with its own fit, refined only by the iterated LM "
                                          "refinement of refine=True: no least-squares refit runs for "
                                          "least_squares_refit to choose")
        elif options.refine:
            why["least_squares_refit"] = ("refine=True ends with the iterated LM refinement; least_squares_refit "
                                          "chooses the final step only with refine=False")
        if self.judge == "reprojection":
            why["gate_probability"] = (f"method {method!r} judges by the stereo reprojection gate (threshold_px), not "
                                       "by the 3-D Mahalanobis gate whose quantile gate_probability is")
        if self.refinement != "pixel-gated":
            why["refine_gate_probability"] = (f"method {method!r} has no pixel-gated final refinement (it sets the "
                                              "gate of probabilistic's refinement and of the methods built on its "
                                              "judge)")
        elif not (options.refine or options.least_squares_refit):
            why["refine_gate_probability"] = ("with refine=False and least_squares_refit=False no final refinement "
                                              "runs for its pixel gate")
        return {name: text for name, text in why.items() if name in given}


UNREAD_CANDIDATES = frozenset({
    "confidence", "max_iterations", "first_batch_size", "fail_at_cap", "least_squares_refit", "gate_probability",
    "refine_gate_probability",
})
"""The shared options that some method leaves unread with some settings (:meth:`OptionReads.unread`):
a call that gives none of them needs no look (the environment's every step)."""


def unread_message(unread: Mapping[str, str], values: Mapping[str, Any]) -> str:
    """``"NAME=VALUE would be ignored: WHY"`` for each of ``unread`` (name -> why), joined by ``"; "``:
    the one wording of a refused unread option, VALUE the given one of ``values`` (:func:`value_repr`)."""
    return "; ".join(f"{name}={value_repr(values[name])} would be ignored: {why}" for name, why in unread.items())
