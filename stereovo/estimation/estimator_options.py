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
    "mahalanobis": "hypotheses judged by the 3-D Mahalanobis gate (the chi-square(3) quantile gate_probability), "
                   "the final inliers selected by a Mahalanobis gate too: the refinement's, else the judge's",
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
    "preemptive": "one set of M hypotheses (the budget, else the method's own count), which is its cap: never "
                  "max_iterations; without a budget confidence says whether the set confirms the returned model, "
                  "for fail_at_cap=True only; under a budget as 'adaptive'",
    "clique-fit": "no hypothesis loop, so no budget, max_iterations nor fail_at_cap: the RANSAC of the fit inside "
                  "the clique stops adaptively at confidence under a cap of its own",
}
"""The stops a method may declare (:attr:`OptionReads.stop`), in words."""

BATCHES: dict[str, str] = {
    "schedule": "the loop's schedule: batches of batch_size, an adaptive search's first of first_batch_size "
                "doubling up to it",
    "one-set": "the whole hypothesis set in one batch: neither batch_size nor first_batch_size, no second batch "
               "for a runner-up refit (runner_up_refit), and the local refit of local_refit only without a final "
               "refinement (the one batch ends the search, so the refinement refits its best in the refit's place)",
    "belief-updates": "the method's own batches between belief updates from the first (bansac_batch, the paper's "
                      "one hypothesis by default): never first_batch_size, and batch_size only as their cap under "
                      "bansac_update='verdict-likelihood'",
    "none": "no hypotheses drawn in batches (batch_size, first_batch_size) nor minimal samples to polish "
            "(polish_iterations) or check for rigidity (rigidity_gate_probability)",
}
"""How a method batches its hypotheses (:attr:`OptionReads.batches`), in words."""

LOCALS: dict[str, str] = {
    "optional": "the consensus refit of local_refit on each new best (and the runner-up refit of runner_up_refit)",
    "always": "the consensus refit on every new best whatever local_refit says",
    "own": "the method's own local optimisation on every new best whatever local_refit says",
    "none": "no local optimisation: neither local_refit nor runner_up_refit",
}
"""The local optimisations a method may declare (:attr:`OptionReads.local`), in words."""


@dataclass(frozen=True)
class OptionReads:
    """Which of the shared options (:class:`EstimatorOptions`) a method's recipe reads, declared by
    the parts of the recipe that decide it; every method declares one when it registers
    (:func:`~stereovo.estimation.registry.register_method`), and its ``+`` variants keep it (an
    enhancement switches a part on or off by an option value, which :meth:`unread` reads; it never
    changes the parts declared here).

    Attributes:
        judge: how hypotheses are judged, a key of :data:`JUDGES`: ``"reprojection"`` never reads
            ``gate_probability``, ``"mahalanobis"`` never ``threshold_px`` (neither its local refit nor
            its final refinement re-selects inliers by the stereo reprojection gate).
        refinement: the final refinement, a key of :data:`REFINEMENTS`: only ``"pixel-gated"`` reads
            ``refine_gate_probability`` (and only when a refinement runs); ``"lm-only"`` never reads
            ``least_squares_refit``, nor does any refinement with ``refine=True``. Whatever the
            refinement, ``refine_rounds`` is read with ``refine=True`` only, and ``refine_iterations``
            only where a refinement runs.
        stop: the stopping rule, a key of :data:`STOPS`: under a fixed ``budget`` an ``"adaptive"``
            stop reads none of ``confidence``, ``max_iterations``, ``first_batch_size`` and
            ``fail_at_cap``; the PROSAC stop still reads ``confidence``; ``"preemptive"`` never reads
            ``max_iterations``; ``"clique-fit"`` reads ``confidence`` whatever the budget, and never
            ``budget``, ``max_iterations`` or ``fail_at_cap``.
        batches: how hypotheses are batched, a key of :data:`BATCHES` (default ``"schedule"``, the loop's).
            A search whose cap (the ``budget``, else ``max_iterations``) is no larger than its first
            batch draws one batch, so it never reads ``runner_up_refit``, which works from the second.
        local: the local optimisation, a key of :data:`LOCALS` (default ``"optional"``, the loop's):
            where one runs whatever ``local_refit`` says, ``local_refit`` is read only as what
            ``runner_up_refit`` needs.
    """

    judge: str
    refinement: str
    stop: str
    batches: str = "schedule"
    local: str = "optional"

    def __post_init__(self) -> None:
        for name, known in (("judge", JUDGES), ("refinement", REFINEMENTS), ("stop", STOPS), ("batches", BATCHES),
                            ("local", LOCALS)):
            if getattr(self, name) not in known:
                raise ValueError(f"OptionReads.{name} must be one of {sorted(known)}, got {getattr(self, name)!r}")

    def unread(self, method: str, options: EstimatorOptions, given: Iterable[str],
               order: bool | None = None, extra: Mapping[str, Any] | None = None) -> dict[str, str]:
        """The names in ``given`` that ``method`` (declaring this) never reads with ``options``, each
        mapped to why; an empty dict when it reads them all.

        Args:
            method: the method's name (for the reasons). options: its options as it runs with them
                (the method's defaults under the given ones). given: the option names the caller
                gave; only these are looked at (a default is never refused).
            order: whether the method is given ``order=`` (PROSAC sampling); None when not known,
                which keeps an option that the method reads with an order.
            extra: the method's own options as it runs with them; None when not known, which keeps an
                option that the method reads with some of them (``batch_size`` of ``bansac``).
        """
        given = set(given) & UNREAD_CANDIDATES
        if not given:
            return {}
        why: dict[str, str] = {}
        adaptive = "(budget=None switches to the adaptive stop)"
        if options.budget is not None and self.stop != "clique-fit":
            budget = f"a fixed budget (budget={options.budget}) draws exactly that many hypotheses per frame"
            why["max_iterations"] = f"{budget}, above any cap: max_iterations caps an adaptive search {adaptive}"
            why["first_batch_size"] = (f"{budget} in batches of batch_size: first_batch_size sizes an adaptive "
                                       f"search's first batch {adaptive}")
            why["fail_at_cap"] = (f"{budget}: the budget is the stop itself, never a cap reached before a stop, so "
                                  f"no estimate fails at it {adaptive}")
            # the PROSAC stop listens under a budget too: it picks the sampled prefix n* with confidence
            prosac = self.stop == "prosac" or (self.stop == "prosac-given-order" and order is not False)
            if not prosac:
                why["confidence"] = f"{budget}: no adaptive stop runs for confidence to set {adaptive}"
        if self.stop == "preemptive":
            one_set = f"method {method!r} draws one set of M hypotheses (the budget, else its preemptive_hypotheses)"
            why["max_iterations"] = f"{one_set}, which is its cap: max_iterations caps none of its searches"
            if options.budget is None and not options.fail_at_cap:
                why["confidence"] = (f"{one_set} and with fail_at_cap=False returns their best whatever the "
                                     "confidence: only fail_at_cap=True asks whether the set confirms it")
        elif self.stop == "clique-fit":
            clique = (f"method {method!r} draws no hypotheses: it takes the maximum clique of consistent matches, "
                      "whose fit stops at confidence under a cap of its own")
            why["budget"] = f"{clique}, so there are none for a budget to count"
            why["max_iterations"] = f"{clique}, so no search of it has a cap for max_iterations to set"
            why["fail_at_cap"] = f"{clique}; the clique is its verdict, which no cap fails"
        refines = options.refine or (options.least_squares_refit and self.refinement != "lm-only")
        why.update(self._unread_by_batches(method, extra))
        why.update(self._unread_in_one_batch(options, extra))
        why.update(self._unread_by_local(method, options, refines))
        if self.refinement == "lm-only":
            why["least_squares_refit"] = (f"method {method!r} ends with its own fit, refined only by the iterated LM "
                                          "refinement of refine=True: no least-squares refit runs for "
                                          "least_squares_refit to choose")
        elif options.refine:
            why["least_squares_refit"] = ("refine=True ends with the iterated LM refinement; least_squares_refit "
                                          "chooses the final step only with refine=False")
        if not refines:
            ends = ("refine=False and least_squares_refit=False run no final refinement" if self.refinement != "lm-only"
                    else f"method {method!r} with refine=False ends with its own fit")
            why["refine_iterations"] = f"{ends}: no LM refinement runs for refine_iterations to set its steps"
        if not options.refine:
            why["refine_rounds"] = ("refine=False runs no iterated LM refinement: refine_rounds bounds its rounds "
                                    "only with refine=True")
        if self.judge == "reprojection":
            why["gate_probability"] = (f"method {method!r} judges by the stereo reprojection gate (threshold_px), not "
                                       "by the 3-D Mahalanobis gate whose quantile gate_probability is")
        elif self.judge == "mahalanobis":
            why["threshold_px"] = (f"method {method!r} judges by the 3-D Mahalanobis gate (gate_probability) and "
                                   "selects its final inliers by a Mahalanobis gate too, never by the stereo "
                                   "reprojection gate whose threshold threshold_px is")
        if self.refinement != "pixel-gated":
            why["refine_gate_probability"] = (f"method {method!r} has no pixel-gated final refinement (it sets the "
                                              "gate of probabilistic's refinement and of the methods built on its "
                                              "judge)")
        elif not refines:
            why["refine_gate_probability"] = ("with refine=False and least_squares_refit=False no final refinement "
                                              "runs for its pixel gate")
        return {name: text for name, text in why.items() if name in given}

    def _unread_by_batches(self, method: str, extra: Mapping[str, Any] | None) -> dict[str, str]:
        """What :attr:`batches` leaves unread (:meth:`unread`'s reasons)."""
        if self.batches == "one-set":
            one_batch = f"method {method!r} hands its whole set of hypotheses to the verifier in one batch"
            return {"batch_size": f"{one_batch}: batch_size sizes none of its batches",
                    "first_batch_size": f"{one_batch}: first_batch_size sizes none of its batches",
                    "runner_up_refit": f"{one_batch}: no later batch has a runner-up for runner_up_refit to refit"}
        if self.batches == "belief-updates":
            own = (f"method {method!r} draws its own batches between belief updates from the first (bansac_batch; "
                   "one hypothesis by default, the paper's)")
            why = {"first_batch_size": f"{own}: first_batch_size sizes none of them"}
            if extra is not None and extra.get("bansac_update") != "verdict-likelihood":
                why["batch_size"] = (f"{own}: batch_size caps them only under bansac_update='verdict-likelihood', "
                                     f"got bansac_update={extra.get('bansac_update')!r}")
            return why
        if self.batches == "none":
            none = (f"method {method!r} draws no hypotheses: it fits its motion on the maximum clique of consistent "
                    "matches")
            return {"batch_size": f"{none}, so batch_size sizes no batch",
                    "first_batch_size": f"{none}, so first_batch_size sizes no batch",
                    "polish_iterations": f"{none}, so no minimal fit is there for polish_iterations to polish",
                    "rigidity_gate_probability": f"{none}, so no minimal sample is there for the rigidity check of "
                                                 "rigidity_gate_probability to drop"}
        return {}

    def _unread_in_one_batch(self, options: EstimatorOptions, extra: Mapping[str, Any] | None) -> dict[str, str]:
        """``runner_up_refit`` where the search's cap is no larger than its first batch (:meth:`unread`'s
        reason): one batch, so no later one has a runner-up. Of the belief updates' own batches only the
        size ``bansac_batch`` gives is known here (None: one hypothesis at least, the paper's one)."""
        if self.local == "none" or self.batches not in ("schedule", "belief-updates"):
            return {}  # no loop, or one set of hypotheses (_unread_by_batches says so)
        if self.batches == "belief-updates":
            own = None if extra is None else extra.get("bansac_batch")
            if own is None:
                first, size = 1, "one hypothesis at least"
            elif extra.get("bansac_update") == "verdict-likelihood":
                first, size = min(options.batch_size, own), f"bansac_batch={own}, at most batch_size"
            else:
                first, size = own, f"bansac_batch={own}"
        elif options.budget is not None or options.batch_size <= options.first_batch_size:
            first, size = options.batch_size, f"batch_size={options.batch_size}"
        else:  # an adaptive search starts with first_batch_size
            first, size = options.first_batch_size, f"first_batch_size={options.first_batch_size}"
        if options.budget is not None:
            cap, text = options.budget, f"a fixed budget (budget={options.budget})"
        else:
            cap, text = options.max_iterations, f"an adaptive search capped at max_iterations={options.max_iterations}"
        if cap > first:
            return {}
        return {"runner_up_refit": f"{text} draws no more than its first batch ({size}): no later batch has a "
                                   "runner-up for runner_up_refit to refit"}

    def _unread_by_local(self, method: str, options: EstimatorOptions, refines: bool) -> dict[str, str]:
        """What :attr:`local` leaves unread with ``options`` (:meth:`unread`'s reasons); ``refines``:
        whether a final refinement runs."""
        if self.local == "none":
            none = f"method {method!r} has no hypothesis loop for a local refit to run in"
            return {"local_refit": none, "runner_up_refit": none}
        # where a refit runs anyway, local_refit=True is still what a given runner_up_refit needs
        if self.local in ("always", "own") and options.runner_up_refit is None:
            what = ("refits every new best on its consensus" if self.local == "always"
                    else "runs its own local optimisation on every new best")
            return {"local_refit": f"method {method!r} {what} whatever local_refit says"}
        if self.local == "optional" and self.batches == "one-set" and refines:
            return {"local_refit": (f"method {method!r} draws its hypotheses in one batch, which ends the search: the "
                                    "final refinement refits the best on its consensus in place of the local refit "
                                    "(refine=False with least_squares_refit=False leaves it to local_refit)")}
        return {}


UNREAD_CANDIDATES = frozenset({
    "confidence", "max_iterations", "budget", "batch_size", "first_batch_size", "fail_at_cap", "least_squares_refit",
    "gate_probability", "refine_gate_probability", "rigidity_gate_probability", "polish_iterations",
    "refine_iterations", "refine_rounds", "local_refit", "runner_up_refit", "threshold_px",
})
"""The shared options that some method leaves unread with some settings (:meth:`OptionReads.unread`):
a call that gives none of them needs no look."""


def unread_message(unread: Mapping[str, str], values: Mapping[str, Any]) -> str:
    """``"NAME=VALUE would be ignored: WHY"`` for each of ``unread`` (name -> why), joined by ``"; "``:
    the one wording of a refused unread option, VALUE the given one of ``values`` (:func:`value_repr`)."""
    return "; ".join(f"{name}={value_repr(values[name])} would be ignored: {why}" for name, why in unread.items())
