"""The markdown of a benchmark report: the headline and breakdown tables, ``summary.md`` and ``claims.md``.

:func:`markdown_table` is the one table writer; the agents' evaluation and the sweep report use
it too, and :func:`success_definition` is the success rule in words that every report quotes.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

from stereovo.benchmark.aggregation import STAT_LABELS, BenchmarkSummary
from stereovo.benchmark.claims import AGREES, DISAGREES, NOT_MEASURED, ClaimCheck, thresholds_text
from stereovo.metrics import SUCCESS_ROT_DEG, SUCCESS_TRANS_M, SUCCESS_TRANS_REL

def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[Any]], align: str | None = None) -> str:
    """A GitHub markdown table; ``align`` is one char per column (``l``/``r``), default left then right."""
    align = align or "l" + "r" * (len(headers) - 1)
    sep = ["---:" if a == "r" else ":---" for a in align]
    lines = ["| " + " | ".join(headers) + " |", "| " + " | ".join(sep) + " |"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def format_stat(key: str, value: Any) -> str:
    """A statistic (:data:`~stereovo.benchmark.aggregation.STAT_LABELS`' keys) in the tables' units; ``n/a`` if missing."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    if key == "frames":
        return str(int(value))
    if key == "success_rate":
        return f"{100 * value:.1f} %"
    if key in ("mean_precision", "mean_recall"):
        return f"{value:.3f}"
    if key in ("median_hypotheses", "mean_hypotheses", "median_point_checks"):
        return f"{value:,.0f}"
    if key == "median_time_ms":
        return f"{value:.1f}"
    return f"{value:.3g}"


def overall_table(summary: BenchmarkSummary) -> str:
    """The headline table: one row per method."""
    keys = list(STAT_LABELS)
    rows = [[f"`{m}`", *(format_stat(k, summary.overall[m].get(k)) for k in keys)] for m in summary.methods]
    return markdown_table(["method", *STAT_LABELS.values()], rows)


def breakdown_table(summary: BenchmarkSummary, axis: str, key: str) -> str:
    """One row per method, one column per value of ``axis``: ``"epsilon"``, ``"n"`` or ``"auc"``."""
    per = {"epsilon": summary.by_epsilon, "n": summary.by_n, "auc": summary.by_auc}[axis]
    values = {"epsilon": summary.epsilons, "n": summary.ns, "auc": summary.aucs}[axis]
    label = {"epsilon": "epsilon", "n": "N", "auc": "AUC"}[axis]
    headers = ["method", *(f"{label} = {v:g}" for v in values)]
    rows = [
        [f"`{m}`", *(format_stat(key, per.get(m, {}).get(v, {}).get(key)) for v in values)]
        for m in summary.methods
    ]
    return markdown_table(headers, rows)


def success_definition() -> str:
    return (
        f"status ok, rotation error < {SUCCESS_ROT_DEG:g} deg and translation error"
        f" < max({SUCCESS_TRANS_M:g} m, {100 * SUCCESS_TRANS_REL:g} % of the true translation)"
    )


def summary_markdown(
    summary: BenchmarkSummary, settings: Mapping[str, Any] | None = None, title: str = "Classical baselines",
    level: int = 1,
) -> str:
    """``summary.md``: settings, the headline table and breakdowns by epsilon and N.

    ``level`` is the markdown heading level of ``title``; breakdowns sit one level below.
    """
    settings = dict(settings or {})
    lines = [f"{'#' * level} {title}", ""]
    if "grid" in settings:
        lines.append(f"Grid: {settings['grid']}.")
    cap = settings.get("max_iterations")
    if "seed" in settings:
        lines.append(f"Seed {settings['seed']}; {settings.get('workers', 1)} worker process(es).")
    lines.append(
        f"Every method runs with max_iterations = {cap if cap is not None else 'the core default'} (hypothesis cap;"
        " not preemptive, whose cap is its M, nor inlier-detection, which draws no hypotheses)"
        " and the frame's pixel noise sigma; success = " + success_definition() + "."
    )
    lines.append(
        "Errors are medians over all frames (a failed estimate counts with what it returned);"
        " precision and recall are means; time is the median wall time of one estimator call"
        " on one core while the other workers run."
    )
    lines += ["", overall_table(summary), ""]
    for caption, axis, key in (
        ("Success rate by contamination", "epsilon", "success_rate"),
        ("Mean hypotheses by contamination", "epsilon", "mean_hypotheses"),
        ("Median time [ms] by contamination", "epsilon", "median_time_ms"),
        ("Median time [ms] by N", "n", "median_time_ms"),
        ("Mean hypotheses by match-score AUC", "auc", "mean_hypotheses"),
    ):
        values = {"epsilon": summary.epsilons, "n": summary.ns, "auc": summary.aucs}[axis]
        if len(values) > (0 if axis == "epsilon" else 1):
            lines += [f"{'#' * (level + 1)} {caption}", "", breakdown_table(summary, axis, key), ""]
    errors = {m: s.get("n_errors", 0) for m, s in summary.overall.items() if s.get("n_errors", 0)}
    if errors:
        lines += ["Estimators that raised (recorded as failures): "
                  + ", ".join(f"`{m}` {n}x" for m, n in errors.items()) + ".", ""]
    return "\n".join(lines).rstrip() + "\n"


def claims_markdown(claims: Sequence[ClaimCheck], heading: str = "# Claims of the seed vs our numbers") -> str:
    """``claims.md``: a verdict table and, per claim, the numbers behind it."""
    counts = {v: sum(c.verdict == v for c in claims) for v in (AGREES, DISAGREES, NOT_MEASURED)}
    lines = [
        heading,
        "",
        f"{counts[AGREES]} agree, {counts[DISAGREES]} do not agree, {counts[NOT_MEASURED]} not measured. "
        + thresholds_text(),
        "",
        markdown_table(
            ["claim", "source", "verdict"],
            [[c.claim, c.source, f"**{c.verdict}**"] for c in claims],
            align="lll",
        ),
        "",
    ]
    for c in claims:
        lines += [f"- **{c.claim}** ({c.source}) — **{c.verdict}**."]
        if c.measured_on:
            lines[-1] += f" Measured on {c.measured_on}."
        if c.reference:
            lines[-1] += f" Reference: {c.reference}."
        lines[-1] += f" Numbers: {c.numbers}."
        if c.context:
            lines[-1] += f" For comparison, {c.context}."
        if c.diagnosis:
            lines[-1] += f" What explains it: {c.diagnosis}."
        if c.note:
            lines[-1] += f" _{c.note}_"
    return "\n".join(lines).rstrip() + "\n"
