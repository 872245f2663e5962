"""The compiled verification kernels (stereovo/estimation/kernels/verification.py): the compiled SPRT
against a point-by-point reference, the SPRT stop's kept answers against fresh ones (Matas & Chum
2005; Chum & Matas 2008), and the compiled T(d,d) pretest route."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from stereovo.estimation.kernels.residuals import forward_reprojection_sq
from stereovo.estimation.kernels.mahalanobis import mahalanobis_sq
from stereovo.estimation.kernels.verification import sprt_verify, sprt_verify_mahalanobis
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.methods.sprt import SprtTermination, SprtTest
from stereovo.estimation.methods.tdd import TddVerification
from stereovo.geometry import random_rotation
from stereovo.simulation import SimulationConfig, simulate_frame
from tests.support.verification import near_truth_motions, sprt_by_hand, tdd_setup


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
    expected = sprt_by_hand(sq, samples, perm, threshold_sq, log_consistent, log_inconsistent, log_A)
    np.testing.assert_array_equal(accepted, expected[0])
    np.testing.assert_array_equal(checked, expected[1])
    np.testing.assert_array_equal(consistent, expected[2])
    np.testing.assert_array_equal(residual_sq[accepted], sq[accepted])  # the same arithmetic, bit for bit
    if design == (0.1, 0.001, 4.0) and n == 300:
        assert np.any(accepted) and not np.all(accepted)  # both outcomes were exercised
        assert np.min(checked[~accepted]) == int(4.0 / log_inconsistent) + 1


@pytest.mark.parametrize("n", [5, 40, 300])
@pytest.mark.parametrize("design", [(0.4, 0.05, 1.5), (0.1, 0.001, 4.0), (0.1, 0.01, 60.0), (0.5, 0.6, 2.0)])
@pytest.mark.parametrize("cap", [0.0, 7.8])
def test_compiled_mahalanobis_sprt_equals_the_point_by_point_test(n, design, cap):
    # The 3-D Mahalanobis route (probabilistic's judge): the same walk as the reprojection one, on the
    # distances mahalanobis_sq computes (capped at the gate or not), which an accepted row repeats bit for bit.
    epsilon, delta, log_A = design
    log_consistent, log_inconsistent = math.log(delta / epsilon), math.log((1 - delta) / (1 - epsilon))
    frame, problem = problem_of(n)
    rng = np.random.default_rng(n + 1)
    R, t = hypotheses(frame, rng, 3, 6, 12)
    threshold_sq = 7.8
    points = (problem.points_prev, problem.points_curr, problem.camera.parameters, problem.noise_sigma**2)
    sq = mahalanobis_sq(R, t, *points, cap)
    perm = rng.permutation(n).astype(np.int64)
    samples = np.stack([rng.choice(n, 3, replace=False) for _ in range(R.shape[0])]).astype(np.int64)
    samples[0] = perm[:3]
    accepted, checked, consistent, residual_sq = sprt_verify_mahalanobis(
        R, t, *points, cap, threshold_sq, samples, perm, log_consistent, log_inconsistent, log_A,
    )
    expected = sprt_by_hand(sq, samples, perm, threshold_sq, log_consistent, log_inconsistent, log_A)
    np.testing.assert_array_equal(accepted, expected[0])
    np.testing.assert_array_equal(checked, expected[1])
    np.testing.assert_array_equal(consistent, expected[2])
    np.testing.assert_array_equal(residual_sq[accepted], sq[accepted])
    if design == (0.1, 0.001, 4.0) and n == 300:
        assert np.any(accepted) and not np.all(accepted)
        assert np.all(accepted[:3])  # the true motion survives


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


# --- The compiled T(d,d) pretest: where it stops, what it measures, the types it is handed ---


def _kernel_points(sample, u, n):
    """The compiled pre-test's points (kernels_verification.tdd_pretest's rule): point j is the floor(u_j (n - 3 - j))-th,
    in increasing index, of the points not yet excluded (the sample and the earlier points)."""
    excluded, points = set(int(s) for s in sample), []
    for j, uj in enumerate(u):
        rest = [i for i in range(n) if i not in excluded]
        point = rest[min(int(uj * (n - 3 - j)), len(rest) - 1)]
        points.append(point)
        excluded.add(point)
    return points


def test_tdd_compiled_pretest_stops_at_the_first_miss():
    # hypotheses far off explain no point: with d = 3 each fails at its first point and costs one check
    frame, problem, ctx = tdd_setup(60)
    rng = np.random.default_rng(3)
    R = np.stack([random_rotation(rng, np.radians(40)) for _ in range(12)])
    t = rng.normal(0, 5.0, (12, 3))
    assert not np.any(ctx.residuals(R, t) < 9.0)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(12)])
    verifier = TddVerification(d=3, adaptive=False)
    scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(2), samples=samples)
    assert np.all(np.isinf(scores)) and checks == 12


def test_tdd_compiled_route_measures_failed_good_hypotheses_with_the_kernels_draws():
    # The reprojection residual: the pre-test (d = 1) and the measuring of failed good ones both run compiled, on
    # the verifier's generator in that order: (H, 1) uniforms for the pre-test, then (failed, measure_points) for the
    # measuring, each turned into points by the kernel's rule. alpha is the mean of the good ones' chances: exact
    # (support outside the sample / (N - 3)) for those that passed, consistent / measure_points for those that failed.
    frame, problem, ctx = tdd_setup(150)
    n, H, m, rng = problem.n, 30, 20, np.random.default_rng(21)
    inl = np.flatnonzero(frame.truth.inlier)
    R, t = near_truth_motions(frame, rng, H)
    samples = np.stack([rng.choice(inl, 3, replace=False) for _ in range(H)])
    mask = ctx.residuals(R, t) < 9.0
    g = np.random.default_rng(5)
    u = g.random((H, 1))
    passed = np.array([mask[h, _kernel_points(samples[h], u[h], n)[0]] for h in range(H)])
    failed = np.flatnonzero(~passed)
    assert 3 <= failed.size <= H - 3
    um = g.random((failed.size, m))
    measured = [mask[h, _kernel_points(samples[h], um[k], n)].sum() for k, h in enumerate(failed)]
    own = np.take_along_axis(mask, samples, axis=1).sum(axis=1)
    chances = np.concatenate([(mask[passed].sum(axis=1) - own[passed]) / (n - 3), np.array(measured) / m])
    v = TddVerification(d=1, measure_points=m, adaptive=False)
    v.on_new_best(frame.truth.inlier, None)
    rng = np.random.default_rng(5)
    scores, checks = v.verify(ctx, R, t, rng, samples=samples)
    np.testing.assert_array_equal(np.isfinite(scores), passed)
    assert checks == failed.size + passed.sum() * n + failed.size * m
    assert v.alpha() == pytest.approx(np.mean(chances), rel=1e-12)
    assert rng.random() == g.random()  # nothing else drawn


def test_tdd_verify_hands_the_kernels_float64_motions_and_int64_samples():
    # kernels_verification takes float64 / int64 arrays, which its wrappers ensure: motions in half or single
    # precision and sample indices held as int32 or floats give the verdicts, counts and alpha of their float64 /
    # int64 copies (numba compiles no float16, and float indices index nothing), on the compiled route with a
    # best model, so the pre-test and the measuring of failed good hypotheses both run.
    frame, problem, ctx = tdd_setup(150)
    rng = np.random.default_rng(22)
    inl = np.flatnonzero(frame.truth.inlier)
    R, t = near_truth_motions(frame, rng, 30)
    R16, t16 = R.astype(np.float16), t.astype(np.float16)
    samples = np.stack([rng.choice(inl, 3, replace=False) for _ in range(30)])

    def run(R, t, samples):
        v = TddVerification(d=1, measure_points=20, adaptive=False)
        v.on_new_best(frame.truth.inlier, None)
        scores, checks = v.verify(ctx, R, t, np.random.default_rng(6), samples=samples)
        return scores.tolist(), checks, v.counters()

    expected = run(R16.astype(float), t16.astype(float), samples)
    assert 0 < expected[2]["tdd_passed"] < 30 and expected[2]["tdd_measure_checks"] > 0
    assert run(R16, t16, samples) == expected
    assert run(R16.astype(float), t16.astype(float), samples.astype(np.int32)) == expected
    assert run(R16.astype(float), t16.astype(float), samples.astype(float)) == expected
