"""What every ``vo-gym`` command shares: argument parsers that name the option, the
usage-error type, the output-folder check made before any computing, and the
one-line handling of usage errors and Ctrl-C.

Conventions (argparse's): a usage error prints one line ``vo-gym CMD: error: ...``
naming the argument and exits 2; Ctrl-C prints one line and exits 130.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


class UsageError(Exception):
    """A bad argument or unusable path; the message names the argument and the value."""


def csv_list(kind: Callable[[str], Any], name: str) -> Callable[[str], list[Any]]:
    """An argparse type for ``A,B,...`` lists of ``kind`` values; errors name ``name``."""

    def parse(text: str) -> list[Any]:
        items = [t.strip() for t in text.split(",") if t.strip()]
        if not items:
            raise argparse.ArgumentTypeError(f"{name} needs at least one value")
        try:
            return [kind(t) for t in items]
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{name} {text!r}: expected comma-separated {kind.__name__} values"
            ) from None

    return parse


def bounded_int(name: str, minimum: int) -> Callable[[str], int]:
    """An argparse type for integers ``>= minimum``; errors name ``name`` and the value."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} {text!r} is not an integer") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{name} must be >= {minimum}, got {value}")
        return value

    return parse


def positive_int(name: str) -> Callable[[str], int]:
    return bounded_int(name, 1)


def seed(text: str) -> int:
    """``--seed``: a non-negative integer."""
    return bounded_int("--seed", 0)(text)


def finite_float(name: str, low: float | None = None, high: float | None = None,
                 low_open: bool = False) -> Callable[[str], float]:
    """An argparse type for finite floats in ``[low, high]`` (``(low, high]`` if ``low_open``)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} {text!r} is not a number") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{name} must be finite, got {text!r}")
        if low is not None and (value < low or (low_open and value == low)):
            raise argparse.ArgumentTypeError(f"{name} must be {'>' if low_open else '>='} {low}, got {value}")
        if high is not None and value > high:
            raise argparse.ArgumentTypeError(f"{name} must be <= {high}, got {value}")
        return value

    return parse


def check_output_dir(path: str | os.PathLike, option: str = "--out") -> Path:
    """Create ``path`` if needed and prove it writable, before any computing starts.

    Raises:
        UsageError: naming ``option`` and the path when it is a file, cannot be created,
            or cannot be written.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise UsageError(f"{option} {str(out)!r} exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".write-check-"):
            pass
    except OSError as err:
        raise UsageError(f"{option} {str(out)!r} is not writable ({err.strerror or err})") from None
    return out


def guarded(command: str, run: Callable[[], int]) -> int:
    """Run a command body; usage errors and Ctrl-C become one line and exit codes 2 / 130."""
    try:
        return int(run() or 0)
    except UsageError as err:
        print(f"vo-gym {command}: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"vo-gym {command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
