"""The compiled SPRT against a point-by-point reference, and the SPRT stop's kept answers against
fresh ones (Matas & Chum 2005; Chum & Matas 2008)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from stereovo.estimation.kernels.residuals import forward_reprojection_sq
from stereovo.estimation.kernels.verification import sprt_verify
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.methods.sprt import SprtTermination, SprtTest
from stereovo.geometry import random_rotation
from stereovo.simulation import SimulationConfig, simulate_frame


def problem_of(n, seed=3):
    frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=0.5), seed)
    return frame, StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)


def hypotheses(frame, rng, n_good, n_near, n_far):
    """The true motion, motions a little off (partly consistent) and far off (rejected early)."""
    R, t = [], []
    for count, degrees, metres in ((n_good, 0.0, 0.0), (n_near, 0.3, 0.03), (n_far, 10.0, 1.0)):
        for _ in range(count):
            R.append(random_rotation(rng, np.radians(degrees)) @ frame.truth.rotation if degrees else frame.truth.rotation)
            t.append(frame.truth.translation + (rng.normal(0, metres, 3) if metres else 0.0))
    return np.ascontiguousarray(np.stack(R)), np.ascontiguousarray(np.stack(t))


def reference(sq, samples, perm, threshold_sq, log_consistent, log_inconsistent, log_A):
    """Wald's test one point at a time, in ``perm``'s order, own sample skipped."""
    out = []
    for h in range(sq.shape[0]):
        log_lambda, checked, consistent, alive = 0.0, 0, 0, True
        for n in perm:
            if n in samples[h]:
                continue
            checked += 1
            if sq[h, n] < threshold_sq:
                consistent += 1
                log_lambda += log_consistent
            else:
                log_lambda += log_inconsistent
                if log_lambda > log_A:
                    alive = False
                    break
        out.append((alive, checked, consistent))
    return out


@pytest.mark.parametrize("n", [5, 40, 300])
@pytest.mark.parametrize("design", [(0.4, 0.05, 1.5), (0.1, 0.001, 4.0), (0.1, 0.01, 60.0), (0.5, 0.6, 2.0)])
def test_compiled_sprt_equals_the_point_by_point_test(n, design):
    # (0.1, 0.001, log A 4): 39 checks before any rejection, a first block of 39; log A 60 at N 40 or
    # less: no rejection possible (one block of N); delta > epsilon: the "inconsistent" step is
    # negative, the kernel must not size a block from it.
    epsilon, delta, log_A = design
    log_consistent, log_inconsistent = math.log(delta / epsilon), math.log((1 - delta) / (1 - epsilon))
    frame, problem = problem_of(n)
    rng = np.random.default_rng(n)
    R, t = hypotheses(frame, rng, 3, 6, 12)
    threshold_sq = 9.0
    sq = forward_reprojection_sq(R, t, problem.points_prev, problem.curr, problem.camera.parameters)
    perm = rng.permutation(n).astype(np.int64)
    samples = np.stack([rng.choice(n, 3, replace=False) for _ in range(R.shape[0])]).astype(np.int64)
    samples[0] = perm[:3]  # a sample at the head of the order: the first block decides less
    samples[-1] = perm[-3:]
    accepted, checked, consistent, residual_sq = sprt_verify(
        R, t, problem.points_prev, problem.curr, problem.camera.parameters, threshold_sq, samples, perm,
        log_consistent, log_inconsistent, log_A,
    )
    expected = reference(sq, samples, perm, threshold_sq, log_consistent, log_inconsistent, log_A)
    np.testing.assert_array_equal(accepted, [a for a, _, _ in expected])
    np.testing.assert_array_equal(checked, [c for _, c, _ in expected])
    np.testing.assert_array_equal(consistent, [k for _, _, k in expected])
    np.testing.assert_array_equal(residual_sq[accepted], sq[accepted])  # the same arithmetic, bit for bit
    if design == (0.1, 0.001, 4.0) and n == 300:
        assert np.any(accepted) and not np.all(accepted)  # both outcomes were exercised
        assert np.min(checked[~accepted]) == int(4.0 / log_inconsistent) + 1


def test_compiled_sprt_with_no_hypotheses():
    frame, problem = problem_of(40)
    accepted, checked, consistent, residual_sq = sprt_verify(
        np.zeros((0, 3, 3)), np.zeros((0, 3)), problem.points_prev, problem.curr, problem.camera.parameters,
        9.0, np.zeros((0, 3), dtype=np.int64), np.arange(40, dtype=np.int64), -1.0, 0.1, 4.0,
    )
    assert accepted.shape == checked.shape == consistent.shape == (0,) and residual_sq.shape == (0, 40)


def test_sprt_stop_keeps_answers_only_while_the_past_draws_and_tests_are_unchanged():
    verifier = SimpleNamespace(history=[SprtTest(0.5, 0.05, 4.0)])
    stop = SprtTermination(verifier, confidence=0.99, max_iterations=10_000)

    def fresh(count, confidence=0.99):
        return SprtTermination(SimpleNamespace(history=list(verifier.history)), confidence, 10_000).required(count, 100)

    assert stop.required(50, 100) == fresh(50) == 49
    verifier.history[0].draws = 30  # the current test's draws: not read by the bound
    assert stop.required(50, 100) == fresh(50) == 49
    verifier.history.append(SprtTest(0.5, 0.05, 2.0))  # a redesign: 30 draws under A = 4 now count
    assert stop.required(50, 100) == fresh(50) != 49
    verifier.history[0].draws = 40
    assert stop.required(50, 100) == fresh(50)
    assert stop.required(70, 100) == fresh(70) and stop.required(50, 100) == fresh(50)
    stop.confidence = 0.5
    assert stop.required(50, 100) == fresh(50, 0.5) < fresh(50)
