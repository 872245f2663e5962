"""PreparedEstimator: one method's options checked once, the estimates those of estimate_problem."""

from __future__ import annotations

import pickle
import re

import numpy as np
import pytest

from stereovo import available_methods
from stereovo.benchmark.runner import METHOD_INPUTS, score_inputs
from stereovo.estimation import PreparedEstimator, StereoProblem, estimate_problem
from stereovo.simulation import SimulationConfig, simulate_frame
from tests.support.rows import spoil_rows


def _same(a, b) -> None:
    np.testing.assert_array_equal(a.rotation, b.rotation)
    np.testing.assert_array_equal(a.translation, b.translation)
    np.testing.assert_array_equal(a.inliers, b.inliers)
    np.testing.assert_array_equal(a.unusable, b.unusable)
    assert (a.status, a.n_hypotheses, a.n_scored, a.n_point_checks, a.score, a.counters) == (
        b.status, b.n_hypotheses, b.n_scored, b.n_point_checks, b.score, b.counters)


def _problems() -> list[StereoProblem]:
    problems = []
    for seed, sigma in ((1, 0.5), (2, 0.5), (3, 1.0)):
        frame = simulate_frame(SimulationConfig(n_correspondences=150, noise_sigma=sigma), rng=seed)
        problems.append(StereoProblem.build(frame.prev, frame.curr, frame.camera, sigma))
    frame = simulate_frame(SimulationConfig(n_correspondences=150), rng=4)
    prev, curr = spoil_rows(frame, np.arange(0, 150, 7))  # unusable rows: the sub-problem's path
    problems.append(StereoProblem.build(prev, curr, frame.camera, 0.5))
    return problems


PROBLEMS = _problems()


@pytest.mark.parametrize("method", sorted(available_methods()))
def test_estimates_are_those_of_estimate_problem(method):
    options = {"budget": 24, "batch_size": 8} if method not in ("irls", "least-squares") else {}
    prepared = PreparedEstimator(method, **options)
    assert prepared.method == method and prepared.options == options
    for round_ in range(2):  # the second round reuses the options derived in the first
        for i, problem in enumerate(PROBLEMS):
            frame_scores = np.linspace(1.0, 0.01, problem.n)
            inputs = {}
            kind = METHOD_INPUTS.get(method)
            if kind == "order":
                inputs["order"] = np.argsort(-frame_scores, kind="stable")
            elif kind == "probabilities" or method in ("guided", "bansac"):
                inputs["priors"] = frame_scores
            try:
                expected = estimate_problem(problem, method=method, rng=10 * i + round_, **inputs, **options)
            except ValueError as error:
                with pytest.raises(ValueError, match=re.escape(str(error))):
                    prepared.estimate(problem, rng=10 * i + round_, **inputs)
                continue
            _same(prepared.estimate(problem, rng=10 * i + round_, **inputs), expected)


def test_the_generator_advances_as_under_estimate_problem():
    ours, theirs = np.random.default_rng(3), np.random.default_rng(3)
    prepared = PreparedEstimator("msac", budget=16)
    for problem in PROBLEMS[:2]:
        _same(prepared.estimate(problem, rng=ours), estimate_problem(problem, method="msac", rng=theirs, budget=16))
        assert ours.bit_generator.state == theirs.bit_generator.state


def test_errors_are_those_of_estimate_problem():
    with pytest.raises(ValueError, match="unknown method"):
        PreparedEstimator("no-such-method")
    prepared = PreparedEstimator("msac", noise_sigma=0.5)
    with pytest.raises(ValueError, match=r"noise_sigma=0.5 differs from the problem's 1.0"):
        prepared.estimate(PROBLEMS[2])
    prepared.estimate(PROBLEMS[0])  # a problem with the given noise is fine
    with pytest.raises(ValueError, match="differs from the problem's"):
        PreparedEstimator("msac", min_disparity_sigmas=3.0).estimate(PROBLEMS[0])
    with pytest.raises(ValueError, match="unknown option"):
        PreparedEstimator("msac", not_an_option=1).estimate(PROBLEMS[0])  # checked on the first estimate, as there
    with pytest.raises(ValueError, match="budget"):
        PreparedEstimator("msac", budget=-1).estimate(PROBLEMS[0])
    with pytest.raises(ValueError, match="problem must be a StereoProblem"):
        PreparedEstimator("msac").estimate(np.zeros((10, 4)))
    with pytest.raises(ValueError, match="needs order"):
        PreparedEstimator("prosac").estimate(PROBLEMS[0])


def test_options_are_a_copy_and_the_estimator_pickles_by_name():
    options = {"budget": 8, "threshold_px": 2.0}
    prepared = PreparedEstimator("msac", **options)
    prepared.options["budget"] = 99
    assert prepared.options == options
    prepared.estimate(PROBLEMS[0], rng=1)
    again = pickle.loads(pickle.dumps(prepared))
    assert again.method == "msac" and again.options == options
    _same(again.estimate(PROBLEMS[1], rng=2), prepared.estimate(PROBLEMS[1], rng=2))
