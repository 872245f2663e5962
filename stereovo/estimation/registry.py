"""The registry of named methods: :class:`MethodSpec`, the decorators that register, the look-ups.

A method registers a recipe for the shared loop (:func:`register_method`) or a direct
estimator (:func:`register_estimator`), declaring with it which shared options its recipe reads
(:class:`~stereovo.estimation.estimator_options.OptionReads`); :func:`register_variant` adds
``base+enhancement`` variants; options several methods share are declared once
(:func:`declare_options`). :func:`validate_options` checks a call's options by these declarations
and refuses the ones the method would not read (:func:`unread_options`); :func:`drop_unread` leaves
them out of settings a caller applies to many methods.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from stereovo.estimation.estimator_options import (
    ENHANCEMENTS,
    SHARED_OPTIONS,
    UNREAD_CANDIDATES,
    EstimatorOptions,
    OptionReads,
    recipe_note,
    unread_message,
)
from stereovo.estimation.loop import RansacComponents, RansacReport, run_ransac
from stereovo.estimation.problem import StereoProblem
from stereovo.options import Option


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
    ``runner`` (a direct estimator returning the loop's :class:`RansacReport`) is set. ``reads``
    declares which shared options the recipe reads (its judge, final refinement and stop); a
    ``+`` variant keeps its base's.
    """

    name: str
    description: str
    reference: str
    build: MethodBuilder | None
    reads: OptionReads
    extra_options: tuple[str, ...] = ()  # method-specific keyword options besides EstimatorOptions
    runner: MethodRunner | None = None
    # Declarations (stereovo.options) of the extra options that have one; a given value is checked
    # before the method runs, so that validity never depends on the frame (nor on a probe frame).
    option_rules: Mapping[str, Option] = dataclasses.field(default_factory=dict)
    # The method's own defaults for EstimatorOptions fields (e.g. probabilistic's tuned recipe, a
    # variant's enhancements): plain values, applied unless the caller gives the option.
    defaults: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    # what the sampler takes: "any" (priors=, order= or neither), "priors", "order", "none", or
    # "priors-optional" (priors= or neither: a belief sampler, which has no use for a ranking)
    inputs: str = "any"

    def check_options(self, extra: Mapping[str, Any]) -> dict[str, Any]:
        """The given method options, validated against :attr:`option_rules` and normalised.

        Raises:
            ValueError: an option that is not the method's, or a value its declaration refuses.
        """
        unknown = set(extra) - set(self.extra_options)
        if unknown:
            allowed = sorted(SHARED_OPTIONS | set(self.extra_options))
            raise ValueError(f"unknown option(s) {sorted(unknown)} for method {self.name!r}; known options: {allowed}")
        given = {k: rule.check(k, v) if (rule := self.option_rule(k)) is not None else v for k, v in extra.items()}
        return {**self.option_defaults(), **given}

    def option_defaults(self) -> dict[str, Any]:
        """The method's options at their declared defaults (:attr:`stereovo.options.Option.default`):
        what its recipe reads for an option the caller did not give."""
        return {name: rule.default for name in self.extra_options if (rule := self.option_rule(name)) is not None}

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
        if self.inputs == "priors-optional" and order:
            raise ValueError(f"method {self.name!r} samples by inlier beliefs: give priors= (or nothing), not order=")
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


def _register(spec: MethodSpec) -> None:
    if spec.name in _METHODS:
        raise ValueError(f"method {spec.name!r} is already registered")
    if not isinstance(spec.reads, OptionReads):
        raise ValueError(f"method {spec.name!r}: reads must be an OptionReads (its judge, refinement and stop), "
                         f"got {spec.reads!r}")
    for option, value in spec.option_defaults().items():
        spec.option_rule(option).check(option, value)  # each declared default obeys its rule
    unknown = set(spec.defaults) - {f.name for f in dataclasses.fields(EstimatorOptions)}
    if unknown:
        raise ValueError(f"method {spec.name!r}: defaults {sorted(unknown)} are not EstimatorOptions fields")
    EstimatorOptions(**spec.defaults)  # each default obeys its declaration
    _METHODS[spec.name] = spec


def _option_names_and_rules(extra_options) -> tuple[tuple[str, ...], dict[str, Option]]:
    if isinstance(extra_options, Mapping):  # None for a name: its shared declaration
        return tuple(extra_options), {k: v for k, v in extra_options.items() if v is not None}
    return tuple(extra_options), {}


def register_method(
    name: str, description: str, reference: str, extra_options: tuple[str, ...] | Mapping[str, Option] = (),
    inputs: str = "any", defaults: Mapping[str, Any] | None = None, *, reads: OptionReads,
) -> Callable[[MethodBuilder], MethodBuilder]:
    """Decorator registering ``build(problem, options, priors, order, extra) -> RansacComponents``.

    ``extra_options``: the method's own option names (declared by :func:`declare_options`), or a
    mapping of them to their declarations (:mod:`stereovo.options`; None: the shared one). Each
    given value is checked before the method runs, and the recipe gets every option, the caller's
    value or the declaration's :attr:`~stereovo.options.Option.default`. ``inputs``: see
    :meth:`MethodSpec.check_inputs`. ``defaults``: :attr:`MethodSpec.defaults`. ``reads`` (required,
    so that no method leaves it out): the judge, final refinement and stop the recipe has, which
    say the shared options it never reads (:class:`OptionReads`).
    """

    def decorator(build: MethodBuilder) -> MethodBuilder:
        names, rules = _option_names_and_rules(extra_options)

        def recipe(problem, options, priors, order, extra):
            # every caller's recipe reads the method's options complete: given or at their defaults
            return build(problem, options, priors, order, _METHODS[name].check_options(extra))

        _register(MethodSpec(name, description, reference, recipe, reads, names, option_rules=rules, inputs=inputs,
                             defaults=dict(defaults or {})))
        return build

    return decorator


def register_estimator(
    name: str, description: str, reference: str, extra_options: tuple[str, ...] | Mapping[str, Option] = (),
    inputs: str = "none", *, reads: OptionReads,
) -> Callable[[MethodRunner], MethodRunner]:
    """Decorator registering a method that is not a sampling loop.

    The runner ``run(problem, options, priors, order, extra, rng) -> RansacReport`` reuses the
    core's fit, refinement and scoring; :func:`estimate_motion` wraps its report like the loop's.
    ``extra_options``, ``inputs`` and ``reads`` as :func:`register_method`'s (a direct runner samples
    nothing: ``inputs="none"`` by default).
    """

    def decorator(runner: MethodRunner) -> MethodRunner:
        names, rules = _option_names_and_rules(extra_options)

        def run(problem, options, priors, order, extra, rng):
            return runner(problem, options, priors, order, _METHODS[name].check_options(extra), rng)

        _register(MethodSpec(name, description, reference, None, reads, names, run, option_rules=rules, inputs=inputs))
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


_SPLIT_CACHE: dict[tuple, tuple[MethodSpec, EstimatorOptions, dict[str, Any]]] = {}
_SPLIT_CACHE_SIZE = 256
_CACHEABLE_VALUES = (bool, int, float, str, type(None), np.bool_, np.integer, np.floating)


def _split_key(spec: MethodSpec, options: Mapping[str, Any]) -> tuple | None:
    """The cache key of a call's options: names, value types and values (``1``, ``1.0`` and ``True``
    hash alike but are checked differently), or None where a value is not a plain scalar."""
    items = []
    for name, value in options.items():
        if not isinstance(value, _CACHEABLE_VALUES):
            return None
        items.append((name, type(value), value))
    return (spec.name, tuple(sorted(items, key=lambda item: item[0])))


def split_options(spec: MethodSpec, options: Mapping[str, Any]) -> tuple[EstimatorOptions, dict[str, Any]]:
    """``options`` of a call to method ``spec`` as its :class:`EstimatorOptions` (the method's
    :attr:`~MethodSpec.defaults` under the given shared options) and its own options, validated.

    A call with the scalar options of an earlier one gets that call's result (the method's own
    options as a fresh dict): deriving and checking them costs as much as the search of an easy
    frame, and the benchmarks and scripts repeat one call frame after frame. Options that were
    refused are not kept, so they are refused again."""
    key = _split_key(spec, options)
    cached = _SPLIT_CACHE.get(key) if key is not None else None
    if cached is not None and cached[0] is spec:
        return cached[1], dict(cached[2])
    shared, extra = _split_options(spec, options)
    if key is not None:
        if len(_SPLIT_CACHE) >= _SPLIT_CACHE_SIZE:
            _SPLIT_CACHE.clear()
        _SPLIT_CACHE[key] = (spec, shared, dict(extra))
    return shared, extra


def _split_options(spec: MethodSpec, options: Mapping[str, Any]) -> tuple[EstimatorOptions, dict[str, Any]]:
    """:func:`split_options` without the cache."""
    extra = spec.check_options({k: v for k, v in options.items() if k not in SHARED_OPTIONS})
    given = {k: v for k, v in options.items() if k in SHARED_OPTIONS}
    merged = {**spec.defaults, **given}
    if "runner_up_refit" not in given and not merged.get("local_refit", False):
        # the runner-up refit is part of the local refit: a caller who switches that off drops both
        merged.pop("runner_up_refit", None)
    return EstimatorOptions(**merged), extra


def unread_options(method: str, options: EstimatorOptions, given: Iterable[str],
                   order: bool | None = None, extra: Mapping[str, Any] | None = None) -> dict[str, str]:
    """The names in ``given`` that ``method`` never reads with ``options``, each mapped to why (by its
    declaration, :meth:`OptionReads.unread <stereovo.estimation.estimator_options.OptionReads.unread>`):

    - under a fixed ``budget`` no adaptive stop runs: ``max_iterations``, ``first_batch_size`` and
      ``fail_at_cap`` are never read, nor is ``confidence``, except by a PROSAC stop (``prosac``; ``usac``
      given an order), which still picks the sampler's prefix with it;
    - ``preemptive`` hands one set of M hypotheses to its verifier in one batch: never ``max_iterations``
      (M is its cap), ``batch_size``, ``first_batch_size`` nor ``runner_up_refit``; ``local_refit`` only
      without a final refinement (which refits the one batch's best in its place), and without a budget
      ``confidence`` only with ``fail_at_cap=True``;
    - ``inlier-detection`` draws no hypotheses: never ``budget``, ``max_iterations``, ``fail_at_cap``,
      ``batch_size``, ``first_batch_size``, ``polish_iterations``, ``rigidity_gate_probability``,
      ``local_refit`` nor ``runner_up_refit`` (its fit inside the clique reads ``confidence``);
    - ``bansac`` and ``p-bansac`` draw their own batches (``bansac_batch``): never ``first_batch_size``,
      and ``batch_size`` only under ``bansac_update='verdict-likelihood'``;
    - ``runner_up_refit`` works from a search's second batch on: never where the cap (the ``budget``, else
      ``max_iterations``) is no larger than the first batch (``batch_size`` under a budget, an adaptive
      search's ``first_batch_size`` if smaller; ``bansac``'s ``bansac_batch``, one hypothesis at least);
    - where a local optimisation runs on every new best whatever ``local_refit`` says (the consensus refit
      of ``bansac``, ``p-bansac`` and ``ars``; the LO+ of ``lo-ransac`` and ``usac``), ``local_refit`` is
      read only as what a given ``runner_up_refit`` needs;
    - ``least_squares_refit`` chooses the final step only without ``refine`` (the iterated LM
      refinement replaces it), and never in ``inlier-detection``, which ends with its own fit;
      ``refine_rounds`` is read only with ``refine=True``, ``refine_iterations`` only where a final
      refinement runs;
    - ``gate_probability`` is never read by a method judged by the stereo reprojection gate
      (``ransac``, ``msac``, ``prosac``, ``r-ransac``, ``waldsac``, ``lo-ransac``, ``preemptive``,
      ``usac``), nor ``threshold_px`` by one judged by the 3-D Mahalanobis gate (``probabilistic``,
      ``mlesac``, ``guided-mlesac``, ``ars``, ``bansac``, ``p-bansac``), whose final inliers are selected
      by a Mahalanobis gate too; ``refine_gate_probability`` only by those with ``probabilistic``'s
      pixel-gated final refinement (``probabilistic``, ``bansac``, ``p-bansac``, ``ars``), when a final
      refinement runs.

    A ``+`` method (``msac+polish+lm``, ``probabilistic+sprt``) reads what its base reads, with its own
    defaults (``+lm``'s ``refine=True`` leaves ``least_squares_refit`` unread).

    Args:
        method: a registered name. options: its validated options (its defaults under the given ones).
        given: the option names the caller gave (defaults are never refused).
        order: whether ``order=`` is passed; None when not known (an option read with an order is kept).
        extra: the method's own options, validated (:func:`split_options`); None when not known (an
            option read with some of them is kept).

    Raises:
        ValueError: an unknown method.
    """
    return method_spec(method).reads.unread(method, options, given, order, extra)


def refuse_unread(spec: MethodSpec, options: EstimatorOptions, given: Mapping[str, Any], order: bool | None,
                  extra: Mapping[str, Any] | None = None) -> None:
    """Raise if the caller ``given`` options (name -> value) that method ``spec`` with ``options``
    never reads (:func:`unread_options`); ``order`` and ``extra`` as there.

    Raises:
        ValueError: ``"method NAME: OPTION=VALUE would be ignored: WHY; ..."``, every such option named.
    """
    if UNREAD_CANDIDATES.isdisjoint(given):  # the common call: nothing to look up
        return
    unread = spec.reads.unread(spec.name, options, given, order, extra)
    if unread:
        raise ValueError(f"method {spec.name!r}: {unread_message(unread, given)}")


def drop_unread(method: str, options: Mapping[str, Any], among: Iterable[str] | None = None,
                order: bool | None = None) -> dict[str, Any]:
    """``options`` without those of ``among`` (default: all of them) that ``method`` would never read
    with the others (:func:`unread_options`), which it would refuse.

    For settings a caller applies to many methods or sets on its own (a benchmark's hypothesis cap, an
    environment's recipe): each method gets those it reads. A user's own options for one method are
    refused instead (leave them out of ``among``). Dropping an unread option leaves what the method
    reads, and so whether it reads the others, unchanged.

    Raises:
        ValueError: an unknown method or option, or a value its declaration refuses.
    """
    spec = method_spec(method)
    shared, extra = split_options(spec, options)
    names = set(options) if among is None else set(options) & set(among)
    unread = spec.reads.unread(spec.name, shared, names, order, extra)
    return {name: value for name, value in options.items() if name not in unread}


def validate_options(
    method: str, options: Mapping[str, Any], priors: bool | None = None, order: bool | None = None
) -> tuple[EstimatorOptions, dict[str, Any]]:
    """Check a method call's settings without running it: the shared options, the method's own
    options, when ``priors`` or ``order`` is given (whether priors= / order= will be passed) whether
    the method runs with that sampling input, and that it reads every option given
    (:func:`unread_options`; without ``priors`` and ``order`` an option that the method reads only
    with an order is kept). What :func:`~stereovo.estimation.api.estimate_motion` accepts, this accepts.

    Returns:
        The :class:`EstimatorOptions` and the method's own options (validated, normalised).

    Raises:
        ValueError: an unknown method or option, a value its declaration refuses (naming both),
            sampling inputs the method cannot use, or an option the method would not read with the
            others (naming it, its value and why), in that order.
    """
    spec = method_spec(method)
    options = dict(options)
    shared, extra = split_options(spec, options)
    told = priors is not None or order is not None
    if told:
        spec.check_inputs(bool(priors), bool(order))
    refuse_unread(spec, shared, options, bool(order) if told else None, extra)
    return shared, extra


def register_variant(base: str, *enhancements: str) -> str:
    """Register ``base+e1+e2...``: method ``base`` with the named :data:`ENHANCEMENTS` switched on by
    default (for the baseline report's "+ enhancement" rows). Returns the variant's name.

    The variant keeps its base's :attr:`MethodSpec.reads`: an enhancement is an option value (the
    sample polish, the local refit, the rigidity check, the LM refinement), which the judge, the
    final refinement and the stop it declares do not depend on; what its defaults switch is read
    from the options (``+lm``'s ``refine=True`` leaves ``least_squares_refit`` unread)."""
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
