"""stereovo.benchmark.aggregation: the summary of hand-made rows, and the trials CSV round trip."""

from __future__ import annotations

import math

import pytest

from stereovo import benchmark as bm
from tests.support.benchmark import TINY, same_rows, Fingerprint, Raises


def _row(method, eps, n, success, rot, trans, hyps, checks, time_s, status="ok", precision=1.0, recall=0.5):
    return {"method": method, "epsilon": eps, "n": n, "noise_sigma": 0.5, "score_auc": 0.75, "outlier_kind": "mix",
            "success": success, "rot_err_deg": rot, "trans_err_m": trans, "precision": precision, "recall": recall,
            "n_hypotheses": hyps, "n_point_checks": checks, "time_s": time_s, "status": status}


def test_summary_aggregates_hand_made_rows():
    rows = [
        _row("a", 0.2, 100, True, 0.1, 0.01, 32, 3200, 0.010),
        _row("a", 0.2, 200, True, 0.3, 0.03, 64, 6400, 0.030),
        _row("a", 0.8, 100, False, 5.0, 1.0, 1000, 100000, 0.100, status="failed: no consensus",
             precision=0.0, recall=0.0),
        _row("b", 0.2, 100, False, math.nan, math.nan, 0, 0, 0.001, status="error: ValueError: x",
             precision=math.nan, recall=math.nan),
    ]
    s = bm.summarize(rows)
    assert s.methods == ["a", "b"] and s.epsilons == [0.2, 0.8] and s.ns == [100, 200] and s.aucs == [0.75]
    a = s.overall["a"]
    assert a["frames"] == 3 and a["success_rate"] == pytest.approx(2 / 3)
    assert a["median_rot_err_deg"] == pytest.approx(0.3) and a["median_trans_err_m"] == pytest.approx(0.03)
    assert a["mean_precision"] == pytest.approx(2 / 3) and a["mean_recall"] == pytest.approx(1 / 3)
    assert a["median_hypotheses"] == 64 and a["mean_hypotheses"] == pytest.approx(1096 / 3)
    assert a["median_point_checks"] == 6400 and a["median_time_ms"] == pytest.approx(30.0)
    assert a["n_failed"] == 1 and a["n_errors"] == 0
    assert s.by_epsilon["a"][0.2]["frames"] == 2 and s.by_epsilon["a"][0.8]["success_rate"] == 0.0
    assert s.by_n["a"][100]["median_time_ms"] == pytest.approx(55.0)
    assert s.by_auc["a"][0.75]["frames"] == 3
    b = s.overall["b"]
    assert b["success_rate"] == 0.0 and math.isnan(b["median_rot_err_deg"]) and b["n_errors"] == 1
    cells = bm.cell_summary_rows(rows)
    assert [(c["method"], c["epsilon"], c["n"], c["frames"]) for c in cells] == [
        ("a", 0.2, 100, 1), ("a", 0.2, 200, 1), ("a", 0.8, 100, 1), ("b", 0.2, 100, 1)]
    table = bm.overall_table(s)
    assert table.count("\n") == 3 and "`a`" in table and "66.7 %" in table and "n/a" in table


def test_trials_csv_round_trip(tmp_path):
    rows = bm.run_benchmark(TINY.trials()[:2], [("a", Fingerprint()), ("bad", Raises())], progress=False)
    bm.write_outputs(rows, tmp_path, {"grid": TINY.describe(), "seed": 0, "max_iterations": 300}, plots=False)
    back = bm.read_trials_csv(tmp_path / "trials.csv")
    same_rows(back, rows)
    for name in ("trials.csv", "summary.csv", "cells.csv", "summary.md", "claims.md"):
        assert (tmp_path / name).stat().st_size > 0
    text = (tmp_path / "summary.md").read_text()
    assert "max_iterations = 300" in text and "raised" in text


def test_n_failed_counts_every_row_not_ok_including_raised_estimators():
    # n_failed counts every status other than "ok": an estimator that raised ("error: ...") failed too;
    # n_errors counts only those. Hand-made: 1 ok, 2 "failed: ...", 3 "error: ..." -> 5 failed, 3 errors.
    statuses = ["ok", "failed: no consensus", "failed: degenerate sample",
                "error: ValueError: x", "error: RuntimeError: y", "error: KeyError: z"]
    rows = [_row("a", 0.2, 100, s == "ok", 0.1, 0.01, 10, 100, 0.001, status=s) for s in statuses]
    a = bm.aggregate(rows)
    assert a["frames"] == 6
    assert a["n_errors"] == 3
    assert a["n_failed"] == 5
    assert bm.summarize(rows).overall["a"]["n_failed"] == 5


def test_hypotheses_to_the_best_model_are_averaged_not_medianed():
    # The column is a mean (its name says so): on 1, 2 and 30 hypotheses it is 11, where a median is 2.
    rows = []
    for to_best in (1, 2, 30):
        r = _row("a", 0.2, 100, True, 0.1, 0.01, 40, 100, 0.001)
        r["n_hypotheses_to_best"] = to_best
        rows.append(r)
    assert bm.aggregate(rows)["mean_hypotheses_to_best"] == pytest.approx(11.0)


def test_cell_summary_rows_keep_noise_levels_apart():
    # A grid cell is (method, epsilon, noise_sigma, score_auc, n, outlier_kind): two noise levels of the
    # same other axes are two cells, each with its own statistics.
    rows = []
    for sigma, rot in ((0.5, 0.1), (0.5, 0.3), (2.0, 1.0), (2.0, 3.0), (2.0, 5.0)):
        r = _row("a", 0.2, 100, True, rot, 0.01, 10, 100, 0.001)
        r["noise_sigma"] = sigma
        rows.append(r)
    cells = bm.cell_summary_rows(rows)
    assert [(c["method"], c["noise_sigma"], c["frames"]) for c in cells] == [("a", 0.5, 2), ("a", 2.0, 3)]
    assert cells[0]["median_rot_err_deg"] == pytest.approx(0.2)  # median of 0.1, 0.3
    assert cells[1]["median_rot_err_deg"] == pytest.approx(3.0)  # median of 1, 3, 5
