"""The sweep file: reading it safely and checking it key by key into a :class:`SweepSpec`.

A sweep file (YAML, read by a ``yaml.SafeLoader`` that also refuses anchors, aliases and deep nesting: no
file can run code or exhaust memory; see :func:`load_sweep`) holds:

- ``name``: the sweep's folder under ``runs/sweep/`` (one path component; default: the file's name);
- ``algo``: ``ngransac`` (:class:`agents.ngransac.NGRansacTrainer`) or ``ppo`` (:mod:`agents.ppo`);
- ``fixed``: trainer config fields shared by every trial (``frames`` / ``timesteps`` is the
  training length);
- ``space``: one search axis per config field: ``{grid: [...]}`` (every value, crossed with the
  other grid axes), ``{choice: [...]}``, ``{uniform: [lo, hi]}``, ``{loguniform: [lo, hi]}``,
  ``{randint: [lo, hi]}`` (random, drawn per sample); ``seed`` is an axis like any other;
- ``samples``: how many times the grid is repeated (random axes get a new draw each time), 1 to
  :data:`MAX_SAMPLES` (1000; default 1);
- ``report_every``: trainer steps (NG-RANSAC frames, PPO environment steps) between reports, at most
  :data:`~agents.training_limits.MAX_TRAINING_STEPS` (the trainers' own counts have the same cap);
- ``metric``: the held-out success rate at a budget: the environment ``env_id`` (a registered step
  id, :data:`vo_gym.registration.STEP`, such as ``vo_gym/StereoVO-v0``; so must a PPO sweep's own
  ``env_id`` be) with ``budget``
  hypotheses per frame, contamination ``epsilon``, ``n`` correspondences, ``episodes`` episodes of
  ``frames_per_episode`` frames from seeds ``seed + i`` (kept away from training seeds), the
  trained policy acting through :func:`agents.rollout.success_rate`, as ``vo-gym evaluate`` does
  (``budget`` and ``n`` within what the environment takes, ``frames_per_episode`` at most
  :data:`~stereovo.simulation.config.MAX_FRAMES`, ``episodes`` at most :data:`MAX_METRIC_EPISODES`);
- ``scheduler``: ``{type: asha, grace_period: G, reduction_factor: R}`` (default: ASHA early
  stopping on the metric, rungs counted in reports) or ``{type: fifo}`` (every trial to the end);
- ``search_seed``: seeds the draws of the random axes (default 0): the same file gives the same trials.

Numbers with an exponent need a dot and a signed exponent: YAML 1.1, which PyYAML reads, takes
``1e-4`` for a string, and ``1.0e-4`` for the number (a quoted number is a string too). Such text in a
numeric field is refused, and the message says how to write it (:func:`yaml_number_hint`).

:func:`load_sweep` reads a file, :func:`parse_sweep` checks a loaded mapping; both raise a one-line
``ValueError`` naming the file, the key and the value. Running the sweep is :mod:`agents.sweep`'s.
"""

from __future__ import annotations

import collections.abc
import math
import os
import re
import types
import typing
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from agents.training_limits import LEARNING_RATE, MAX_TRAINING_STEPS
from stereovo.estimation.estimator_options import MAX_COUNT
from stereovo.options import (
    Integer,
    Number,
    Option,
    OptionError,
    check_options,
    is_finite_real,
    is_integer,
    value_repr,
)
from stereovo.simulation.config import MAX_CORRESPONDENCES, MAX_FRAMES

__all__ = [
    "ALGOS",
    "AXIS_KINDS",
    "METRIC",
    "MAX_FILE_BYTES",
    "MAX_DEPTH",
    "MAX_NAME",
    "MAX_SAMPLES",
    "MAX_METRIC_EPISODES",
    "MetricSpec",
    "SweepSpec",
    "FieldRule",
    "field_rule",
    "field_rules",
    "load_sweep",
    "parse_sweep",
    "yaml_number_hint",
]

ALGOS = ("ngransac", "ppo")
AXIS_KINDS = ("grid", "choice", "uniform", "loguniform", "randint")
METRIC = "success"
TOP_KEYS = {"name", "algo", "fixed", "space", "samples", "report_every", "metric", "scheduler", "search_seed"}
MAX_FILE_BYTES = 1 << 20
"""A sweep file is a few dozen lines; a larger one is refused before it is parsed."""
MAX_DEPTH = 32
"""How deeply a sweep file's collections may nest (the deepest a valid file needs is 4)."""
MAX_NAME = 100
"""The longest ``name`` (it is the folder under ``runs/sweep/``)."""
MAX_SAMPLES = 1000
"""The most repeats of the grid (``samples``). Each repeat runs every grid point again, and every trial keeps
its folder and a checkpoint per report; the cluster-sized ``configs/sweeps/realistic.yaml`` repeats its grid
twice, so a thousand is far past any sweep that finishes, and a larger number is a typo."""


MAX_METRIC_EPISODES = 10_000
"""The most held-out episodes of the metric: it is evaluated at every report of every trial, and ten
thousand episodes at each report already outlast any training they would judge."""


_METRIC_RULES: dict[str, Option] = {
    # as the environment and the simulator bound them, so a typo fails here and not inside a trial
    "budget": Integer(low=1, high=MAX_COUNT),
    "n": Integer(low=3, high=MAX_CORRESPONDENCES),
    "frames_per_episode": Integer(low=1, high=MAX_FRAMES),
    "episodes": Integer(low=1, high=MAX_METRIC_EPISODES),
    "seed": Integer(low=0),
    "epsilon": Number(low=0.0, high=1.0, high_open=True),
}
"""The declarations :class:`MetricSpec` is checked by (:mod:`stereovo.options`)."""

_ASHA_RULES: dict[str, Option] = {
    "scheduler.grace_period": Integer(low=1),
    "scheduler.reduction_factor": Number(low=1.0, low_open=True),
}
_COUNT_RULES: dict[str, Option] = {
    "samples": Integer(low=1, high=MAX_SAMPLES),
    "report_every": Integer(low=1, high=MAX_TRAINING_STEPS),
    "search_seed": Integer(low=0),
}
"""The declarations of the file's own numbers (the ASHA scheduler's, then the top's), by key as messages name them."""

_SEARCHED_RULES: dict[str, Option] = {"learning_rate": LEARNING_RATE}
"""Trainer config fields whose every searched value is checked by the trainer's declaration: each grid or
choice value and both bounds of a range (the trainer's config checks the fixed value and the first point of
the space only, and a trial drawn past the cap would fail after the sweep had started)."""


@dataclass(frozen=True)
class MetricSpec:
    """Held-out success rate at a budget (see the module doc)."""

    env_id: str = "vo_gym/StereoVO-v0"
    epsilon: float = 0.8
    budget: int = 16
    n: int = 500
    episodes: int = 5
    frames_per_episode: int = 10
    seed: int = 10_000

    def __post_init__(self) -> None:
        check_options(_METRIC_RULES, vars(self), prefix="sweep metric.", only=_METRIC_RULES)

    def env_kwargs(self) -> dict[str, Any]:
        return {"n_frames": self.frames_per_episode, "n_correspondences": self.n,
                "outlier_ratio": float(self.epsilon), "budget": self.budget}

    def seeds(self) -> list[int]:
        return [self.seed + i for i in range(self.episodes)]

    def describe(self) -> str:
        return (f"held-out success at eps {self.epsilon:g} with {self.budget} hypotheses, N {self.n},"
                f" {self.episodes} x {self.frames_per_episode} frames from seed {self.seed}")


@dataclass(frozen=True)
class SweepSpec:
    """A parsed sweep file (see the module doc); build it with :func:`parse_sweep`."""

    name: str
    algo: str
    fixed: Mapping[str, Any]
    space: Mapping[str, Mapping[str, list]]
    samples: int
    report_every: int
    metric: MetricSpec
    scheduler: Mapping[str, Any] = field(default_factory=lambda: {"type": "asha"})
    search_seed: int = 0  # seeds the draws of the random axes: the same file gives the same trials

    @property
    def total_steps(self) -> int:
        """Training length of one trial: NG-RANSAC frames or PPO environment steps."""
        return int(self.trainer_config({}).frames if self.algo == "ngransac" else self.trainer_config({}).timesteps)

    @property
    def n_reports(self) -> int:
        """Reports of one trial: ``ceil(total_steps / report_every)``, in integers (no float to overflow)."""
        return max(1, -(-self.total_steps // self.report_every))

    def trainer_config(self, params: Mapping[str, Any]):
        """The trainer's config for one trial's parameters (validated by the trainer's config class)."""
        values = {**self.fixed, **params}
        if self.algo == "ngransac":
            # Tune keeps the best checkpoint; reloading the best weights inside the trainer would undo training
            # between reports.
            values.setdefault("keep_best", False)
            values.setdefault("eval_every", self.report_every)
            values.setdefault("eval_frames", 10)
        else:
            values.setdefault("eval_every", 10 ** 9)  # the sweep's metric is the evaluation; SB3's own is not needed
            values.setdefault("checkpoint_every", 10 ** 9)
        return _build(_config_class(self.algo), values)

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["fixed"], d["space"], d["scheduler"] = dict(self.fixed), {k: dict(v) for k, v in self.space.items()}, \
            dict(self.scheduler)
        return d


def _build(cls, values: Mapping[str, Any]):
    import dataclasses

    known = {f.name for f in dataclasses.fields(cls)}
    unknown = set(values) - known
    if unknown:
        raise ValueError(f"sweep: unknown {cls.__name__} field(s) {_keys(unknown)}; known: {', '.join(sorted(known))}")
    # YAML has no tuples: a list given for a field typed as a tuple becomes one, as the field's type says
    hints = typing.get_type_hints(cls)
    return cls(**{key: tuple(value) if isinstance(value, list) and _is_tuple_type(hints[key]) else value
                  for key, value in values.items()})


def _is_tuple_type(annotation: Any) -> bool:
    """Whether ``annotation`` is ``tuple[...]``, alone or in a union (``tuple[float, float] | None``)."""
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        return any(_is_tuple_type(arg) for arg in typing.get_args(annotation))
    return annotation is tuple or typing.get_origin(annotation) is tuple


def _key(key: Any) -> str:
    """A key for a message: as written when it is a short string, else abbreviated."""
    return key if isinstance(key, str) and len(key) <= 60 and key.isprintable() else value_repr(key, 60)


def _keys(keys: Any) -> str:
    """A list of keys for a message (keys of any type, sorted by their text, abbreviated)."""
    return value_repr(sorted(keys, key=lambda k: (not isinstance(k, str), str(k)[:200])))


@dataclass(frozen=True)
class FieldRule:
    """How a sweep file's value for one trainer config field is checked, before the trainer compares it."""

    rule: str
    """The accepted values in words, as the message says them (``"an integer"``)."""
    accepts: Callable[[Any], bool]
    optional: bool = False
    """null (``None``) is accepted too: the field's type is ``X | None``."""

    def check(self, source: str, where: str, value: Any) -> None:
        """Raise a ``ValueError`` naming ``source``, the key ``where`` and the value when it is not accepted."""
        if self.optional and value is None:
            return
        if not self.accepts(value):
            raise ValueError(f"{source}: {where} must be {self.rule}{' or null' if self.optional else ''},"
                             f" got {value_repr(value)}{yaml_number_hint(value, integer=self.rule == 'an integer')}")


_YAML_EXPONENT = re.compile(r"([-+]?)(\d+)(?:\.(\d*))?[eE]([-+]?)(\d+)")


def yaml_number_hint(value: Any, integer: bool = False) -> str:
    """What a message adds for text that reads as a number, or for a list holding such text: YAML 1.1,
    which PyYAML reads, takes ``1e-4`` for a string (its floats need a dot and a signed exponent,
    ``1.0e-4``), and a quoted number is a string too. Returns `` (YAML reads '1e-4' as text; write
    1.0e-4 ...)`` naming the spelling that reads as the number (``integer``: the digits of a whole
    number), or ``""`` for anything else."""
    if isinstance(value, (list, tuple)):
        return next((hint for hint in (yaml_number_hint(v, integer) for v in value[:16]) if hint), "")
    if not isinstance(value, str) or len(value) > 60:
        return ""
    try:
        number = float(value)
    except ValueError:
        return ""
    if not math.isfinite(number):
        return ""
    if integer and number.is_integer():
        return f" (YAML reads {value!r} as text; write {int(number)})"
    match = _YAML_EXPONENT.fullmatch(value.strip())
    if match:
        sign, whole, fraction, exponent_sign, exponent = match.groups()
        spelled = f"{sign}{whole}.{fraction or '0'}e{exponent_sign or '+'}{exponent}"
        return f" (YAML reads {value!r} as text; write {spelled}: a YAML float needs a dot and a signed exponent)"
    return f" (YAML reads {value!r} as text; write {number!r}, without quotes)"


def _hint(err: OptionError, values: Mapping[str, Any], declarations: Mapping[str, Option]) -> str:
    """:func:`yaml_number_hint`'s words for the value that ``err`` refused: the one of ``values`` under the
    key that ``err`` names (its ``name``, one of ``declarations``, whose type says whether a whole number
    is due), or ``""``."""
    if err.name not in values or err.name not in declarations:
        return ""
    return yaml_number_hint(values[err.name], integer=isinstance(declarations[err.name], Integer))


def _finite_list(length: int) -> Callable[[Any], bool]:
    return lambda v: isinstance(v, (list, tuple)) and len(v) == length and all(map(is_finite_real, v))


# Keyed by the type itself, not its spelling: ``int``, ``typing.Optional[int]`` and ``int | None`` all land here.
_SCALAR_RULES: dict[type, tuple[str, Callable[[Any], bool]]] = {
    int: ("an integer", is_integer),
    float: ("a finite number", is_finite_real),
    bool: ("true or false", lambda v: isinstance(v, bool)),
    str: ("a string", lambda v: isinstance(v, str)),
}


def field_rule(annotation: Any) -> FieldRule | None:
    """The check for a trainer config field of type ``annotation`` (a type, as :func:`typing.get_type_hints`
    gives it, never its text): ``int``, ``float``, ``bool``, ``str``, a fixed-length tuple of floats
    (written as a YAML list), a dict or mapping, or any of these ``| None``. ``Any`` is not checked (None).

    Raises:
        TypeError: a type with no rule here (a string annotation included), so that a trainer field of a new
            type fails the sweep's tests instead of going unchecked.
    """
    if annotation is Any:
        return None
    base, optional = annotation, False
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        members = typing.get_args(annotation)
        rest = [m for m in members if m is not type(None)]
        if len(rest) == 1 and len(rest) < len(members):
            base, optional = rest[0], True
    origin, args = typing.get_origin(base), typing.get_args(base)
    if isinstance(base, type) and base in _SCALAR_RULES:
        rule, accepts = _SCALAR_RULES[base]
    elif origin is tuple and args and all(a is float for a in args):
        rule, accepts = f"a list of {len(args)} finite numbers", _finite_list(len(args))
    elif base in (dict, collections.abc.Mapping) or origin in (dict, collections.abc.Mapping):
        rule, accepts = "a mapping", lambda v: isinstance(v, dict)
    else:
        raise TypeError(f"sweep: no check for a trainer config field of type {annotation!r}")
    return FieldRule(rule, accepts, optional)


def field_rules(config_class: type) -> dict[str, FieldRule | None]:
    """The check for every field of a trainer config dataclass, by field name (from its resolved types)."""
    import dataclasses

    hints = typing.get_type_hints(config_class)
    rules = {}
    for f in dataclasses.fields(config_class):
        try:
            rules[f.name] = field_rule(hints[f.name])
        except TypeError as err:
            raise TypeError(f"{err} ({config_class.__name__}.{f.name})") from None
    return rules


def _config_class(algo: str) -> type:
    if algo == "ngransac":
        from agents.ngransac import NGRansacConfig

        return NGRansacConfig
    from agents.ppo.config import PPOConfig

    return PPOConfig


def _check_name(source: str, name: Any, given: bool) -> str:
    """``name`` is the folder ``runs/sweep/NAME``: one plain path component, nothing that leaves that folder."""
    what = "name" if given else f"name (taken from the file name; set name:)"
    if isinstance(name, int) and not isinstance(name, bool):
        name = str(name)
    if not isinstance(name, str):
        raise ValueError(f"{source}: {what} must be a string, got {value_repr(name)}")
    if (not name or len(name) > MAX_NAME or name.startswith(".") or any(c in name for c in "/\\:")
            or not name.isprintable()):
        raise ValueError(f"{source}: {what} must be a single folder name of 1 to {MAX_NAME} characters without"
                         f" '/', '\\', ':' or a leading '.', got {value_repr(name)}")
    return name


def parse_sweep(data: Any, source: str = "sweep") -> SweepSpec:
    """A :class:`SweepSpec` from a mapping (a loaded YAML document); errors name the key and the value.

    Raises:
        ValueError: a missing or unknown key, an unknown algo or axis kind, a bad value, or a trainer
            config the trainer refuses (checked here for the first point of the space).
    """
    if not isinstance(data, dict):
        raise ValueError(f"{source}: expected a mapping at the top, got {type(data).__name__}")
    unknown = set(data) - TOP_KEYS
    if unknown:
        raise ValueError(f"{source}: unknown key(s) {_keys(unknown)}; known: {', '.join(sorted(TOP_KEYS))}")
    algo = data.get("algo")
    if not isinstance(algo, str) or algo not in ALGOS:
        raise ValueError(f"{source}: algo must be one of {ALGOS}, got {value_repr(algo)}")
    name = _check_name(source, data["name"] if data.get("name") is not None else Path(source).stem,
                       data.get("name") is not None)
    rules = field_rules(_config_class(algo))
    fixed = data.get("fixed") or {}
    if not isinstance(fixed, dict):
        raise ValueError(f"{source}: fixed must be a mapping, got {value_repr(fixed)}")
    for key, value in fixed.items():
        rule = rules.get(key) if isinstance(key, str) else None  # an unknown field: the trainer's config names it
        if rule is not None:
            rule.check(source, f"fixed.{_key(key)}", value)
    space_in = data.get("space") or {}
    if not isinstance(space_in, dict) or not space_in:
        raise ValueError(f"{source}: space must be a non-empty mapping of field -> axis, got {value_repr(space_in)}")
    space: dict[str, dict[str, list]] = {}
    for key, axis in space_in.items():
        where = f"space.{_key(key)}"
        if not isinstance(axis, dict) or len(axis) != 1:
            raise ValueError(f"{source}: {where} must be one of {{kind: values}} with kind in {AXIS_KINDS},"
                             f" got {value_repr(axis)}")
        [(kind, values)] = axis.items()
        if not isinstance(kind, str) or kind not in AXIS_KINDS:
            raise ValueError(f"{source}: {where}: unknown axis kind {value_repr(kind)}; known: {', '.join(AXIS_KINDS)}")
        where += f".{kind}"
        if not isinstance(values, list) or not values:
            raise ValueError(f"{source}: {where} must be a non-empty list, got {value_repr(values)}")
        if kind in ("uniform", "loguniform", "randint"):
            if len(values) != 2 or not all(map(is_finite_real, values)) or not values[0] < values[1]:
                raise ValueError(f"{source}: {where} must be [low, high] finite numbers with low < high,"
                                 f" got {value_repr(values)}{yaml_number_hint(values)}")
            if kind == "loguniform" and values[0] <= 0:
                raise ValueError(f"{source}: {where} needs low > 0, got {value_repr(values)}")
            if kind == "randint" and not all(isinstance(v, int) for v in values):
                raise ValueError(f"{source}: {where} must be [low, high] integers, got {value_repr(values)}")
        else:
            rule = rules.get(key) if isinstance(key, str) else None
            for i, value in enumerate(values):
                if rule is not None:
                    rule.check(source, f"{where}[{i}]", value)
        if isinstance(key, str) and key in _SEARCHED_RULES:
            for i, value in enumerate(values):
                _SEARCHED_RULES[key].check(f"{where}[{i}]", value, prefix=f"{source}: ")
        space[key] = {kind: list(values)}
    if algo == "ppo":  # the id PPO trains in: a step environment, as the metric's
        ids = [("fixed.env_id", fixed["env_id"])] if isinstance(fixed.get("env_id"), str) else []
        for kind, values in space.get("env_id", {}).items():
            ids += [(f"space.env_id.{kind}[{i}]", v) for i, v in enumerate(values) if isinstance(v, str)]
        for where, env_id in ids:
            _check_step_env(source, where, env_id, "PPO trains in one of")
    clash = set(space) & set(fixed)
    if clash:
        raise ValueError(f"{source}: {_keys(clash)} both fixed and searched")
    metric_in = data.get("metric") or {}
    if not isinstance(metric_in, dict):
        raise ValueError(f"{source}: metric must be a mapping, got {value_repr(metric_in)}")
    unknown = set(metric_in) - set(MetricSpec.__dataclass_fields__) - {"name"}
    if unknown:
        raise ValueError(f"{source}: unknown metric key(s) {_keys(unknown)}; known: "
                         f"{', '.join(MetricSpec.__dataclass_fields__)}")
    if metric_in.get("name", METRIC) != METRIC:
        raise ValueError(f"{source}: metric.name must be {METRIC!r} (held-out success),"
                         f" got {value_repr(metric_in['name'])}")
    if not isinstance(metric_in.get("env_id", ""), str):
        raise ValueError(f"{source}: metric.env_id must be a string, got {value_repr(metric_in['env_id'])}")
    if "env_id" in metric_in:
        _check_step_env(source, "metric.env_id", metric_in["env_id"],
                        "the metric steps a one-shot policy through one of")
    try:
        metric = MetricSpec(**{k: v for k, v in metric_in.items() if k != "name"})
    except OptionError as err:  # it names the field: the hint is for that field's value
        raise ValueError(f"{source}: {_short(err)}{_hint(err, metric_in, _METRIC_RULES)}") from None
    scheduler = data.get("scheduler") or {"type": "asha"}
    if not isinstance(scheduler, dict):
        raise ValueError(f"{source}: scheduler must be a mapping, got {value_repr(scheduler)}")
    scheduler = dict(scheduler)
    kind = scheduler.setdefault("type", "asha")
    if not isinstance(kind, str) or kind not in ("asha", "fifo"):
        raise ValueError(f"{source}: scheduler.type must be 'asha' or 'fifo', got {value_repr(kind)}")
    allowed = {"type", "grace_period", "reduction_factor"} if kind == "asha" else {"type"}
    unknown = set(scheduler) - allowed
    if unknown:
        raise ValueError(f"{source}: unknown scheduler key(s) {_keys(unknown)} for {kind};"
                         f" known: {', '.join(sorted(allowed))}")
    if kind == "asha":
        scheduler.setdefault("grace_period", 1)
        scheduler.setdefault("reduction_factor", 2)
    # the numbers of the file's top and of its scheduler, by key as the messages name them
    rules = {**(_ASHA_RULES if kind == "asha" else {}), **_COUNT_RULES}
    given = {**{f"scheduler.{k}": v for k, v in scheduler.items()}, "samples": data.get("samples", 1),
             "report_every": data.get("report_every"), "search_seed": data.get("search_seed", 0)}
    try:
        checked = check_options(rules, given, prefix="", only=rules)
    except OptionError as err:  # it names the key: the hint is for that key's value
        raise ValueError(f"{source}: {err}{_hint(err, given, rules)}") from None
    if kind == "asha":
        scheduler["grace_period"] = checked["scheduler.grace_period"]
    samples, report_every, search_seed = checked["samples"], checked["report_every"], checked["search_seed"]
    spec = SweepSpec(
        name=name, algo=algo, fixed=dict(fixed), space=space, samples=samples, report_every=report_every,
        metric=metric, scheduler=scheduler, search_seed=search_seed,
    )
    first = {key: next(iter(axis.values()))[0] for key, axis in space.items()}
    for key, axis in space.items():
        if "randint" in axis:
            first[key] = int(first[key])
    try:
        spec.trainer_config(first)
    except (TypeError, ValueError, ArithmeticError) as err:
        raise ValueError(f"{source}: {_keyed(err, fixed, space)}") from None
    return spec


def _keyed(err: BaseException, fixed: Mapping[str, Any], space: Mapping[str, Any]) -> str:
    """A trainer config's refusal naming the sweep file's key that set the field, where the refusal is a
    :class:`~vo_gym.settings.FieldError` (which names its field; the trainer's prefix, ``PPO:``, is left
    out): ``fixed.frames must ...``, ``space.learning_rate (its first value) must ...``. Any other
    refusal, or one of a field the file does not set, keeps its own words (on one line)."""
    from vo_gym.settings import FieldError

    if isinstance(err, FieldError) and err.field in fixed:
        return _short(err.named(f"fixed.{err.field}"))
    if isinstance(err, FieldError) and err.field in space:
        return _short(err.named(f"space.{err.field} (its first value)"))
    return _short(err)


def _check_step_env(source: str, where: str, env_id: str, purpose: str) -> None:
    """The id at ``where`` (``metric.env_id``; a PPO sweep's ``fixed.env_id`` or a searched one) must be a
    registered step environment (:data:`vo_gym.registration.STEP`): the metric rolls a one-shot policy
    through it (:func:`agents.rollout.success_rate`) and PPO trains in it, which an in-frame or image
    id, an unknown one or another package's cannot take. ``purpose`` ends the message."""
    from vo_gym.names import did_you_mean
    from vo_gym.registration import IMAGES, IN_FRAME, OTHER, STEP, env_kind, step_ids

    kind = env_kind(env_id)
    if kind == STEP:
        return
    what = {None: "not a registered environment", IMAGES: "an image environment",
            IN_FRAME: "an in-frame environment (its action also stops the search)"}
    what = what.get(kind, "not a vo_gym step environment")
    hint = did_you_mean(env_id, step_ids()) if kind in (None, OTHER) else ""
    raise ValueError(f"{source}: {where} {value_repr(env_id)} is {what}{hint}; {purpose}: {', '.join(step_ids())}")


def _short(err: BaseException, limit: int = 400) -> str:
    """An exception's message on one line, cut where it is long (a message never grows with the file)."""
    text = " ".join(str(err).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _safe_loader():
    """A ``yaml.SafeLoader`` that also refuses anchors and aliases (a sweep file needs none, and nine
    nested aliases expand to a billion nodes) and collections nested deeper than :data:`MAX_DEPTH`."""
    import yaml

    class SweepLoader(yaml.SafeLoader):
        _depth = 0

        def compose_node(self, parent, index):
            event = self.peek_event()
            if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None) is not None:
                raise yaml.YAMLError(f"line {event.start_mark.line + 1}: anchors and aliases (&name, *name, <<) are"
                                     " not allowed in a sweep file; write the values out")
            if isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
                if self._depth >= MAX_DEPTH:
                    raise yaml.YAMLError(f"line {event.start_mark.line + 1}: nested more than {MAX_DEPTH} deep")
                self._depth += 1
                try:
                    return super().compose_node(parent, index)
                finally:
                    self._depth -= 1
            return super().compose_node(parent, index)

    return SweepLoader


def load_sweep(path: str | os.PathLike) -> SweepSpec:
    """Read and check a sweep file: safe YAML only (tags that would build objects, anchors and aliases,
    and nesting past :data:`MAX_DEPTH` are refused), at most :data:`MAX_FILE_BYTES`, UTF-8.

    Raises:
        FileNotFoundError: no such file.
        ValueError: a directory, unreadable, too large, not UTF-8, not YAML, or not a valid sweep (the
            message names the file and the key).
    """
    import yaml

    path = Path(path)
    shown = str(path) if len(str(path)) <= 200 else str(path)[:197] + "..."  # the file, as messages name it
    if not path.exists():
        raise FileNotFoundError(f"sweep file {shown!r} does not exist")
    if path.is_dir():
        raise ValueError(f"{shown}: is a directory, not a sweep file")
    if not path.is_file():
        raise ValueError(f"{shown}: not a regular file")
    try:
        with path.open("rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
    except OSError as err:
        raise ValueError(f"{shown}: cannot read ({err.strerror or err})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise ValueError(f"{shown}: larger than {MAX_FILE_BYTES // 1024} KiB; a sweep file is a few dozen lines")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise ValueError(f"{shown}: not UTF-8 text (byte {err.start}: {raw[err.start:err.start + 1]!r})") from None
    try:
        data = yaml.load(text, Loader=_safe_loader())  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as err:
        raise ValueError(f"{shown}: not valid YAML ({_short(err, 300)})") from None
    except RecursionError:
        raise ValueError(f"{shown}: not valid YAML (nested too deeply)") from None
    return parse_sweep(data, shown)
