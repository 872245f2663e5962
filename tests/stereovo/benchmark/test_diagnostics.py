"""stereovo.benchmark.diagnostics: the claim diagnostics measured on the run's frames."""

from __future__ import annotations

import pytest

from stereovo import benchmark as bm
from stereovo.benchmark import AGREES, DISAGREES
from tests.support.benchmark import summary_stats, make_summary, judge_claims


def test_preemptive_miss_probability_and_its_diagnosis():
    assert bm.preemptive_miss_probability(0.0, 1) == 0.0
    assert bm.preemptive_miss_probability(0.8, 500) == pytest.approx((1 - 0.2 ** 3) ** 500)
    assert bm.preemptive_miss_probability(0.9, 500) > 0.5 > bm.preemptive_miss_probability(0.8, 500)
    by_eps = {"preemptive": {0.2: summary_stats(median_hypotheses=500.0),
                             0.8: summary_stats(success_rate=0.0, median_hypotheses=500.0)}}
    c = judge_claims(make_summary({"preemptive": summary_stats()}, by_eps))["preemptive-unreliable"]
    assert c.verdict == AGREES and "M = 500" in c.diagnosis and "1.8 %" in c.diagnosis


def test_claim_diagnostics_measure_the_runs_frames():
    rows = [{"trial": i, "cell": 0, "repeat": i, "epsilon": 0.8, "noise_sigma": 0.5, "score_auc": 0.9,
             "n": 200, "outlier_kind": "mix"} for i in range(2)]
    d = bm.claim_diagnostics(rows, seed=0, samples_per_frame=50)
    assert set(d) == {"support", "r-ransac-time", "waldsac-time", "clique-robust"}
    assert all("on 2 frames of the run at epsilon 0.8" in v for v in d.values())
    assert d == bm.claim_diagnostics(rows, seed=0, samples_per_frame=50)  # same seed, same figures
    c = judge_claims(make_summary({"ransac": summary_stats(), "waldsac": summary_stats()}))
    with_d = {k: v for k, v in ((x.key, x) for x in bm.check_claims(
        make_summary({"ransac": summary_stats(), "waldsac": summary_stats()}), d))}
    assert c["waldsac-time"].diagnosis == "" and d["waldsac-time"] in with_d["waldsac-time"].diagnosis
    assert d["support"] in with_d["waldsac-time"].diagnosis  # judged against textbook ransac
    assert bm.claim_diagnostics([], seed=0) == {}


def test_the_clique_diagnosis_on_frames_without_a_moving_object_counts_outliers_not_object_points():
    rows = [{"trial": i, "cell": 0, "repeat": i, "epsilon": 0.8, "noise_sigma": 0.5, "score_auc": 0.9,
             "n": 200, "outlier_kind": "hostile"} for i in range(2)]
    text = bm.claim_diagnostics(rows, seed=0, samples_per_frame=10)["clique-robust"]
    assert text.startswith("on 2 frames of the run at epsilon 0.8 (no moving object in them), in ")
    assert "most of inlier-detection's inliers are outliers (median share " in text
    assert "moving-object points" not in text
    mix = bm.claim_diagnostics([{**r, "outlier_kind": "mix"} for r in rows], seed=0, samples_per_frame=10)
    assert "moving-object points" in mix["clique-robust"]


def test_constant_time_diagnosis_reads_the_point_checks():
    by_eps = {"preemptive": {0.2: summary_stats(median_time_ms=70.0, median_point_checks=8e4),
                             0.8: summary_stats(median_time_ms=40.0, median_point_checks=8e4)}}
    c = judge_claims(make_summary({"preemptive": summary_stats()}, by_eps))["preemptive-constant-time"]
    assert c.verdict == DISAGREES  # 70 / 40 ms spread
    assert "(max/min x1.00)" in c.diagnosis  # the scoring itself did not change with epsilon
