"""The four figures of a benchmark report, one panel per method family.

:func:`write_plots` draws success and hypotheses against contamination, time against N and the
error CDFs (:data:`PLOT_NAMES`); :func:`plot_panels` splits the methods into panels by family
(:data:`METHOD_FAMILIES`), each led by :data:`REFERENCE_METHOD`. matplotlib is imported only when
a figure is drawn.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from stereovo.benchmark.aggregation import BenchmarkSummary, finite_stat, group_rows
from stereovo.benchmark.runner import GUIDED_VARIANTS
from stereovo.metrics import SUCCESS_ROT_DEG, SUCCESS_TRANS_M, SUCCESS_TRANS_REL
from stereovo.reporting import (
    ERROR_FLOOR,
    MAX_LINES_PER_PANEL,
    check_plot_format,
    figure,
    line_style,
    plot_success,
    save_figure,
)

PLOT_NAMES = ("success_vs_epsilon", "hypotheses_vs_epsilon", "time_vs_n", "error_cdf")
PLOT_FILES = tuple(f"{name}.png" for name in PLOT_NAMES)
"""The report figures' file names in the default format (PNG); :func:`plot_files` for another."""

REFERENCE_METHOD = "ransac"
"""Drawn in every panel (black), so each family reads against plain RANSAC."""

METHOD_FAMILIES: dict[str, str] = {
    "ransac": "scoring", "msac": "scoring", "mlesac": "scoring", "probabilistic": "scoring",
    "r-ransac": "verification", "waldsac": "verification", "preemptive": "verification",
    "guided-mlesac": "sampling", "prosac": "sampling", "bansac": "sampling", "p-bansac": "sampling", "ars": "sampling",
    "lo-ransac": "frameworks", "usac": "frameworks", "inlier-detection": "frameworks",
}
"""The figure panel of each registered method; a guided variant goes with ``sampling``, another
``base+step`` name with ``enhancements``, anything else with ``other``."""

FAMILY_TITLES: dict[str, str] = {
    "scoring": "how a hypothesis is scored",
    "verification": "early rejection, preemption",
    "sampling": "ordered, guided and adaptive sampling",
    "frameworks": "local optimisation, USAC, inlier detection",
    "enhancements": "a base method plus single steps",
    "other": "other methods",
}


def plot_files(fmt: str = "png") -> tuple[str, ...]:
    """The report figures' file names in ``fmt`` (one of :data:`stereovo.reporting.PLOT_FORMATS`)."""
    fmt = check_plot_format(fmt)
    return tuple(f"{name}.{fmt}" for name in PLOT_NAMES)


def method_family(name: str) -> str:
    """The panel family of a benchmark method (see :data:`METHOD_FAMILIES`)."""
    if name in METHOD_FAMILIES:
        return METHOD_FAMILIES[name]
    if name in GUIDED_VARIANTS:
        return "sampling"
    return "enhancements" if "+" in name else "other"


def plot_panels(methods: Sequence[str], max_lines: int = MAX_LINES_PER_PANEL) -> list[tuple[str, list[str]]]:
    """``(title, methods)`` of each panel: one family each, in the order of the families, every panel
    led by :data:`REFERENCE_METHOD` (when it ran) and at most ``max_lines`` lines (a larger family is
    split into balanced parts)."""
    reference = REFERENCE_METHOD if REFERENCE_METHOD in methods else None
    families: dict[str, list[str]] = {f: [] for f in FAMILY_TITLES}
    for m in methods:
        if m != reference:
            families[method_family(m)].append(m)
    if reference is not None and not any(families.values()):
        families["scoring"] = []  # the reference alone still gets its panel
    room = max(max_lines - (reference is not None), 1)
    panels = []
    for family, members in families.items():
        if not members and not (family == "scoring" and reference is not None):
            continue
        parts = max(math.ceil(len(members) / room), 1)
        size = math.ceil(len(members) / parts) if members else 0
        for p in range(parts):
            chunk = members[p * size:(p + 1) * size]
            title = FAMILY_TITLES[family] + (f" ({p + 1}/{parts})" if parts > 1 else "")
            panels.append((title, ([reference] if reference else []) + chunk))
    return panels


def _panel_style(method: str, j: int) -> dict[str, Any]:
    if method == REFERENCE_METHOD:
        return {"color": "black", "marker": "o", "linestyle": "-"}
    return line_style(j)


def _panel_grid(n_panels: int, panel_size: tuple[float, float] = (5.2, 4.4)):
    cols = min(n_panels, 3)
    rows = math.ceil(n_panels / cols)
    fig = figure((panel_size[0] * cols, panel_size[1] * rows))
    axes = [fig.add_subplot(rows, cols, i + 1) for i in range(n_panels)]
    return fig, axes


def _panel_legend(ax) -> None:
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, fontsize="x-small", frameon=False)


def _line_plot(summary: BenchmarkSummary, axis: str, key: str, scale: float, ylabel: str, title: str,
               path: Path, logx: bool = False, logy: bool = False, ylim: tuple[float, float] | None = None,
               confidence: float | None = None) -> Path:
    """``key`` against epsilon or N, one panel per family (:func:`plot_panels`), a legend under each.

    With ``confidence``, ``key`` is a success rate and each line carries its Wilson band over the
    frames behind the point.
    """
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter, ScalarFormatter

    per = summary.by_epsilon if axis == "epsilon" else summary.by_n
    panels = plot_panels(summary.methods)
    fig, axes = _panel_grid(len(panels))
    xs_all = sorted({x for m in summary.methods for x in per.get(m, {})})
    for ax, (panel_title, methods) in zip(axes, panels):
        j = 0
        for method in methods:
            points = sorted((x, finite_stat(s, key), s.get("frames", 0)) for x, s in per.get(method, {}).items())
            points = [(x, y, n) for x, y, n in points if y is not None]
            if not points:
                continue
            style = _panel_style(method, j)
            j += method != REFERENCE_METHOD
            xs, ys, ns = zip(*points)
            if confidence is not None:
                plot_success(ax, xs, ys, ns, method, style, confidence, scale)
            else:
                ax.plot(xs, [y * scale for y in ys], label=method, lw=1.3, ms=4, **style)
        if logx:
            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_xticks(xs_all)
            ax.xaxis.set_major_formatter(ScalarFormatter())
        elif xs_all:
            ax.set_xticks(xs_all)
        if logy and ax.has_data():
            ax.set_yscale("log")
            low, high = ax.dataLim.y0, ax.dataLim.y1
            decades = math.log10(high / low) if 0 < low < high else 0.0
            subs = (1.0, 1.5, 2.0, 3.0, 5.0, 7.0) if decades < 1.5 else (1.0, 2.0, 5.0) if decades < 3 else (1.0,)
            ax.yaxis.set_major_locator(LogLocator(subs=subs))
            ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
            ax.yaxis.set_minor_formatter(NullFormatter())
        if ylim:
            ax.set_ylim(*ylim)
        ax.set_xlabel("contamination epsilon" if axis == "epsilon" else "correspondences N")
        ax.set_ylabel(ylabel)
        ax.set_title(panel_title, fontsize="small")
        ax.grid(True, which="both", alpha=0.3)
        _panel_legend(ax)
    band = f"; bands: {100 * confidence:g} % Wilson intervals" if confidence is not None else ""
    fig.suptitle(title + band, fontsize="medium")
    return save_figure(fig, path)


def plot_error_cdf(rows: Sequence[Mapping[str, Any]], methods: Sequence[str], path: Path) -> Path:
    """Empirical CDFs of rotation (left) and translation error (right), one row of panels per family.

    Each panel marks its own success bound (1 deg; 0.05 m or 5 % of the true translation, whichever
    is larger, so the dashed 0.05 m is the translation bound's floor), both named in the row's legend
    on its right, clear of the curves.
    """
    from matplotlib.ticker import NullFormatter

    panels = plot_panels(methods)
    fig = figure((12, 3.6 * len(panels)))
    groups = group_rows(rows, "method")
    trans_rel = f"{100 * SUCCESS_TRANS_REL:g} %"
    for r, (panel_title, members) in enumerate(panels):
        ax_rot, ax_trans = fig.add_subplot(len(panels), 2, 2 * r + 1), fig.add_subplot(len(panels), 2, 2 * r + 2)
        j = 0
        for method in members:
            group = groups.get((method,), [])
            style = _panel_style(method, j)
            j += method != REFERENCE_METHOD
            for ax, column in ((ax_rot, "rot_err_deg"), (ax_trans, "trans_err_m")):
                values = np.asarray([float(row[column]) for row in group], dtype=float)
                values = np.where(np.isfinite(values), values, np.inf)  # a raised estimator never succeeds
                if values.size == 0:
                    continue
                xs = np.sort(np.maximum(values, ERROR_FLOOR))
                ys = np.arange(1, xs.size + 1) / xs.size
                ax.step(xs, ys, where="post", label=method, lw=1.2, color=style["color"],
                        linestyle=style["linestyle"])
        bounds = ((ax_rot, SUCCESS_ROT_DEG, f"success bound {SUCCESS_ROT_DEG:g} deg", "rotation error [deg]"),
                  (ax_trans, SUCCESS_TRANS_M, f"success bound {SUCCESS_TRANS_M:g} m (or {trans_rel} of |t|)",
                   "translation error [m]"))
        for ax, bound, text, xlabel in bounds:
            # Named in a legend, not written beside the line, where it would cover the curves.
            ax.axvline(bound, color="tab:red", ls="--", lw=0.8, label=text)
            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_xlabel(xlabel)
            ax.set_ylabel("fraction of frames")
            ax.set_ylim(0, 1.01)
            ax.grid(True, which="both", alpha=0.3)
        ax_rot.set_title(panel_title, fontsize="small", loc="left")
        handles, labels = ax_trans.get_legend_handles_labels()
        rot_bound = ax_rot.get_lines()[-1]  # the row's one legend, outside the panels, names both bounds
        ax_trans.legend([*handles, rot_bound], [*labels, rot_bound.get_label()], loc="center left",
                        bbox_to_anchor=(1.01, 0.5), fontsize="x-small")
    fig.suptitle("Error CDFs over all frames of the grid", fontsize="medium")
    return save_figure(fig, path)


def _frames_per_point(summary: BenchmarkSummary) -> str:
    counts = sorted({int(s.get("frames", 0)) for per in summary.by_epsilon.values() for s in per.values()})
    return "/".join(str(c) for c in counts) if len(counts) <= 2 else f"{counts[0]}-{counts[-1]}"


def write_plots(rows: Sequence[Mapping[str, Any]], summary: BenchmarkSummary, out: str | os.PathLike,
                fmt: str = "png") -> list[Path]:
    """The four report figures (:data:`PLOT_NAMES`) under ``out`` as ``fmt`` files (png, pdf or svg)."""
    out = Path(out)
    names = plot_files(fmt)
    return [
        _line_plot(summary, "epsilon", "success_rate", 100.0, "success rate [%]",
                   f"Success rate vs contamination (other axes pooled, {_frames_per_point(summary)} frames a point;"
                   " a wiggle inside a band is noise)", out / names[0], ylim=(-2, 102), confidence=0.95),
        _line_plot(summary, "epsilon", "mean_hypotheses", 1.0, "mean hypotheses per frame",
                   "Hypotheses generated vs contamination", out / names[1], logy=True),
        _line_plot(summary, "n", "median_time_ms", 1.0, "median time per frame [ms]",
                   "Time vs number of correspondences", out / names[2], logx=True, logy=True),
        plot_error_cdf(rows, summary.methods, out / names[3]),
    ]
