"""kernels.depth.resolvable_rows: StereoProblem's disparity rule, as its numpy formulation gives it."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.camera import StereoCamera
from stereovo.estimation.kernels.depth import resolvable_rows
from stereovo.estimation.problem import StereoProblem, resolvable_depth


def _measurements(rng: np.random.Generator, n: int) -> np.ndarray:
    meas = np.column_stack([rng.uniform(0, 1240, n), rng.uniform(0, 375, n), np.zeros(n), np.zeros(n)])
    meas[:, 2] = meas[:, 0] - rng.choice([0.0, 0.05, 0.7071067811865476, 1.4142135623730951, 1.5, 30.0], n)
    meas[:, 3] = meas[:, 1]
    meas[rng.integers(0, n, 3), rng.integers(0, 4, 3)] = [np.nan, np.inf, -np.inf]
    return meas


@pytest.mark.parametrize("sigmas,noise", [(2.0, 0.5), (2, 1), (0.0, 0.5), (1.0, 0.5), (np.float32(2.5), 0.3)])
def test_the_compiled_rule_is_resolvable_depth(sigmas, noise):
    rng = np.random.default_rng(3)
    prev, curr = _measurements(rng, 300), _measurements(rng, 300)
    start_prev, start_curr = rng.random(300) > 0.05, rng.random(300) > 0.05
    expected_prev, expected_curr = start_prev.copy(), start_curr.copy()
    if sigmas > 0:
        expected_prev &= resolvable_depth(prev, noise, sigmas)
        expected_curr &= resolvable_depth(curr, noise, sigmas)
    ours_prev, ours_curr = start_prev.copy(), start_curr.copy()
    threshold = float(sigmas) * np.sqrt(2.0) * float(noise)
    every = resolvable_rows(prev, curr, threshold, bool(sigmas > 0), ours_prev, ours_curr)
    np.testing.assert_array_equal(ours_prev, expected_prev)
    np.testing.assert_array_equal(ours_curr, expected_curr)
    assert every == bool(expected_prev.all() and expected_curr.all()) == False  # noqa: E712
    ones_prev, ones_curr = np.ones(2, bool), np.ones(2, bool)
    assert resolvable_rows(prev[:0], curr[:0], threshold, True, ones_prev[:0], ones_curr[:0])
    assert resolvable_rows(np.array([[10.0, 5, 0, 5]] * 2), np.array([[10.0, 5, 0, 5]] * 2), threshold, True,
                           ones_prev, ones_curr)


def test_problems_flag_the_rows_the_rule_refuses():
    rng = np.random.default_rng(5)
    prev, curr = _measurements(rng, 200), _measurements(rng, 200)
    problem = StereoProblem.build(prev, curr, StereoCamera(), 0.5, 2.0)
    cam = StereoCamera()
    expected = (cam.triangulate_usable(prev, 0.5)[2] & cam.triangulate_usable(curr, 0.5)[2]
                & resolvable_depth(prev, 0.5, 2.0) & resolvable_depth(curr, 0.5, 2.0))
    np.testing.assert_array_equal(problem.usable, expected)
    assert np.isnan(problem.points_prev[~expected]).all() and np.isfinite(problem.points_prev[expected]).all()
