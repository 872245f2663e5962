"""What the reports share: number formats, binomial confidence intervals and the figure helpers.

The baselines report (:mod:`stereovo.benchmark`) and the agents' evaluation
(:mod:`agents.evaluation`) format their tables and draw their figures with these,
so both read the same way. Figures are built on ``matplotlib.figure.Figure``
with the Agg canvas (no pyplot: no global backend, no display, no figure
managers kept alive in long runs); matplotlib is imported only when a figure is
made, so importing this module stays cheap.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

__all__ = [
    "ERROR_FLOOR",
    "PLOT_FORMATS",
    "MAX_LINES_PER_PANEL",
    "format_percent",
    "format_number",
    "wilson_interval",
    "check_plot_format",
    "line_style",
    "figure",
    "save_figure",
    "plot_success",
]

ERROR_FLOOR = 1e-6
"""Log axes need a positive floor for exact (zero) errors; errors below it are drawn at it."""

PLOT_FORMATS: tuple[str, ...] = ("png", "pdf", "svg")
"""File formats of the figures: PNG (raster, 110 dpi) or the vector formats PDF and SVG."""

MAX_LINES_PER_PANEL = 8
"""A panel with more lines than this is split: beyond it, colours repeat and lines become unreadable."""

_PALETTE = (  # matplotlib's tab10, every colour distinguishable from its neighbours
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf",
)
_MARKERS = "os^vDP*Xh"  # nine against ten colours: colour and marker repeat together only after 90
_LINESTYLES = ("-", "--", "-.", ":")


def format_percent(value: float | None) -> str:
    """A rate in [0, 1] as ``"12.3 %"``; ``"n/a"`` for None."""
    return "n/a" if value is None else f"{100 * value:.1f} %"


def format_number(value: float | None, spec: str = ".3g") -> str:
    """``format(value, spec)``; ``"n/a"`` for None."""
    return "n/a" if value is None else format(value, spec)


def wilson_interval(successes: Any, trials: Any, confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Wilson score interval of a binomial success rate, elementwise.

    Args:
        successes: successes k, any shape (counts; non-integers are rounded).
        trials: trials n, broadcastable against ``successes``; n = 0 gives NaN bounds.
        confidence: two-sided coverage in (0, 1).

    Returns:
        ``(low, high)`` arrays of the broadcast shape, within [0, 1]. Unlike the normal
        approximation, the interval stays inside [0, 1] and is not empty at k = 0 or k = n
        (at n = 10 and k = 10 it is [0.72, 1] at 95 %), which is what a success rate over
        10-100 frames needs (E. B. Wilson, "Probable inference, the law of succession, and
        statistical inference", Journal of the American Statistical Association, 1927).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    from scipy.stats import norm

    k = np.rint(np.asarray(successes, dtype=float))
    n = np.asarray(trials, dtype=float)
    if np.any(n < 0) or np.any(k < 0) or np.any(k > n):
        raise ValueError(f"need 0 <= successes <= trials, got successes={successes!r}, trials={trials!r}")
    z = float(norm.ppf(0.5 + confidence / 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        p = k / n
        denom = 1.0 + z * z / n
        centre = (p + z * z / (2 * n)) / denom
        half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    low, high = np.clip(centre - half, 0.0, 1.0), np.clip(centre + half, 0.0, 1.0)
    # the bounds are exact at the ends; keep rounding from moving them off 0 or 1
    low, high = np.where(k == 0, 0.0, low), np.where(k == n, 1.0, high)
    return np.where(n > 0, low, np.nan), np.where(n > 0, high, np.nan)


def check_plot_format(fmt: str) -> str:
    """``fmt`` if it is one of :data:`PLOT_FORMATS` (a leading dot allowed), else ValueError naming it."""
    text = str(fmt).lower().lstrip(".")
    if text not in PLOT_FORMATS:
        raise ValueError(f"plot format must be one of {', '.join(PLOT_FORMATS)}, got {fmt!r}")
    return text


def line_style(i: int) -> dict[str, Any]:
    """Colour, marker and line style of the ``i``-th line of a panel (distinct for the first ten)."""
    return {"color": _PALETTE[i % len(_PALETTE)], "marker": _MARKERS[i % len(_MARKERS)],
            "linestyle": _LINESTYLES[(i // len(_PALETTE)) % len(_LINESTYLES)]}


def figure(figsize: tuple[float, float]):
    """A matplotlib ``Figure`` of ``figsize`` inches on the Agg canvas, constrained layout."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path: str | Path) -> Path:
    """Write ``fig`` to ``path`` (format from its suffix, one of :data:`PLOT_FORMATS`); returns the path."""
    path = Path(path)
    check_plot_format(path.suffix)
    path.parent.mkdir(parents=True, exist_ok=True)
    from matplotlib import rc_context

    # No creation date and a fixed salt for SVG's element ids: the same figure gives the same file.
    metadata = {"svg": {"Date": None}, "pdf": {"CreationDate": None}}.get(path.suffix.lstrip(".").lower())
    with rc_context({"svg.hashsalt": "vo-gym"}):
        fig.savefig(path, dpi=110, metadata=metadata)
    return path


def plot_success(ax, xs: Sequence[float], rates: Sequence[float], frames: Sequence[int], label: str,
                 style: dict[str, Any], confidence: float = 0.95, scale: float = 100.0) -> None:
    """A success-rate line with its Wilson band (``confidence``) on ``ax``, in percent by default.

    ``rates[i]`` is the success rate over ``frames[i]`` frames at ``xs[i]``; the band is drawn in
    the line's colour, light enough that eight overlapping bands stay readable.
    """
    xs = np.asarray(xs, dtype=float)
    rates = np.asarray(rates, dtype=float)
    frames = np.asarray(frames, dtype=float)
    low, high = wilson_interval(rates * frames, frames, confidence)
    ax.plot(xs, rates * scale, label=label, lw=1.3, ms=4, **style)
    if xs.size and not math.isnan(float(np.nanmax(high))):
        ax.fill_between(xs, low * scale, high * scale, color=style["color"], alpha=0.12, lw=0)
