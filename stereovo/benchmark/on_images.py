"""The classical family on the frames of an image sequence: one row per (frame, method), a summary.

The grid of :mod:`stereovo.benchmark.grid` chooses a contamination; on images the front end does.
So the frames here are the sequence's own pairs, every method sees each pair once, and the rows
carry the pair's measured outlier ratio (from the sequence's per-match ground-truth labels)
instead of a grid cell. A method's random stream is seeded by ``(seed, frame, method)``, so a
method's rows do not depend on which other methods run or in which order.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from stereovo.benchmark.grid import check_seed, stable_int
from stereovo.benchmark.runner import Estimator, measure_estimator
from stereovo.reporting import figure, format_number, format_percent, save_figure, wilson_interval
from stereovo.simulation import Frame

_TAG = stable_int("images")

IMAGE_COLUMNS: tuple[str, ...] = (
    "frame", "method", "n", "outlier_ratio", "success", "rot_err_deg", "trans_err_m", "precision", "recall",
    "n_inliers", "n_true_inliers", "n_hypotheses", "status", "time_s",
)
"""The columns of one row: the frame index k (1-based), the method, the pair's match count and
true outlier ratio, then :func:`stereovo.benchmark.runner.measure_estimator`'s metrics."""


def frame_rng(seed: int, k: int, name: str) -> np.random.Generator:
    """Method ``name``'s generator on frame ``k`` of a run seeded ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(check_seed(seed), spawn_key=(_TAG, int(k), stable_int(name))))


def run_on_frames(frames: Iterable[Frame], estimators: Sequence[tuple[str, Estimator]], seed: int,
                  advance: Callable[[], None] | None = None) -> list[dict[str, Any]]:
    """Every estimator on every frame: rows with :data:`IMAGE_COLUMNS`.

    Args:
        frames: frame pairs with ground truth (``frame.truth``: motion and per-match labels).
        estimators: ``(name, estimator)`` pairs, e.g. from
            :func:`stereovo.benchmark.runner.classical_estimators`.
        seed: the run's seed (see :func:`frame_rng`).
        advance: called once per frame after its rows (a progress bar's ``update``).
    """
    rows = []
    for frame in frames:
        k = int(frame.index)
        n_true = int(np.count_nonzero(frame.truth.inlier))
        for name, estimator in estimators:
            metrics, elapsed = measure_estimator(estimator, frame, frame_rng(seed, k, name))
            row = {"frame": k, "method": name, "n": int(frame.n),
                   "outlier_ratio": float(frame.truth.outlier_ratio), **metrics,
                   "n_true_inliers": n_true, "time_s": elapsed}
            rows.append({column: row[column] for column in IMAGE_COLUMNS})
        if advance is not None:
            advance()
    return rows


def _median(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.median(finite)) if finite else math.nan


def summarise(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per method, in first-seen order: frames, success rate with its Wilson 95 % interval, the
    median rotation (deg) and translation (m) errors of all frames, mean inlier precision and
    recall, mean hypotheses and median time per frame (ms)."""
    summary = []
    for method in dict.fromkeys(r["method"] for r in rows):
        own = [r for r in rows if r["method"] == method]
        hits = sum(bool(r["success"]) for r in own)
        low, high = wilson_interval(hits, len(own))
        summary.append({
            "method": method, "frames": len(own), "success": hits / len(own),
            "ci_low": float(low), "ci_high": float(high),
            "median_rot_err_deg": _median([float(r["rot_err_deg"]) for r in own]),
            "median_trans_err_m": _median([float(r["trans_err_m"]) for r in own]),
            "precision": float(np.nanmean([float(r["precision"]) for r in own])),
            "recall": float(np.nanmean([float(r["recall"]) for r in own])),
            "mean_hypotheses": float(np.mean([float(r["n_hypotheses"]) for r in own])),
            "median_ms": 1e3 * float(np.median([float(r["time_s"]) for r in own])),
        })
    return summary


def summary_markdown(summary: Sequence[dict[str, Any]], title: str) -> str:
    """The summary as a markdown table under ``title``."""
    lines = [f"## {title}", "",
             "| method | frames | success (95 % CI) | median rot err (deg) | median trans err (m) | precision | recall "
             "| mean hypotheses | median ms |",
             "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for s in summary:
        lines.append(
            f"| {s['method']} | {s['frames']} | {format_percent(s['success'])} "
            f"({format_percent(s['ci_low'])}-{format_percent(s['ci_high'])}) | {format_number(s['median_rot_err_deg'])} "
            f"| {format_number(s['median_trans_err_m'])} | {format_number(s['precision'])} "
            f"| {format_number(s['recall'])} | {format_number(s['mean_hypotheses'])} | {format_number(s['median_ms'])} |"
        )
    return "\n".join(lines) + "\n"


def plot_summary(path: str | Path, summary: Sequence[dict[str, Any]], title: str) -> Path:
    """Success with its Wilson 95 % interval against median time per frame, one point a method."""
    fig = figure((6.4, 4.2))
    ax = fig.add_subplot()
    for s in summary:
        rate, low, high = (100.0 * s[key] for key in ("success", "ci_low", "ci_high"))
        ax.errorbar([s["median_ms"]], [rate], yerr=[[rate - low], [high - rate]], fmt="o", capsize=3)
        ax.annotate(s["method"], (s["median_ms"], rate), textcoords="offset points", xytext=(4, 3), fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("median time per frame (ms, log scale)")
    ax.set_ylabel("success (%, 95 % CI)")
    ax.set_title(title, fontsize=9)
    ax.grid(True, alpha=0.3)
    return save_figure(fig, path)
