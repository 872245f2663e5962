"""The one contract for options: typed declarations that validate a value and name it on failure.

Every layer that takes settings (the estimator's :class:`~stereovo.estimation.EstimatorOptions`
and each method's own options, :class:`~stereovo.simulation.SimulationConfig`, the environment's
keywords, the command line) declares them with these types, so the same value is accepted or
refused, with the same message, wherever it enters:

- :class:`Integer`: Python or numpy integers only. ``bool`` is refused (``True`` is not a count),
  so is numpy's ``timedelta64`` (an ``np.signedinteger`` to numpy), and so is ``3.0`` or ``1.5``
  (a float that happens to be whole is a sign of a computed value that was meant to be rounded by
  the caller, not here).
- :class:`Boolean`: ``True``/``False`` (or numpy bools) only; ``"no"`` or ``0`` is refused
  (``"no"`` is truthy and would silently act as True).
- :class:`Number`: a real, finite number in a range; ``"0.9"``, ``nan``, ``inf`` and complex
  numbers are refused, and so is an integer too large for a float (``10**400``: no float64 holds
  it, so every computation with it would overflow).
- :class:`Choice`: one of a fixed set of strings; the message lists them.

Arrays have one contract too: :func:`real_array` (a real numeric array of a given shape; as for
:class:`Number`, bools are no numbers, nor are None, dates, durations and strings, though numpy
casts them all to float64).

Each declaration may allow ``None``. :meth:`Option.check` returns the value normalised to a
plain Python ``int``/``float``/``bool``/``str`` (never changing it numerically), or raises
:class:`OptionError` (a ``ValueError``) of the form
``option NAME must be RULE, got VALUE``; VALUE is :func:`value_repr`'s (the ``repr``, abbreviated
when it would be enormous: a 400-digit integer is written ``~1e+400 (an integer of 401 digits)``).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Iterable, Mapping

import numpy as np

__all__ = [
    "OptionError", "Option", "Integer", "Boolean", "Number", "Choice", "check_options", "is_integer", "is_real",
    "is_finite_real", "real_array", "value_repr",
]


class OptionError(ValueError):
    """An option's value breaks its declaration; the message names the option and the value.

    Raised by :meth:`Option.check`, it also carries the message's parts: ``name`` (the option as the
    message names it) and ``rule`` (what it says of the value, after the name: ``" must be ..., got
    ..."``), so that a caller that set the option under another name can say the same of that name;
    both are None where the error was raised otherwise.
    """

    def __init__(self, message: str, name: str | None = None, rule: str | None = None) -> None:
        super().__init__(message)
        self.name, self.rule = name, rule


_NOT_NUMBERS = (bool, np.bool_, np.timedelta64)
"""Types that pass for integers (``True``; numpy's timedelta64 is an ``np.signedinteger``) but are no numbers."""


def is_integer(value: Any) -> bool:
    """A Python or numpy integer, not a bool, not a numpy timedelta64."""
    return isinstance(value, (numbers.Integral, np.integer)) and not isinstance(value, _NOT_NUMBERS)


def is_real(value: Any) -> bool:
    """A real Python or numpy number (int or float), not a bool, not complex, not a string, not a
    numpy timedelta64."""
    return isinstance(value, (numbers.Real, np.integer, np.floating)) and not isinstance(value, _NOT_NUMBERS)


def is_finite_real(value: Any) -> bool:
    """A real number (:func:`is_real`) that is a finite float64: not NaN, not infinite, and no integer
    too large for a float (``math.isfinite`` and ``float()`` raise OverflowError on ``10**400``)."""
    if not is_real(value):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


_REPR_LIMIT = 200  # characters of a value's repr in a message; a longer one is abbreviated
_BIG_INT_BITS = 200  # integers of more bits (some 60 digits) are written by magnitude, not digit by digit


def value_repr(value: Any, limit: int = _REPR_LIMIT) -> str:
    """``repr(value)`` for an error message, abbreviated where it would be enormous.

    An integer of more than some 60 digits is written by its magnitude and number of digits
    (``~1e+400 (an integer of 401 digits)``; Python refuses ``repr`` of an int beyond 4300 digits),
    also inside a short tuple, list or dict; any other repr longer than ``limit`` characters (200) is
    cut (``...``). Never raises.
    """
    if is_integer(value):
        v = int(value)
        if v.bit_length() > _BIG_INT_BITS:
            log = math.log10(abs(v))  # exact enough for a message; the digit count is made exact below
            digits = math.floor(log) + 1
            if abs(v) < 10 ** (digits - 1):
                digits -= 1
            return f"~{'-' if v < 0 else ''}{10 ** (log % 1):.3g}e+{math.floor(log)} (an integer of {digits} digits)"
    elif type(value) in (tuple, list) and len(value) <= 16:
        items = [value_repr(x, limit) for x in value]
        if type(value) is tuple:
            return "(" + ", ".join(items) + ("," if len(items) == 1 else "") + ")"
        return "[" + ", ".join(items) + "]"
    elif type(value) is dict and len(value) <= 16:
        return "{" + ", ".join(f"{value_repr(k, limit)}: {value_repr(v, limit)}" for k, v in value.items()) + "}"
    try:
        text = repr(value)
    except Exception:  # a repr that fails (an int past Python's digit limit inside a container, ...)
        return f"<{type(value).__name__} object>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _fmt(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


@dataclass(frozen=True)
class Option:
    """Base declaration; subclasses define :meth:`_accepts` and :attr:`rule`.

    Attributes:
        allow_none: ``None`` is a valid value (meaning "not set"; the owner's docstring says what it means).
        default: the value an owner that fills in missing options uses (a method's options: the
            registry hands the recipe this value when the caller gives none); None where the owner
            keeps its defaults itself (a dataclass field's default).
        prefix: text before the option's name in messages (e.g. ``"SimulationConfig."``; default ``"option "``).
    """

    allow_none: bool = False
    default: Any = None

    @property
    def rule(self) -> str:  # pragma: no cover - overridden
        raise NotImplementedError

    def describe(self) -> str:
        """The rule in words, as the error message says it."""
        return f"None or {self.rule}" if self.allow_none else self.rule

    def check(self, name: str, value: Any, prefix: str = "option ") -> Any:
        """``value`` normalised to a plain Python type, or :class:`OptionError` naming ``name`` and ``value``."""
        if value is None and self.allow_none:
            return None
        ok, normalised = self._accepts(value)
        if not ok:
            rule = f" must be {self.describe()}, got {value_repr(value)}"
            raise OptionError(f"{prefix}{name}{rule}", name=name, rule=rule)
        return normalised

    def _accepts(self, value: Any) -> tuple[bool, Any]:  # pragma: no cover - overridden
        raise NotImplementedError


@dataclass(frozen=True)
class Integer(Option):
    """An integer in ``[low, high]`` (either bound optional)."""

    low: int | None = None
    high: int | None = None

    @property
    def rule(self) -> str:
        bounds = ([f">= {self.low}"] if self.low is not None else []) + (
            [f"<= {self.high}"] if self.high is not None else [])
        return "an integer" + (" " + " and ".join(bounds) if bounds else "")

    def _accepts(self, value: Any) -> tuple[bool, Any]:
        if not is_integer(value):
            return False, None
        v = int(value)
        ok = (self.low is None or v >= self.low) and (self.high is None or v <= self.high)
        return ok, v


@dataclass(frozen=True)
class Boolean(Option):
    """``True`` or ``False``."""

    @property
    def rule(self) -> str:
        return "True or False"

    def _accepts(self, value: Any) -> tuple[bool, Any]:
        if isinstance(value, (bool, np.bool_)):
            return True, bool(value)
        return False, None


@dataclass(frozen=True)
class Number(Option):
    """A finite real number between ``low`` and ``high``; ``low_open``/``high_open`` exclude the bound."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    unit: str = ""

    @property
    def rule(self) -> str:
        if self.low is not None and self.high is not None:
            left, right = "(" if self.low_open else "[", ")" if self.high_open else "]"
            rule = f"a finite number in {left}{_fmt(self.low)}, {_fmt(self.high)}{right}"
        elif self.low is not None:
            rule = f"a finite number {'>' if self.low_open else '>='} {_fmt(self.low)}"
        elif self.high is not None:
            rule = f"a finite number {'<' if self.high_open else '<='} {_fmt(self.high)}"
        else:
            rule = "a finite number"
        return rule + (f" ({self.unit})" if self.unit else "")

    def _accepts(self, value: Any) -> tuple[bool, Any]:
        if not is_finite_real(value):  # not a number, NaN, inf, or an integer too large for a float
            return False, None
        v = float(value)
        if self.low is not None and (v < self.low or (self.low_open and v == self.low)):
            return False, None
        if self.high is not None and (v > self.high or (self.high_open and v == self.high)):
            return False, None
        # An integer given for a number keeps its type: digests hash the options' values.
        return True, int(value) if is_integer(value) else v


@dataclass(frozen=True)
class Choice(Option):
    """One of ``choices`` (strings)."""

    choices: tuple[str, ...] = ()

    @property
    def rule(self) -> str:
        return "one of " + ", ".join(repr(c) for c in self.choices)

    def _accepts(self, value: Any) -> tuple[bool, Any]:
        if isinstance(value, str) and value in self.choices:
            return True, value
        return False, None


def check_options(declarations: Mapping[str, Option], values: Mapping[str, Any], prefix: str = "option ",
                  only: Iterable[str] | None = None) -> dict[str, Any]:
    """Validate ``values`` (a subset of ``declarations``' keys) and return them normalised.

    Raises:
        OptionError: for the first bad value, naming it.
    """
    names = values.keys() if only is None else only
    return {name: declarations[name].check(name, values[name], prefix) for name in names}


_NOT_NUMBER_KINDS = "bMmUSV"
"""Dtype kinds numpy casts to float64 though they hold no numbers: bool, datetime64, timedelta64,
str, bytes and void (structured)."""

_REAL = object()  # _first_not_real's "all real"


def _first_not_real(elements: Iterable[Any]) -> Any:
    """The first element that is no real number (:func:`is_real`: a bool, None, a string, a date ...), or ``_REAL``."""
    return next((x for x in elements if not is_real(x)), _REAL)


def real_array(name: str, value: Any, shape: tuple[int | str, ...], entries: str = "numbers", per: str = "",
               what: str | None = None, prefix: str = "") -> np.ndarray:
    """``value`` as a float64 array of ``shape``, or a ``ValueError`` naming ``name`` and the value.

    The one check of "a real numeric array of shape X": complex values are refused (a cast would
    drop the imaginary part with only a warning), and so is what numpy would cast to float64 though
    it holds no numbers: None (NaN to numpy), bools (``True`` is not a number, as for
    :class:`Number`), datetime64 and timedelta64 values, strings and bytes (``"1.5"``) and
    structured (void) arrays, in an array, in a list or tuple, or in an object array (which may
    hold real numbers only: :func:`is_real`). So are values numpy cannot read as numbers (a ragged
    list, an integer too large for a float) and arrays of another shape. NaN and inf pass (the
    callers say what they mean). The input itself is returned when it already is a float64 array
    (no copy); what is accepted is ``np.asarray(value, float64)``.

    Args:
        name: the argument's name, for the messages (after ``prefix``, e.g. ``"StereoVOEnv: "``).
        shape: the expected shape; an axis given as a string (``"N"``) takes any length.
        entries: what the values are, for the messages (``"weights"``, ``"(uL, vL, uR, vR) pixels"``).
        per: what one entry stands for, for the shape message (``"one weight per correspondence"``).
        what: the whole array in words, for a value that is no array of numbers (default: ``"a
            numeric array of shape (...) of {entries}"``).

    Raises:
        ValueError: ``{name} must be real {entries}, got complex dtype ...``, ``{name} must be
            {what}, got GOT`` (GOT: the value's type where numpy cannot cast it, else ``None``,
            ``ndarray of dtype bool``, ``list holding True``, ``ndarray holding None`` or, for a
            scalar, its repr) or ``{name} must have shape (...), {per}, got (...)``.
    """
    if type(value) is np.ndarray and value.dtype.kind in "iuf":
        # the common case, a real array: no complex check, no conversion for float64 (np.asarray's result)
        array = value if value.dtype == np.float64 else value.astype(np.float64)
    else:
        what = what or f"a numeric array of shape {_shape_text(shape)} of {entries}"
        if value is None:  # np.asarray(None, float64) is a 0-d NaN
            raise ValueError(f"{prefix}{name} must be {what}, got None")
        try:
            inferred = value if isinstance(value, np.ndarray) else np.asarray(value)
            complex_dtype = inferred.dtype if inferred.dtype.kind == "c" else None
            array = None if complex_dtype is not None else np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):  # no numbers, a ragged list, 10**400
            raise ValueError(f"{prefix}{name} must be {what}, got {type(value).__name__}") from None
        if complex_dtype is not None:
            raise ValueError(f"{prefix}{name} must be real {entries}, got complex dtype {complex_dtype}")
        got = _not_real_numbers(value, inferred)
        if got is not None:
            raise ValueError(f"{prefix}{name} must be {what}, got {got}")
    if array.ndim != len(shape) or any(isinstance(k, int) and k != m for k, m in zip(shape, array.shape)):
        raise ValueError(
            f"{prefix}{name} must have shape {_shape_text(shape)}{', ' + per if per else ''}, got {array.shape}"
        )
    return array


def _not_real_numbers(value: Any, inferred: np.ndarray) -> str | None:
    """What :func:`real_array`'s message says it got when ``value`` (``inferred``: numpy's reading
    of it), which numpy casts to float64, holds something other than real numbers; None otherwise."""
    kind, kind_of = inferred.dtype.kind, type(value).__name__
    if isinstance(value, (list, tuple)):
        # the elements themselves, not numpy's reading of them: [True, 2.0] reads as float64
        bad = _first_not_real(np.asarray(value, dtype=object).flat)
        return None if bad is _REAL else f"{kind_of} holding {value_repr(bad)}"
    if kind in _NOT_NUMBER_KINDS:
        return value_repr(value) if inferred.ndim == 0 else f"{kind_of} of dtype {inferred.dtype}"
    if kind == "O":
        bad = _first_not_real(inferred.flat)
        return None if bad is _REAL else f"{kind_of} holding {value_repr(bad)}"
    return None


def _shape_text(shape: tuple[int | str, ...]) -> str:
    """``shape`` as the messages write it: ``(N, 4)``, ``(500,)``."""
    return "(" + ", ".join(map(str, shape)) + ("," if len(shape) == 1 else "") + ")"
