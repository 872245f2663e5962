"""Preemptive RANSAC (Nister 2003; docs/algorithms.md, `preemptive`): the preemption function, exact
counts, a constant hypothesis count."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation.methods.preemptive import (
    PreemptiveVerification,
    preemption_function,
    preemptive_evaluations,
)
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.scoring import ReprojectionResidual, TruncatedQuadratic
from stereovo.estimation.roles.verification import ScoringContext
from stereovo.simulation import SimulationConfig, simulate_frame
from tests.support.verification import good_and_bad, estimate, succeeded


def test_preemption_function_and_the_98800_evaluations():
    i = np.array([1, 99, 100, 199, 200, 799, 800])
    np.testing.assert_array_equal(preemption_function(i, 500, 100), [500, 500, 250, 250, 125, 3, 1])
    assert preemptive_evaluations(800, 500, 100) == 98_800
    assert preemptive_evaluations(5000, 500, 100) == 98_800
    assert preemptive_evaluations(300, 500, 100) == 99 * 500 + 100 * 250 + 100 * 125 + 62


def test_preemptive_verifier_counts_exactly_and_keeps_the_best():
    frame = simulate_frame(SimulationConfig(n_correspondences=900, outlier_ratio=0.5), 12)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    ctx = ScoringContext(problem, ReprojectionResidual(9.0), TruncatedQuadratic(), 9.0)
    rng = np.random.default_rng(6)
    R, t = good_and_bad(frame, 1, 499, rng)
    verifier = PreemptiveVerification(500, 100)
    scores, checks = verifier.verify(ctx, R, t, rng)
    assert verifier.last_preemption_evaluations == 98_800  # stopped at i = 800 whatever the data
    assert checks == 98_800 + (900 - 799)  # plus the winner's unseen observations
    assert np.argmax(scores) == 0 and np.sum(np.isfinite(scores)) == 1
    assert scores[0] == pytest.approx(ctx.score(R[:1], t[:1])[0])  # the winner's full MSAC score


def test_preemptive_uses_a_constant_hypothesis_count():
    config = SimulationConfig(n_correspondences=300, outlier_ratio=0.5)
    for i in range(3):
        frame = simulate_frame(config, 300 + i)
        est = estimate(frame, "preemptive", i)
        assert est.n_hypotheses == 500 and est.report.n_scored + est.report.n_degenerate == 500
        assert succeeded(est, frame)
    small = estimate(frame, "preemptive", 0, preemptive_hypotheses=64, preemptive_block=16)
    assert small.n_hypotheses == 64


def test_preemptive_fails_more_often_than_adaptive_ransac_at_high_contamination():
    # epsilon 0.88, N 150: 18 inliers, P(no all-inlier triplet among 500) = 0.48, and a good
    # hypothesis can still be preempted on the first observations; RANSAC adapts (~3000 draws).
    config = SimulationConfig(n_correspondences=150, outlier_ratio=0.88, outlier_mix=(1, 0, 0))
    ok = {"ransac": 0, "preemptive": 0}
    for i in range(5):
        frame = simulate_frame(config, 400 + i)
        for method in ok:
            est = estimate(frame, method, i)
            ok[method] += succeeded(est, frame)
    assert ok["ransac"] >= 4 and ok["preemptive"] <= ok["ransac"] - 2, ok


def test_preemptive_fails_a_model_its_m_hypotheses_cannot_confirm():
    """Nister's M is the search's cap: a returned model whose inliers would need more than M draws
    for the confidence fails (fail_at_cap), where the paper's end returns it; as a budget it is the
    stop itself and returns the best as the paper does."""
    from stereovo import estimate_motion
    from stereovo.metrics import frame_metrics

    # hostile stream frame 23 (N 1000, eps 0.9): 16 "inliers" of 845 rows, 1.7 m off
    frame = simulate_frame(SimulationConfig(n_correspondences=1000, outlier_ratio=0.9, outliers="hostile"), 23)
    paper = estimate_motion(frame.prev, frame.curr, frame.camera, method="preemptive", rng=23, fail_at_cap=False)
    assert paper.ok and paper.n_hypotheses == 500 and frame_metrics(paper, frame.truth).trans_err_m > 1.0
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method="preemptive", rng=23)
    assert est.status.startswith("failed: no confident consensus (the cap of 500 hypotheses")
    assert est.n_hypotheses == 500
    budget = estimate_motion(frame.prev, frame.curr, frame.camera, method="preemptive", rng=23, budget=500)
    assert budget.ok
    np.testing.assert_array_equal(budget.rotation, paper.rotation)
