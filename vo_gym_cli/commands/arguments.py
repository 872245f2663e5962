"""The ``vo-gym`` commands' argument types: argparse ``type=`` callables that refuse a bad value in one
line naming the option and the value (``--frames must be >= 1, got 0``), and the names the parsers
offer without importing the library (presets, outlier presets, detectors; tests keep them equal to
the library's). A cap a count is checked against is read from the library only when a value is
parsed, so that building a parser imports nothing.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any, Callable


def csv_list(kind: Callable[[str], Any], name: str) -> Callable[[str], list[Any]]:
    """An argparse type for ``A,B,...`` lists of distinct ``kind`` values (each list is a set of cells,
    methods or kinds: a value given twice would run or print twice); errors name ``name``."""

    def parse(text: str) -> list[Any]:
        items = [t.strip() for t in text.split(",") if t.strip()]
        if not items:
            raise argparse.ArgumentTypeError(f"{name} needs at least one value")
        try:
            values = [kind(t) for t in items]
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{name} {text!r}: expected comma-separated {kind.__name__} values"
            ) from None
        repeated = next((items[i] for i, v in enumerate(values) if v in values[:i]), None)
        if repeated is not None:
            raise argparse.ArgumentTypeError(f"{name} {text!r} gives {repeated} twice")
        return values

    return parse


def bounded_int(name: str, minimum: int, maximum: int | Callable[[], int] | None = None) -> Callable[[str], int]:
    """An argparse type for integers ``>= minimum`` (and ``<= maximum``: a number, or a function giving
    the library's cap, read only when a value is parsed so that building the parser imports nothing);
    errors name ``name`` and the value."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} {text!r} is not an integer") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{name} must be >= {minimum}, got {value}")
        most = maximum() if callable(maximum) else maximum
        if most is not None and value > most:
            from stereovo.options import value_repr

            raise argparse.ArgumentTypeError(f"{name} must be <= {most}, got {value_repr(value)}")
        return value

    return parse


def max_count() -> int:
    """The estimator's cap on a count of hypotheses (a budget, an iteration cap)."""
    from stereovo.estimation.estimator_options import MAX_COUNT

    return MAX_COUNT


def max_correspondences() -> int:
    """The simulator's cap on the matches of a frame."""
    from stereovo.simulation.config import MAX_CORRESPONDENCES

    return MAX_CORRESPONDENCES


def max_learning_rate() -> float:
    """The trainers' cap on a learning rate (exclusive: :data:`agents.training_limits.MAX_LEARNING_RATE`)."""
    from agents.training_limits import MAX_LEARNING_RATE

    return MAX_LEARNING_RATE


def max_frames() -> int:
    """The simulator's cap on the frames of a sequence."""
    from stereovo.simulation.config import MAX_FRAMES

    return MAX_FRAMES


def output_path(name: str = "--out", kind: Callable[[str], Any] = Path) -> Callable[[str], Any]:
    """An argparse type for an output path: ``kind(text)``, refusing an empty one (``Path("")`` is the
    current folder, where an unset shell variable would have a command write) and one holding a NUL
    character (no file system takes it)."""

    def parse(text: str) -> Any:
        if not text:
            raise argparse.ArgumentTypeError(f"{name} must name a file or folder, got '' (the current folder is '.')")
        if "\x00" in text:
            raise argparse.ArgumentTypeError(f"{name} must not hold a NUL character, got {text!r}")
        return kind(text)

    return parse


def positive_int(name: str) -> Callable[[str], int]:
    return bounded_int(name, 1)


def seed(text: str) -> int:
    """``--seed``: a non-negative integer."""
    return bounded_int("--seed", 0)(text)


def finite_float(name: str, low: float | None = None, high: float | Callable[[], float] | None = None,
                 low_open: bool = False, high_open: bool = False) -> Callable[[str], float]:
    """An argparse type for finite floats in ``[low, high]`` (``low_open`` / ``high_open`` exclude a bound;
    ``high`` may be a function giving the library's cap, read only when a value is parsed)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} {text!r} is not a number") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{name} must be finite, got {text!r}")
        if low is not None and (value < low or (low_open and value == low)):
            raise argparse.ArgumentTypeError(f"{name} must be {'>' if low_open else '>='} {low}, got {value}")
        most = high() if callable(high) else high
        if most is not None and (value > most or (high_open and value == most)):
            raise argparse.ArgumentTypeError(f"{name} must be {'<' if high_open else '<='} {most}, got {value}")
        return value

    return parse


PRESETS = ("car", "free")
"""The motion presets of the simulator and of rendered sequences (``--preset``, ``rendered:PRESET``)."""


OUTLIER_PRESETS = ("default", "hostile")
"""The simulator's outlier presets (``stereovo.simulation.OUTLIER_PRESETS``' keys, named here so
that building the parser imports no simulation code; a test keeps the two equal)."""


DETECTORS = ("orb", "sift", "akaze")
"""The image front end's keypoint detectors (``stereovo.frontend.options.DETECTORS``, named here so
that building the parser imports no front-end code; a test keeps the two equal)."""


def parse_source(text: str) -> str:
    """``--source``: ``rendered``, ``rendered:PRESET`` or ``kitti:PATH[:SEQ]`` (checked, returned as given)."""
    from stereovo.sequences.sources import parse_source as parse

    try:
        kind, named = parse(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"--{err}") from None
    if kind == "rendered" and named.get("preset", "car") not in PRESETS:
        raise argparse.ArgumentTypeError(f"--source {text!r}: the rendered preset must be one of "
                                         f"{', '.join(PRESETS)}, got {named['preset']!r}")
    return text


def method_name(name: str = "--method") -> Callable[[str], str]:
    """An argparse type for a registered estimator method; the error lists them (imports the core on use)."""

    def parse(text: str) -> str:
        from stereovo.estimation import available_methods

        methods = list(available_methods())
        if text not in methods:
            raise argparse.ArgumentTypeError(f"{name}: unknown method {text!r}; available: {', '.join(methods)}")
        return text

    return parse
