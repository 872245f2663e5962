"""Trial rows back from CSV, and their statistics: per method, per axis value and per grid cell.

:func:`aggregate` turns any group of trial rows into one dict of statistics (success rate,
median errors, hypotheses, point checks, time); :func:`summarize` groups a run's rows into a
:class:`BenchmarkSummary` (per method, per epsilon, per N, per AUC) and :func:`cell_summary_rows`
into one row per (method, cell). :func:`read_trials_csv` reads a ``trials.csv`` back with its
types restored, so a report can be rebuilt from the stored rows alone.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Container, Iterable, Mapping, Sequence

import numpy as np

# The columns of runner.TRIAL_COLUMNS that are not floats; trials.csv stores every value as text.
_INT_COLUMNS = {"trial", "cell", "repeat", "n", "n_inliers", "n_true_inliers", "n_hypotheses", "n_scored", "n_point_checks"}
_STR_COLUMNS = {"outlier_kind", "method", "status"}
_BOOL_COLUMNS = {"success"}


def typed_value(column: str, text: str, ints: Container[str], strs: Container[str], bools: Container[str],
                strict: bool = False) -> Any:
    """A CSV cell's text as its column's type: ``strs`` as they are, ``bools`` from ``True``/``False``,
    ``ints`` as integers, any other column as a float; a text that is no number stays text, or with
    ``strict`` raises ValueError.

    The baselines' ``trials.csv`` (:func:`parse_trial_value`) and the agents' evaluation's
    ``frames.csv`` read their cells with it.
    """
    if column in strs:
        return text
    if column in bools:
        if text not in ("True", "False"):
            raise ValueError(f"column {column}: expected True/False, got {text!r}")
        return text == "True"
    if column in ints:
        return int(text)
    if strict:
        return float(text)
    try:
        return float(text)
    except ValueError:
        return text


def parse_trial_value(column: str, text: str) -> Any:
    """A ``trials.csv`` cell's value with its type restored (see :data:`TRIAL_COLUMNS`); a text that is
    no value of its column (``success=maybe``, ``rot_err_deg=hello``) raises ValueError."""
    return typed_value(column, text, _INT_COLUMNS, _STR_COLUMNS, _BOOL_COLUMNS, strict=True)


class TrialsFileError(ValueError):
    """A ``trials.csv`` that is not one :func:`write_outputs` wrote; the message names the line."""


# Columns a trials.csv may lack (files written before they existed); the statistics default them.
_OPTIONAL_COLUMNS = {"n_hypotheses_to_best"}


def read_trials_csv(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Rows of a ``trials.csv`` written by :func:`write_outputs`, with their types restored.

    Raises:
        TrialsFileError: not UTF-8 CSV, a header with unknown or missing columns, a row of another
            width, or a cell that is no value of its column; the message names the line.
    """
    from stereovo.benchmark.runner import TRIAL_COLUMNS
    from stereovo.trials.store import csv_records, header_mismatch, parsed_row

    name = Path(path).name
    try:
        text = Path(path).read_bytes().decode("utf-8")
    except UnicodeDecodeError as err:
        raise TrialsFileError(f"{name}: not UTF-8 text (byte {err.start})") from None
    except OSError as err:
        raise TrialsFileError(f"{name}: cannot be read ({err.strerror or err})") from None
    rows: list[dict[str, Any]] = []
    try:
        records = csv_records(text)
        _, header = next(records, (1, []))
        if not header:
            raise TrialsFileError(f"{name}: no header line")
        what = header_mismatch(header, TRIAL_COLUMNS, _OPTIONAL_COLUMNS)
        if what is not None:
            raise TrialsFileError(f"{name}: line 1: {what}")
        rows = [parsed_row(header, fields, parse_trial_value, line) for line, fields in records]
    except TrialsFileError:
        raise
    except ValueError as err:  # csv_records' and parsed_row's, which name the line
        raise TrialsFileError(f"{name}: {err}") from None
    return rows


STAT_LABELS: dict[str, str] = {
    "frames": "frames",
    "success_rate": "success",
    "median_rot_err_deg": "rot err med [deg]",
    "median_trans_err_m": "trans err med [m]",
    "mean_precision": "inlier precision",
    "mean_recall": "inlier recall",
    "median_hypotheses": "hypotheses med",
    "mean_hypotheses": "hypotheses mean",
    "median_point_checks": "point checks med",
    "median_time_ms": "time med [ms]",
}


def finite_stat(stats: Mapping[str, Any] | None, key: str) -> float | None:
    """``stats[key]`` as a float; None when the statistic is absent, None or not finite."""
    if stats is None or key not in stats or stats[key] is None:
        return None
    value = float(stats[key])
    return value if math.isfinite(value) else None


def _finite(values: Iterable[Any]) -> np.ndarray:
    a = np.asarray([float(v) for v in values], dtype=float)
    return a[np.isfinite(a)]


def _median(values: Iterable[Any]) -> float:
    a = _finite(values)
    return float(np.median(a)) if a.size else math.nan


def _mean(values: Iterable[Any]) -> float:
    a = _finite(values)
    return float(np.mean(a)) if a.size else math.nan


def aggregate(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Statistics of a group of trial rows (any grouping).

    Medians and means ignore NaN (estimators that raised); the success rate
    counts every row (a raised estimator is a failure). Errors of failed
    estimates (identity motion) count in the error medians: that is what the
    estimator returned.
    """
    statuses = [str(r["status"]) for r in rows]
    return {
        "frames": len(rows),
        "success_rate": float(np.mean([bool(r["success"]) for r in rows])) if rows else math.nan,
        "median_rot_err_deg": _median(r["rot_err_deg"] for r in rows),
        "median_trans_err_m": _median(r["trans_err_m"] for r in rows),
        "mean_precision": _mean(r["precision"] for r in rows),
        "mean_recall": _mean(r["recall"] for r in rows),
        "median_hypotheses": _median(r["n_hypotheses"] for r in rows),
        "mean_hypotheses": _mean(r["n_hypotheses"] for r in rows),
        "mean_hypotheses_to_best": _mean(r.get("n_hypotheses_to_best", math.nan) for r in rows),
        "median_point_checks": _median(r["n_point_checks"] for r in rows),
        "mean_point_checks": _mean(r["n_point_checks"] for r in rows),
        "median_time_ms": 1e3 * _median(r["time_s"] for r in rows),
        "mean_time_ms": 1e3 * _mean(r["time_s"] for r in rows),
        "n_failed": sum(s != "ok" for s in statuses),
        "n_errors": sum(s.startswith("error") for s in statuses),
    }


@dataclass
class BenchmarkSummary:
    """Aggregated statistics (see :func:`aggregate`) per method and per (method, axis value).

    ``by_epsilon[method][epsilon]``, ``by_n[method][n]`` and ``by_auc[method][score_auc]``
    pool every other axis; ``by_epsilon_auc[method][(epsilon, score_auc)]`` pools the rest (a
    claim about priors is judged per contamination too: pooling over epsilon lets the cheap
    low-contamination frames dilute the ratio).
    """

    methods: list[str]
    overall: dict[str, dict[str, Any]]
    by_epsilon: dict[str, dict[float, dict[str, Any]]] = field(default_factory=dict)
    by_n: dict[str, dict[int, dict[str, Any]]] = field(default_factory=dict)
    by_auc: dict[str, dict[float, dict[str, Any]]] = field(default_factory=dict)
    by_epsilon_auc: dict[str, dict[tuple[float, float], dict[str, Any]]] = field(default_factory=dict)

    @property
    def epsilons(self) -> list[float]:
        return sorted({e for per in self.by_epsilon.values() for e in per})

    @property
    def ns(self) -> list[int]:
        return sorted({n for per in self.by_n.values() for n in per})

    @property
    def aucs(self) -> list[float]:
        return sorted({a for per in self.by_auc.values() for a in per})


def group_rows(rows: Iterable[Mapping[str, Any]], *keys: str) -> dict[tuple, list[Mapping[str, Any]]]:
    groups: dict[tuple, list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in keys), []).append(row)
    return groups


def summarize(rows: Sequence[Mapping[str, Any]]) -> BenchmarkSummary:
    """Aggregate trial rows; methods keep their first-seen order."""
    methods = list(dict.fromkeys(str(r["method"]) for r in rows))
    by_method = group_rows(rows, "method")
    overall = {m: aggregate(by_method[(m,)]) for m in methods}
    by_epsilon: dict[str, dict[float, dict[str, Any]]] = {m: {} for m in methods}
    for (m, e), group in sorted(group_rows(rows, "method", "epsilon").items(), key=lambda kv: kv[0][1]):
        by_epsilon[m][float(e)] = aggregate(group)
    by_n: dict[str, dict[int, dict[str, Any]]] = {m: {} for m in methods}
    for (m, n), group in sorted(group_rows(rows, "method", "n").items(), key=lambda kv: kv[0][1]):
        by_n[m][int(n)] = aggregate(group)
    by_auc: dict[str, dict[float, dict[str, Any]]] = {m: {} for m in methods}
    for (m, a), group in sorted(group_rows(rows, "method", "score_auc").items(), key=lambda kv: kv[0][1]):
        by_auc[m][float(a)] = aggregate(group)
    by_epsilon_auc: dict[str, dict[tuple[float, float], dict[str, Any]]] = {m: {} for m in methods}
    for (m, e, a), group in sorted(group_rows(rows, "method", "epsilon", "score_auc").items(),
                                   key=lambda kv: kv[0][1:]):
        by_epsilon_auc[m][(float(e), float(a))] = aggregate(group)
    return BenchmarkSummary(methods, overall, by_epsilon, by_n, by_auc, by_epsilon_auc)


def cell_summary_rows(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One aggregated row per (method, grid cell), in trial order."""
    keys = ("method", "epsilon", "noise_sigma", "score_auc", "n", "outlier_kind")
    groups = group_rows(rows, *keys)
    return [{**dict(zip(keys, key)), **aggregate(group)} for key, group in groups.items()]
