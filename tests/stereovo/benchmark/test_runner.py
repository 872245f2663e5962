"""stereovo.benchmark.runner: every estimator sees the identical frame with its own stream, rows do
not depend on the worker count, errors become rows, and the classical estimators get their inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stereovo import benchmark as bm
from stereovo.benchmark import ClassicalEstimator
from tests.support.benchmark import TINY, same_rows, Fingerprint, Raises


def _without_time(rows):
    return [{k: v for k, v in row.items() if k not in bm.TIME_COLUMNS} for row in rows]


def test_every_estimator_sees_the_identical_frame_with_its_own_stream():
    estimators = [("a", Fingerprint()), ("b", Fingerprint()), ("c", Fingerprint())]
    rows = bm.run_benchmark(TINY.trials(), estimators, seed=1, progress=False)
    assert len(rows) == TINY.n_trials * 3
    assert [r["method"] for r in rows[:3]] == ["a", "b", "c"]
    for trial in range(TINY.n_trials):
        mine = [r for r in rows if r["trial"] == trial]
        assert len({r["n_hypotheses"] for r in mine}) == 1  # same frame bytes
        assert len({r["n_scored"] for r in mine}) == 3  # different estimator streams
        assert all(r["success"] and r["precision"] == 1.0 and math.isnan(r["n_hypotheses_to_best"]) for r in mine)
    assert len({r["n_hypotheses"] for r in rows}) == TINY.n_trials  # different frames per trial


def test_same_seed_same_rows_any_worker_count_and_different_seed_differs():
    estimators = bm.classical_estimators(["ransac", "ransac+guided"], max_iterations=300)
    trials = TINY.trials()
    one = bm.run_benchmark(trials, estimators, seed=5, workers=1, progress=False)
    two = bm.run_benchmark(trials, estimators, seed=5, workers=2, progress=False)
    same_rows(_without_time(one), _without_time(two))
    assert [r["trial"] for r in one] == sorted(r["trial"] for r in one)
    other = bm.run_benchmark(trials, estimators, seed=6, workers=1, progress=False)
    assert _without_time(other) != _without_time(one)
    assert all(r["time_s"] > 0 for r in one)
    assert all(16 <= r["n_hypotheses_to_best"] <= r["n_hypotheses"] for r in one)  # a first batch of 16
    assert list(one[0]) == list(bm.TRIAL_COLUMNS)


def test_rows_carry_the_frames_true_inlier_count_and_the_hypothesis_that_found_the_best():
    """``n_true_inliers`` is the frame's labelled inliers (not its N); ``n_hypotheses_to_best`` the loop
    report's ``best_found_at`` (not the hypotheses drawn): recomputed here from the frame and the estimate."""
    from stereovo import estimate_motion

    trial = TINY.trials()[0]
    frame = bm.simulate_trial(trial, 3)

    def estimator(frame, rng):
        return estimate_motion(frame.prev, frame.curr, frame.camera, method="ransac", rng=rng)

    (row,) = bm.run_trial(trial, [("ransac", estimator)], 3)
    est = estimator(frame, np.random.default_rng(bm.estimator_seed(3, trial.cell, trial.repeat, "ransac")))
    assert row["n_true_inliers"] == int(frame.truth.inlier.sum()) < frame.n
    assert row["n_hypotheses_to_best"] == est.report.best_found_at < est.n_hypotheses


def test_raising_estimator_is_recorded_as_an_error_row():
    rows = bm.run_benchmark(TINY.trials()[:1], [("bad", Raises()), ("fine", Fingerprint())], progress=False)
    bad, fine = rows
    assert bad["status"] == "error: RuntimeError: boom second line" and bad["success"] is False
    assert math.isnan(bad["rot_err_deg"]) and fine["status"] == "ok"
    summary = bm.summarize(rows)
    assert summary.overall["bad"]["n_errors"] == 1 and summary.overall["bad"]["success_rate"] == 0.0


def test_run_benchmark_rejects_duplicate_names_and_bad_workers():
    with pytest.raises(ValueError, match="unique"):
        bm.run_benchmark(TINY.trials(), [("a", Fingerprint()), ("a", Fingerprint())], progress=False)
    with pytest.raises(ValueError, match="workers"):
        bm.run_benchmark(TINY.trials(), [("a", Fingerprint())], workers=0, progress=False)


def test_classical_estimators_cover_registry_and_variants():
    from stereovo.estimation import available_methods

    names = [n for n, _ in bm.classical_estimators(max_iterations=100)]
    assert names[: len(available_methods())] == list(available_methods())
    for variant, (base, kind) in bm.GUIDED_VARIANTS.items():
        assert (variant in names) == (base in available_methods())
    pairs = dict(bm.classical_estimators(["ransac+guided", "ransac"], max_iterations=100))
    assert pairs["ransac+guided"] == ClassicalEstimator("ransac", "priors", (("max_iterations", 100),))
    assert pairs["ransac"].inputs is None
    with pytest.raises(ValueError, match=r"unknown method\(s\): nope.*available: ransac"):
        bm.classical_estimators(["ransac", "nope"])


def test_the_options_for_every_method_reach_each_method_that_reads_them_and_run_without_error_rows():
    # preemptive's cap is its M and inlier-detection draws no hypotheses: neither gets (nor refuses) the grid's cap
    pairs = dict(bm.classical_estimators(["ransac", "preemptive", "inlier-detection", "bansac"], max_iterations=300,
                                         local_refit=False))
    assert pairs["ransac"].options == (("local_refit", False), ("max_iterations", 300))
    assert pairs["preemptive"].options == ()  # its final refit refits the one batch's best in the local refit's place
    assert pairs["inlier-detection"].options == ()
    assert pairs["bansac"].options == (("max_iterations", 300),)  # it refits every new best anyway
    rows = bm.run_benchmark(TINY.trials()[:2], list(pairs.items()), seed=3, progress=False)
    assert not [r["status"] for r in rows if r["status"].startswith("error")]
    # an invalid option is left to each estimate, which records it as before
    [(_, bad)] = bm.classical_estimators(["preemptive"], max_iterations=0)
    assert bad.options == (("max_iterations", 0),)


def test_method_inputs_table_is_applied():
    for name, kind in bm.METHOD_INPUTS.items():
        assert ClassicalEstimator(name, kind).inputs == kind
    frame = bm.simulate_trial(TINY.trials()[0], 0)
    order = bm.score_inputs(frame, "order")["order"]
    assert np.all(np.diff(frame.scores[order]) <= 0)
    np.testing.assert_array_equal(bm.score_inputs(frame, "priors")["priors"], frame.scores)
    assert bm.score_inputs(frame, None) == {}


def test_missing_priors_or_order_is_supplied_on_retry(monkeypatch):
    calls = []

    def fake(prev, curr, camera, method, rng, priors=None, order=None, **options):
        calls.append((method, priors is not None, order is not None, float(rng.random())))
        if method == "needs-priors" and priors is None:
            raise ValueError("method 'needs-priors' requires priors= (per-correspondence gamma_i)")
        if method == "needs-order" and order is None:
            raise ValueError("method 'needs-order' requires an order= (PROSAC ranking)")
        if method == "broken":
            raise ValueError("something else entirely")
        return "estimate"

    monkeypatch.setattr(bm.runner, "estimate_motion", fake)  # where ClassicalEstimator looks it up
    frame = bm.simulate_trial(TINY.trials()[0], 0)
    assert ClassicalEstimator("needs-priors")(frame, np.random.default_rng(0)) == "estimate"
    assert calls[0][1:3] == (False, False) and calls[1][1:3] == (True, False)
    assert calls[0][3] == calls[1][3]  # the retry replays the same random stream
    calls.clear()
    assert ClassicalEstimator("needs-order")(frame, np.random.default_rng(0)) == "estimate"
    assert calls[1][1:3] == (False, True)
    with pytest.raises(ValueError, match="something else"):
        ClassicalEstimator("broken")(frame, np.random.default_rng(0))
