"""The environments' keywords, each checked by one rule, declared once, the same in every environment.

:class:`vo_gym.env.StereoVOEnv` (and :class:`vo_gym.images_env.StereoVOImagesEnv` above it) and
:class:`vo_gym.adaptive_env.StereoVOAdaptiveEnv` accept the same kinds of keywords, and each one
is checked by the same rule wherever it enters, with the same message
(``StereoVOEnv: hypothesis_cost must be a finite number in [0, 1], got 2``):

- the environment's own (:data:`RULES`, the declarations of :mod:`stereovo.options`), checked by
  :func:`check_settings`, which also applies the rules between two of them;
- the simulator's: the fields of :class:`~stereovo.simulation.SimulationConfig`, whose defaults and
  rules are its own (:func:`simulation_config`);
- the estimator's: the :class:`~stereovo.estimation.EstimatorOptions` fields and the method's own
  options, declared by the estimator (:func:`estimator_settings`); the environments' defaults for
  them are :data:`DEFAULT_ESTIMATOR_OPTIONS`.

A constructor hands its keywords to these functions and keeps what they return as plain attributes;
its signature keeps the defaults (those of the simulator's keywords are SimulationConfig's).

The configs above the environments (the trainers', the evaluation's) refuse a field's value with a
:class:`FieldError`, which carries the field's name (:func:`check_fields`): a command line that set the
field by an option of another name says so without reading the name out of the message.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Iterable, Mapping

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.estimation import EstimatorOptions, method_spec
from stereovo.estimation import unread_options
from stereovo.estimation.estimator_options import ESTIMATOR_OPTION_RULES, MAX_COUNT, SHARED_OPTIONS, unread_message
from stereovo.estimation.registry import MethodSpec, split_options
from stereovo.options import Choice, Integer, Number, Option, OptionError, check_options, is_real, value_repr
from stereovo.simulation import SimulationConfig
from vo_gym.names import constructor_keywords, keyword_hint
from vo_gym.rewards import REWARD_MODES, REWARD_OPTIONS

__all__ = [
    "SAMPLING_MODES", "DEFAULT_ESTIMATOR_OPTIONS", "SIMULATOR_KEYWORDS", "RULES", "Lengths", "ContaminationRange",
    "check_settings", "simulation_config", "observation_rows", "estimator_noise", "estimator_settings",
    "read_by_reward", "check_reset_options", "FieldError", "check_field", "check_fields",
]

SAMPLING_MODES: tuple[str, ...] = ("guided", "prosac")

DEFAULT_ESTIMATOR_OPTIONS: dict[str, Any] = {
    "polish_iterations": 2, "refine": True, "local_refit": False, "refine_iterations": 3, "refine_rounds": 2,
}
"""The environments' defaults for :class:`~stereovo.estimation.EstimatorOptions` fields (the rest
keep the method's defaults): two of the core's enhancements, named explicitly because the named
methods default to their papers' recipes: the sample polish and the final LM refinement (with
fewer iterations and rounds); no per-hypothesis local refit, which keeps a step fast. Pass any of
them as a keyword to change it."""

SIMULATOR_KEYWORDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(SimulationConfig))
"""The simulator's keywords: the :class:`~stereovo.simulation.SimulationConfig` fields (their defaults are its)."""

# exp(+-300) is representable in float64; a larger logit range overflows the sampling weights.
MAX_LOGIT = 300.0
# The action Box is float32: a larger bound is no float32, and gymnasium's Box refused it without naming action_bound.
MAX_ACTION_BOUND = float(np.finfo(np.float32).max)


@dataclasses.dataclass(frozen=True)
class Lengths(Option):
    """A non-empty list, tuple or 1-D array of positive finite lengths (m), normalised to a tuple of
    floats. Anything else is refused, also what merely iterates to numbers: a string (``"123"``),
    bytes (``b"car"``), a dict, a set, a generator; so are bools (``True`` is no length)."""

    @property
    def rule(self) -> str:
        return "a non-empty list, tuple or 1-D array of positive numbers (m)"

    def _accepts(self, value: Any) -> tuple[bool, Any]:
        if isinstance(value, np.ndarray):
            if value.ndim != 1:
                return False, None
            value = value.tolist()  # numpy's numbers as Python's (a bool array gives bools, refused below)
        elif not isinstance(value, (list, tuple)):
            return False, None
        if not value or not all(is_real(x) for x in value):
            return False, None
        try:
            lengths = tuple(float(x) for x in value)
        except OverflowError:  # an integer beyond float64
            return False, None
        return all(math.isfinite(x) and x > 0 for x in lengths), lengths


@dataclasses.dataclass(frozen=True)
class ContaminationRange(Option):
    """A ``(low, high)`` range of outlier ratios with ``0 <= low <= high < 1``, normalised to floats
    (the range a trainer draws each episode's or frame's contamination from)."""

    @property
    def rule(self) -> str:
        return "a (low, high) pair with 0 <= low <= high < 1"

    def _accepts(self, value: Any) -> tuple[bool, Any]:
        if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
            return False, None
        low, high = value
        if not (is_real(low) and is_real(high)):
            return False, None
        low, high = float(low), float(high)
        return 0.0 <= low <= high < 1.0, (low, high)


class FieldError(ValueError):
    """A config's refusal of one field's value, naming the field in structured form as well as in words.

    The message is ``prefix + subject + rule``: ``subject`` is how it names the field (the field's
    own name unless given, e.g. ``"every budget"``; empty for a message that starts with no name, whose
    ``rule`` is then all of it) and ``rule`` what it says of the value (``" must be >= 2"``,
    ``"=5 exceeds ..."``). A caller that set the field under another name (a command-line option)
    gives the same message with that name: :meth:`named`.

    Attributes:
        field: the config field refused. subject, rule, prefix: the message's parts, as above.
    """

    def __init__(self, field: str, rule: str, subject: str | None = None, prefix: str = "") -> None:
        self.field, self.rule, self.prefix = field, rule, prefix
        self.subject = field if subject is None else subject
        super().__init__(f"{prefix}{self.subject}{rule}")

    def __reduce__(self):
        # the constructor's arguments, not the message, so that a copy (pickle, a worker's) keeps the field
        return type(self), (self.field, self.rule, self.subject, self.prefix)

    def named(self, name: str) -> str:
        """The message with ``name`` for the field and without the prefix: ``name + rule``, or
        ``"name: rule"`` where the message names no field (an empty ``subject``)."""
        return f"{name}{self.rule}" if self.subject else f"{name}: {self.rule}"


def check_field(field: str, option: Option, value: Any, subject: str | None = None, prefix: str = "") -> Any:
    """``option.check`` of one field's value: the value normalised, or a :class:`FieldError` whose message
    is the one ``option.check`` gives (``"{prefix}SUBJECT must be RULE, got VALUE"``; ``subject`` as in
    :class:`FieldError`, e.g. ``"every budget"`` for one entry of ``budgets``)."""
    subject = field if subject is None else subject
    try:
        return option.check(subject, value, prefix="")
    except OptionError as err:
        rule = err.rule if err.name == subject and err.rule is not None else f": {err}"
        raise FieldError(field, rule, subject=subject, prefix=prefix) from None


def check_fields(declarations: Mapping[str, Option], values: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """:func:`~stereovo.options.check_options` of a config's fields, every one of ``declarations``, in
    their order: the values normalised, or :func:`check_field`'s :class:`FieldError` for the first bad one
    (the message ``check_options`` gives)."""
    return {name: check_field(name, option, values[name], prefix=prefix) for name, option in declarations.items()}


RULES: dict[str, Option] = {
    "sampling": Choice(choices=SAMPLING_MODES),
    "reward_mode": Choice(choices=REWARD_MODES),
    "render_mode": Choice(choices=("rgb_array",), allow_none=True),
    "action_bound": Number(low=0.0, high=MAX_ACTION_BOUND, low_open=True),
    "logit_scale": Number(low=0.0, low_open=True),
    "success_bonus": Number(low=0.0, high=1.0),
    # Rewards are clipped to [-1, 1]: a cost above 1 per hypothesis would pin every reward at the floor.
    "hypothesis_cost": Number(low=0.0, high=1.0),
    "failure_reward": Number(low=-1.0, high=1.0),
    "max_correspondences": Integer(low=1, high=MAX_COUNT, allow_none=True),
    "kitti_lengths": Lengths(),
    "estimator_noise_sigma": dataclasses.replace(ESTIMATOR_OPTION_RULES["noise_sigma"], allow_none=True),
    "budget": dataclasses.replace(ESTIMATOR_OPTION_RULES["budget"], allow_none=True),
    "batch_size": dataclasses.replace(ESTIMATOR_OPTION_RULES["batch_size"], allow_none=True),
    "max_hypotheses": Integer(low=1, high=10**6),  # a frame keeps an (H, N) bool inlier mask per hypothesis
}
"""One declaration per environment keyword (:mod:`stereovo.options`). ``batch_size`` is the
hypotheses fitted together: per vectorised batch in :class:`~vo_gym.env.StereoVOEnv`, per step
in :class:`~vo_gym.adaptive_env.StereoVOAdaptiveEnv`; None means all of them in one batch
(the ``budget``, or ``max_hypotheses``)."""


def check_settings(owner: str, **given: Any) -> dict[str, Any]:
    """``given`` (names of :data:`RULES`) checked and normalised, numbers as floats.

    Also the rules between two of them: with ``sampling="prosac"``, ``logit_scale`` must be 1;
    otherwise ``action_bound * logit_scale <= 300`` when both are given.

    Raises:
        ValueError: ``"{owner}: NAME must be RULE, got VALUE"`` for the first bad value.
    """
    checked = check_options(RULES, given, prefix=f"{owner}: ")
    for name, value in checked.items():
        if isinstance(RULES[name], Number) and value is not None:
            checked[name] = float(value)
    if checked.get("sampling") == "prosac":
        # the order is argsort(-a): a positive scale changes no ranking and no weight is exponentiated,
        # so a scale other than 1 would be accepted and ignored
        if checked.get("logit_scale", 1.0) != 1.0:
            raise ValueError(f"{owner}: logit_scale must be 1 with sampling='prosac' (its order ranks the action "
                             "values, which no positive scale changes; the scale applies to sampling='guided'), "
                             f"got {given['logit_scale']!r}")
    elif "action_bound" in checked and "logit_scale" in checked:
        product = checked["action_bound"] * checked["logit_scale"]
        if product > MAX_LOGIT:
            raise ValueError(f"{owner}: action_bound * logit_scale must be <= 300 (weights exp(+-300) stay "
                             f"representable), got {product:g}")
    return checked


def simulation_config(owner: str, fields: Mapping[str, Any]) -> SimulationConfig:
    """The :class:`SimulationConfig` of ``fields`` (a subset of :data:`SIMULATOR_KEYWORDS`; ``camera``
    None means the KITTI-like :class:`StereoCamera`).

    Raises:
        ValueError: ``"{owner}: invalid simulator setting: ..."`` naming the field.
    """
    fields = dict(fields)
    if fields.get("camera", None) is None:
        fields["camera"] = StereoCamera()
    try:
        return SimulationConfig(**fields)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{owner}: invalid simulator setting: {err}") from None


def observation_rows(owner: str, max_correspondences: int | None, n_correspondences: int) -> int:
    """The observation's rows: ``max_correspondences`` (checked), None meaning ``n_correspondences``.

    Raises:
        ValueError: fewer rows than a frame's matches.
    """
    if max_correspondences is None:
        return n_correspondences
    if max_correspondences < n_correspondences:
        raise ValueError(
            f"{owner}: max_correspondences={max_correspondences} is smaller than "
            f"n_correspondences={n_correspondences}: every frame has exactly n_correspondences matches and all must fit"
        )
    return max_correspondences


def estimator_noise(owner: str, estimator_noise_sigma: float | None, noise_sigma: float) -> float:
    """The pixel noise the estimator and the features assume (px): ``estimator_noise_sigma``, or the
    simulator's ``noise_sigma`` when it is None.

    Raises:
        ValueError: None on noise-free frames.
    """
    if estimator_noise_sigma is not None:
        return float(estimator_noise_sigma)
    if noise_sigma <= 0:
        raise ValueError(
            f"{owner}: noise_sigma=0 (noise-free frames) needs estimator_noise_sigma > 0: "
            "the estimator's gates and the features' uncertainties need a positive pixel noise"
        )
    return float(noise_sigma)


def estimator_settings(owner: str, cls: type, method: str, options: Mapping[str, Any], fixed: Mapping[str, Any],
                       sampling: str | None = None, also_known: Iterable[str] = (),
                       refused: Mapping[str, str] | None = None, reward_mode: str | None = None,
                       given_fixed: Iterable[str] = ()) -> tuple[MethodSpec, EstimatorOptions, dict[str, Any]]:
    """The method, its :class:`EstimatorOptions` and its own options, validated by their declarations
    (never by running the method).

    Args:
        owner: the environment's name, the messages' prefix. cls: its class (for did-you-mean hints).
        method: a registered method name.
        options: the user's estimator keywords; the environments' defaults are
            :data:`DEFAULT_ESTIMATOR_OPTIONS`.
        fixed: the options the environment sets itself (``noise_sigma``, ...), which the user
            passes through the environment's own keywords, not here.
        sampling: ``"guided"`` (priors) or ``"prosac"`` (an order): checks that the method takes it.
        also_known: further keywords the environment accepts (for the hints).
        refused: shared options the environment has no use for, each with why (it would ignore them):
            refused when given and left out of the options an error lists.
        reward_mode: the environment's; the options its reward reads (:func:`read_by_reward`) are the
            environment's, never refused as unread by the method.
        given_fixed: those of ``fixed`` that the user gave through the environment's own keywords
            (``batch_size``), refused like ``options`` where the method would not read them.

    Raises:
        TypeError: a keyword that is no option of the method, or a refused one (naming it, its value
            and why). ValueError: a bad value, named, or an option the method would not read with these
            settings (:func:`stereovo.estimation.unread_options`: ``confidence`` under a fixed budget,
            ``least_squares_refit`` with ``refine``, ...), naming it, its value and why; only the
            user's ``options`` and ``given_fixed`` are looked at (the environment's defaults never are).
    """
    refused = dict(refused or {})
    given_refused = [name for name in options if name in refused]
    if given_refused:
        raise TypeError(f"{owner}: " + "; ".join(f"{name}={options[name]!r} does not apply: {refused[name]}"
                                                 for name in given_refused))
    try:
        spec = method_spec(method)
    except ValueError as err:
        raise ValueError(f"{owner}: method: {err}") from None
    # the environment's own keywords never reach here (a constructor parameter takes them)
    allowed = sorted((SHARED_OPTIONS - set(fixed) - set(refused) - set(constructor_keywords(cls)))
                     | set(spec.extra_options))
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise TypeError(
            f"{owner} got unexpected keyword argument(s) {unknown}: not an environment or simulator "
            f"argument nor an option of estimator method {method!r} (its options: {allowed})"
            f"{keyword_hint(unknown, cls, [*allowed, *also_known])}"
        )
    # The values first, then the sampling input, then the options the method would not read, in the
    # environment's words (validate_options would refuse the last before the sampling input is known,
    # and would count the environment's defaults as given).
    try:
        shared, extra = split_options(spec, {**DEFAULT_ESTIMATOR_OPTIONS, **options, **fixed})
    except (TypeError, ValueError) as err:
        raise ValueError(f"{owner}: invalid estimator setting: {err}") from None
    if sampling is not None:
        try:
            spec.check_inputs(priors=sampling == "guided", order=sampling == "prosac")
        except ValueError as err:
            raise ValueError(f"{owner}: estimator method {method!r} with sampling={sampling!r}: {err}") from None
    # the adaptive environment (sampling None) steers with weights: no order either
    given = {**{name: fixed[name] for name in given_fixed}, **options}
    own = read_by_reward(reward_mode)
    unread = unread_options(spec.name, shared, [name for name in given if name not in own],
                            order=sampling == "prosac", extra=extra)
    if unread:
        for name in unread.keys() & REWARD_OPTIONS.keys():
            unread[name] += (f"; the environment's reward reads it with reward_mode={REWARD_OPTIONS[name]!r} only, got "
                             f"reward_mode={reward_mode!r}")
        raise ValueError(f"{owner}: {unread_message(unread, given)}")
    return spec, shared, extra


def read_by_reward(reward_mode: str | None) -> frozenset[str]:
    """The estimator options the reward of ``reward_mode`` reads itself (:data:`vo_gym.rewards.REWARD_OPTIONS`):
    the environment passes them on only to a method that reads them too."""
    return frozenset(name for name, mode in REWARD_OPTIONS.items() if mode == reward_mode)


def check_reset_options(owner: str, options: Any) -> None:
    """``reset(options=...)`` of the environments, which take none: None or an empty dict pass.

    Raises:
        ValueError: anything else (a dict with keys, a string, a list, ...), naming ``options`` and the value.
    """
    if options is None or (isinstance(options, dict) and not options):
        return
    raise ValueError(f"{owner}: reset() takes no options (None or an empty dict; the episode is drawn from the "
                     f"seed alone), got options={value_repr(options)}")
