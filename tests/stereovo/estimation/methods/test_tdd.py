"""R-RANSAC with the T(d,d) pretest (Matas & Chum 2002/2004): pass rates, exact costs, when the
pretest pays, and the stop stretched by the pass probability."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import binom

import stereovo.estimation.methods.tdd as tdd_module
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.scoring import InlierCount, ReprojectionResidual
from stereovo.estimation.methods.tdd import TddVerification, pass_probability, random_points_excluding
from stereovo.estimation.roles.verification import ScoringContext
from stereovo.geometry import random_rotation
from stereovo.simulation import SimulationConfig, simulate_frame
from tests.support.verification import setup, good_and_bad, estimate, succeeded, tdd_setup, near_truth_motions


def test_pretest_points_exclude_the_sample_and_are_uniform():
    rng = np.random.default_rng(0)
    samples = np.tile([0, 1, 2], (20_000, 1))
    picked = random_points_excluding(samples, 8, 1, rng)[:, 0]
    assert not np.isin(picked, [0, 1, 2]).any()
    np.testing.assert_allclose(np.bincount(picked, minlength=8)[3:] / picked.size, 0.2, atol=0.01)
    two = random_points_excluding(np.tile([5, 6, 7], (1000, 1)), 10, 2, rng)
    assert np.all(two[:, 0] != two[:, 1]) and not np.isin(two, [5, 6, 7]).any()


def test_tdd_pass_rates_and_exact_cost():
    frame, problem, ctx = setup()
    rng = np.random.default_rng(1)
    n_good, n_bad = 2000, 2000
    R, t = good_and_bad(frame, n_good, n_bad, rng)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(n_good + n_bad)])
    verifier = TddVerification(d=1)
    scores, checks = verifier.verify(ctx, R, t, rng, samples=samples)
    passed = np.isfinite(scores)
    # Good model: passes iff its random non-sample point is inside its gate.
    consistent = ctx.residuals(R[:1], t[:1])[0] < 9.0
    w = consistent.mean()
    lo, hi = binom.interval(0.999, n_good, w)
    assert lo <= passed[:n_good].sum() <= hi
    # Wrong models pass at their own (small) consistency rate delta.
    delta = np.mean(ctx.residuals(R[n_good:], t[n_good:]) < 9.0)
    lo, hi = binom.interval(0.999, n_bad, delta)
    assert lo <= passed[n_good:].sum() <= hi
    # Cost: one check per failing hypothesis, N per survivor (d + P(pass) (N - d) on average).
    assert checks == (~passed).sum() * 1 + passed.sum() * problem.n
    # Survivors carry their full score.
    np.testing.assert_array_equal(scores[passed], ctx.score(R[passed], t[passed]))


def test_compiled_tdd_pretest_points_are_uniform_and_exclude_the_sample():
    from stereovo.estimation.kernels.verification import tdd_pretest

    frame, problem, ctx = setup()
    H, d = 4000, 3
    R = np.repeat(frame.truth.rotation[None], H, axis=0)
    t = np.repeat(frame.truth.translation[None], H, axis=0)
    samples = np.tile(np.array([5, 0, 299]), (H, 1))
    # a gate of +inf passes every point, so all d are checked; record which by perturbing one row at a time
    passed, checks, consistent = tdd_pretest(R, t, problem.points_prev, problem.curr, problem.camera.parameters,
                                             np.inf, samples, np.random.default_rng(0).random((H, d)), False)
    assert np.all(passed) and np.all(checks == d) and np.all(consistent == d)
    # the same uniforms select the points the closed-form shift gives: distinct, never 0, 5 or 299
    u = np.random.default_rng(1).random((H, d))
    picked = []
    for h in range(200):
        excluded = sorted([0, 5, 299])
        row = []
        for j in range(d):
            idx = min(int(u[h, j] * (problem.n - 3 - j)), problem.n - 4 - j)
            for e in excluded:
                if idx >= e:
                    idx += 1
            excluded = sorted(excluded + [idx])
            row.append(idx)
        picked.append(row)
    picked = np.array(picked)
    assert not np.isin(picked, [0, 5, 299]).any() and all(len(set(r)) == d for r in picked)
    # pass rate of the true motion on the pre-test = its support fraction among the other points
    sq = ctx.residuals(frame.truth.rotation[None], frame.truth.translation[None])[0]
    support = np.delete(sq < ctx.threshold_sq, [0, 5, 299])
    passed, checks, _ = tdd_pretest(R, t, problem.points_prev, problem.curr, problem.camera.parameters,
                                    ctx.threshold_sq, samples, np.random.default_rng(2).random((H, 1)), True)
    lo, hi = binom.interval(0.999, H, support.mean())
    assert lo <= passed.sum() <= hi and np.all(checks == 1)


def test_tdd_measured_pass_probability_matches_that_of_true_all_inlier_fits():
    """The verifier's alpha (mean pass probability of the hypotheses whose samples lie in the best
    model's inliers) against the pass rate of minimal fits on truly all-inlier samples."""
    from stereovo.estimation.roles.solvers import minimal_hypotheses

    frame = simulate_frame(SimulationConfig(n_correspondences=500, outlier_ratio=0.5), 21)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    threshold = 9.0
    ctx = ScoringContext(problem, ReprojectionResidual(threshold), InlierCount(), threshold)
    rng = np.random.default_rng(4)
    inl = np.flatnonzero(frame.truth.inlier)
    truth_samples = np.stack([rng.choice(inl, 3, replace=False) for _ in range(2000)])
    R, t, valid = minimal_hypotheses(problem, truth_samples, 2)
    sq = ctx.residuals(R[valid], t[valid])
    own = np.take_along_axis(sq < threshold, truth_samples[valid], axis=1).sum(axis=1)
    true_alpha = np.mean(((sq < threshold).sum(axis=1) - own) / (problem.n - 3))
    verifier = TddVerification(1, max_measured=10_000)
    verifier.on_new_best(frame.truth.inlier, None)
    mixed = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(6000)])
    Rm, tm, validm = minimal_hypotheses(problem, mixed, 2)
    verifier.verify(ctx, Rm[validm], tm[validm], rng, samples=mixed[validm])
    counters = verifier.counters()
    assert counters["tdd_good_measured"] > 400
    assert counters["tdd_alpha"] == pytest.approx(true_alpha, rel=0.15), (counters, true_alpha)
    assert counters["tdd_alpha"] < 0.6 * (1 - 0.5)  # far below the textbook w^d


def test_r_ransac_at_eps_08_is_not_capped_and_switches_off_a_pretest_that_cannot_pay():
    """eps 0.8, N 500: the measured good-model pass rate (~0.1 with polished fits, a few per cent with
    raw ones) makes T(1,1) a loss under the cost model, so the pre-test switches itself off and the
    run stops by the bound, well inside max_iterations, and finds the motion."""
    config = SimulationConfig(n_correspondences=500, outlier_ratio=0.8)
    draws = []
    for seed in range(6):
        frame = simulate_frame(config, 1000 + seed)
        est = estimate(frame, "r-ransac", seed)
        counters = est.report.counters
        assert succeeded(est, frame), seed
        assert counters["tdd_off"] > 0 and counters["tdd_switches"] >= 1
        assert counters["tdd_alpha"] < 0.2  # measured (or -1: switched off on the optimistic bound first)
        draws.append(est.n_hypotheses)
    assert max(draws) < 10_000 and np.median(draws) < 3000, draws


def test_tdd_pretest_stays_on_where_it_pays():
    """Low noise and a generous gate (every inlier passes, alpha ~ w = 0.5), N = 2000, a cheap fit
    (t_M = 20 point checks): d + P(pass) N + t_M (1 - alpha) < alpha N, so the pre-test stays on."""
    from stereovo.estimation.roles.solvers import minimal_hypotheses

    frame = simulate_frame(SimulationConfig(n_correspondences=2000, outlier_ratio=0.5, noise_sigma=0.05), 3)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    ctx = ScoringContext(problem, ReprojectionResidual(4.0), InlierCount(), 4.0)
    rng = np.random.default_rng(0)
    verifier = TddVerification(1, t_m=20.0)
    verifier.on_new_best(frame.truth.inlier, None)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(3000)])
    R, t, valid = minimal_hypotheses(problem, samples, 2)
    for start in range(0, int(valid.sum()), 128):
        rows = np.flatnonzero(valid)[start : start + 128]
        verifier.verify(ctx, R[rows], t[rows], rng, samples=samples[rows])
    counters = verifier.counters()
    assert counters["tdd_good_measured"] >= 16 and counters["tdd_alpha"] > 0.3
    assert verifier.active and counters["tdd_off"] == 0
    assert counters["tdd_passed"] < 0.3 * counters["tdd_tested"]


def test_tdd_pretest_points_are_the_smallest_random_keys_outside_the_sample():
    # The documented draw: one uniform key per correspondence, +inf on the row's own sample, then the
    # d smallest keys in increasing order. Rebuilt here from the same seed.
    samples = np.array([[0, 1, 2], [5, 9, 3], [7, 8, 6]])
    for d in (1, 2, 4):
        got = random_points_excluding(samples, 12, d, np.random.default_rng(11))
        keys = np.random.default_rng(11).random((3, 12))
        for row, sample in enumerate(samples):
            keys[row, sample] = np.inf
        np.testing.assert_array_equal(got, np.argsort(keys, axis=1)[:, :d])
        for row, sample in enumerate(samples):
            assert not set(got[row]) & set(sample) and len(set(got[row])) == d


# --- The T(d,d) pretest and its measuring, by hand, and its options ---


class _OtherResidual:
    """Stands in for ReprojectionResidual in the tdd module's type test: the numpy route is taken."""


def _two_point_chance(c, m):
    """The chance that 2 distinct points drawn from m, c of them consistent, are both consistent."""
    c, m = np.asarray(c, float), np.asarray(m, float)
    return np.maximum(c, 0) * np.maximum(c - 1, 0) / (np.maximum(m, 1) * np.maximum(m - 1, 1))


def _rates(v, *, on, off, passed, alpha=None, good=0):
    """The verifier's measured rates as its verify calls leave them: hypotheses verified with the test on and
    off, the sum of their pass chances, the mean pass chance of the good ones measured and how many."""
    v.n_on, v.n_off, v._pass_sum, v._alpha, v._good = on, off, passed, alpha, good


def _pays(t_m, d, p_pass, alpha, n):
    return (t_m + d + p_pass * (n - d)) / alpha < t_m + n


def _adversarial_argpartition(a, kth, axis=-1, **_):
    """np.argpartition's contract and no more: the kth entry in place, the entries before it no larger, those after
    no smaller, each side in an undefined order, here the worst one (reversed); NumPy's own SIMD selection sorts
    small blocks, which would hide a wrong kth."""
    assert a.ndim == 2 and axis in (1, -1)
    kth = kth + a.shape[1] if kth < 0 else kth
    order = np.argsort(a, axis=1, kind="stable")
    return np.concatenate([order[:, :kth][:, ::-1], order[:, kth:kth + 1], order[:, kth + 1:][:, ::-1]], axis=1)


class _TableResidual:
    """A residual model read from a table: hypothesis h (its t[h, 0]) has squared residual table[h, i] on point i
    (found by its k-1 measurement, so sub-problems keep their points); with a cap it bounds as the contract allows,
    returning exactly the cap for every residual at or above it."""

    name = "table"

    def __init__(self, problem, table):
        self._row = {tuple(m): i for i, m in enumerate(problem.prev.tolist())}
        self._table = np.asarray(table, dtype=float)

    def squared(self, problem, R, t, cap=None):
        points = [self._row[tuple(m)] for m in problem.prev.tolist()]
        sq = self._table[np.ix_(np.asarray(t)[:, 0].astype(int), points)]
        return sq if cap is None else np.where(sq >= cap, cap, sq)


def test_tdd_pretest_on_the_numpy_route_by_hand(monkeypatch):
    # d = 2 and no best model yet (nothing to measure): each hypothesis is checked on d random points outside
    # its sample (random_points_excluding with the verifier's generator), in order, stopping at its first miss;
    # it passes when all d are consistent and is then scored on all N points, its d checks counted once. Two
    # batches: the counters add up.
    monkeypatch.setattr(tdd_module, "ReprojectionResidual", _OtherResidual)
    frame = simulate_frame(SimulationConfig(n_correspondences=150, outlier_ratio=0.3), 4)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    ctx = ScoringContext(problem, ReprojectionResidual(9.0), InlierCount(), 9.0)
    rng = np.random.default_rng(8)
    verifier = TddVerification(d=2, adaptive=False)
    for batch, seed in enumerate((1, 2), start=1):
        R = np.stack([random_rotation(rng, np.radians(0.3)) @ frame.truth.rotation for _ in range(30)])
        t = frame.truth.translation + rng.normal(0, 0.03, (30, 3))
        samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(30)])
        sq = ctx.residuals(R, t)
        idx = random_points_excluding(samples, problem.n, 2, np.random.default_rng(seed))
        consistent = np.take_along_axis(sq, idx, axis=1) < 9.0
        passed = consistent.all(axis=1)
        assert 3 <= passed.sum() <= 27 and (~consistent[:, 0]).any() and (consistent[:, 0] & ~consistent[:, 1]).any()
        first_miss = np.where(~consistent[:, 0], 1, 2)
        scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(seed), samples=samples)
        np.testing.assert_array_equal(np.isinf(scores), ~passed)
        np.testing.assert_array_equal(scores[passed], np.sum(sq[passed] < 9.0, axis=1))
        assert checks == first_miss[~passed].sum() + passed.sum() * problem.n
        # a passed hypothesis' inliers come from the residuals just computed; a failed one's are computed
        for k, fresh in ((np.flatnonzero(passed)[0], False), (np.flatnonzero(~passed)[0], True)):
            mask, computed = ctx.inliers_of(R, t, k)
            np.testing.assert_array_equal(mask, sq[k] < 9.0)
            assert computed is fresh
        c = verifier.counters()
        assert c["tdd_tested"] == 30 * batch
        if batch == 1:
            passed_before = int(passed.sum())
            assert c["tdd_passed"] == passed_before
        else:
            assert c["tdd_passed"] == passed_before + int(passed.sum())


def test_tdd_measures_good_hypotheses_pass_chance_on_the_numpy_route_by_hand(monkeypatch):
    # With a best model, hypotheses drawn from its inliers are good: a good one that passed has its exact pass
    # chance from its full support (its own 3 points left out of the N - 3), a good one that failed is measured
    # on measure_points more random points outside its sample (the same generator, after the pre-test's), which
    # the checks count. alpha is the mean of those chances.
    monkeypatch.setattr(tdd_module, "ReprojectionResidual", _OtherResidual)
    frame = simulate_frame(SimulationConfig(n_correspondences=150, outlier_ratio=0.3), 4)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    ctx = ScoringContext(problem, ReprojectionResidual(9.0), InlierCount(), 9.0)
    n, rng = problem.n, np.random.default_rng(9)
    verifier = TddVerification(d=2, measure_points=20, adaptive=False)
    verifier.on_new_best(frame.truth.inlier, None)
    R = np.stack([random_rotation(rng, np.radians(0.1)) @ frame.truth.rotation for _ in range(30)])
    t = frame.truth.translation + rng.normal(0, 0.01, (30, 3))
    samples = np.stack([rng.choice(np.flatnonzero(frame.truth.inlier), 3, replace=False) for _ in range(30)])
    mask = ctx.residuals(R, t) < 9.0
    g = np.random.default_rng(4)
    consistent = np.take_along_axis(mask, random_points_excluding(samples, n, 2, g), axis=1)
    passed = consistent.all(axis=1)
    failed = np.flatnonzero(~passed)
    assert 3 <= passed.sum() <= 27
    measured = np.take_along_axis(mask[failed], random_points_excluding(samples[failed], n, 20, g), axis=1).sum(axis=1)
    own = np.take_along_axis(mask, samples, axis=1).sum(axis=1)
    chances = np.concatenate([_two_point_chance(mask[passed].sum(axis=1) - own[passed], n - 3),
                              _two_point_chance(measured, 20)])
    scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(4), samples=samples)
    first_miss = np.where(~consistent[:, 0], 1, 2)
    assert checks == first_miss[failed].sum() + passed.sum() * n + failed.size * 20
    c = verifier.counters()
    assert c["tdd_good_measured"] == 30 and c["tdd_alpha"] == pytest.approx(np.mean(chances), rel=1e-12)
    assert (c["tdd_measure_checks"], c["tdd_failed"], c["tdd_on"], c["tdd_off"]) == (failed.size * 20, failed.size, 30, 0)


def test_pass_probability_is_the_hypergeometric_chance():
    # d distinct points from a pool of m, c consistent: C(c, d) / C(m, d), for every c in [0, m] (c < d gives 0,
    # a pool of exactly d consistent ones gives 1), integer or float counts, elementwise over arrays.
    for d in (1, 2, 3):
        for m in range(d, 9):
            c = np.arange(m + 1)
            expected = [math.comb(int(k), d) / math.comb(m, d) for k in c]
            np.testing.assert_allclose(pass_probability(c, m, d), expected, rtol=1e-12, atol=0)
            np.testing.assert_allclose(pass_probability(c.astype(float), float(m), d), expected, rtol=1e-12, atol=0)
    assert pass_probability(1, 1, 1) == 1.0 and pass_probability(0, 5, 1) == 0.0 and pass_probability(1, 10, 2) == 0.0
    # no points to draw: every hypothesis passes, in the broadcast shape of the counts and the pools
    assert pass_probability(np.array([0, 2, 5]), 7, 0).tolist() == [1.0, 1.0, 1.0]
    assert pass_probability(4, np.array([6, 8]), 0).tolist() == [1.0, 1.0]


@pytest.mark.parametrize("name", ["d", "measure_points", "max_measured", "min_measured"])
def test_tdd_integer_options_are_checked_with_their_names(name):
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError) as err:
            TddVerification(**{name: bad})
        assert str(err.value) == f"option tdd_{name} must be an integer >= 1, got {bad!r}"
    v = TddVerification(**{name: 1.0})
    assert getattr(v, name) == 1


def test_tdd_t_m_is_checked():
    for bad in (0, 0.0, -1.0, float("inf"), float("nan"), "200", None):
        with pytest.raises(ValueError) as err:
            TddVerification(t_m=bad)
        assert str(err.value) == f"option tdd_t_m must be a positive number, got {bad!r}"
    assert TddVerification(t_m=0.5).t_m == 0.5


def test_tdd_counters_of_a_fresh_verifier():
    assert TddVerification().counters() == {
        "tdd_tested": 0, "tdd_passed": 0, "tdd_failed": 0, "tdd_good_measured": 0, "tdd_alpha": -1.0,
        "tdd_measure_checks": 0, "tdd_on": 0, "tdd_off": 0, "tdd_switches": 0}


def test_tdd_pays_is_matas_and_chums_cost_model_by_hand():
    # with min_measured good hypotheses measured their mean alpha counts; the pass rate is over all verified
    n = 100
    for t_m, d, alpha in ((1.0, 1, 0.6), (5.0, 2, 0.4), (200.0, 1, 0.9)):
        for on, off in ((40, 0), (30, 10), (1, 0)):
            for passed in np.linspace(0, on + off, 21):
                v = TddVerification(d=d, t_m=t_m, min_measured=4)
                _rates(v, on=on, off=off, passed=passed, alpha=alpha, good=4)
                assert v.pays(n) == _pays(t_m, d, passed / (on + off), alpha, n), (t_m, d, alpha, on, off, passed)
    # the expected costs equal exactly: it does not pay
    v = TddVerification(d=1, t_m=200.0, min_measured=1)
    _rates(v, on=4, off=0, passed=1.0, alpha=0.5, good=1)
    assert (200 + 1 + 0.25 * 402) / 0.5 == 200 + 403 and not v.pays(403)
    # alpha 0: a good hypothesis never passes, it cannot pay
    _rates(v, on=4, off=0, passed=1.0, alpha=0.0, good=1)
    assert not v.pays(403)
    # nothing verified yet: the paper's test stays on
    _rates(v, on=0, off=0, passed=0.0, alpha=0.01, good=1)
    assert v.pays(403)


def test_tdd_pays_takes_the_optimistic_alpha_until_min_measured():
    # until min_measured good ones are measured alpha is C(I - 3, d) / C(N - 3, d) for the best model's support I
    n, support, t_m = 100, 60, 1.0
    mask = np.zeros(n, dtype=bool)
    mask[:support] = True
    for d in (1, 2):
        optimistic = math.comb(support - 3, d) / math.comb(n - 3, d)
        for good, alpha_used in ((2, optimistic), (3, 0.2), (4, 0.2)):
            v = TddVerification(d=d, t_m=t_m, min_measured=3, adaptive=False)
            v.on_new_best(mask, None)
            for passed in np.linspace(0, 40, 81):
                _rates(v, on=40, off=0, passed=passed, alpha=0.2, good=good)
                assert v.pays(n) == _pays(t_m, d, passed / 40, alpha_used, n), (d, good, passed)
    # a best model with no support beyond its sample: alpha 0, the test is switched off
    # (a cheap model, t_m = 0.01, and no hypothesis passing: any alpha >= 1 / (N - 3) would pay)
    v = TddVerification(d=1, t_m=0.01, adaptive=True)
    _rates(v, on=10, off=0, passed=0.0)
    v.on_new_best(np.arange(n) < 3, None)
    assert (v.active, v.counters()["tdd_switches"]) == (False, 1)
    v = TddVerification(d=1, adaptive=True)
    v.on_new_best(mask, None)  # nothing verified yet: stays on, no switch
    assert (v.active, v.counters()["tdd_switches"]) == (True, 0)


def test_tdd_verify_without_points_outside_the_sample():
    # N = 3: nothing to pre-test on, every hypothesis is scored on all points; N = 4 with d = 2: one point left
    for n, d in ((3, 1), (4, 2)):
        frame, problem, ctx = tdd_setup(n, 0.0)
        rng = np.random.default_rng(1)
        R, t = near_truth_motions(frame, rng, 6, spread=2.0)
        samples = np.tile(np.arange(3), (6, 1))
        sq = ctx.residuals(R, t)
        verifier = TddVerification(d=d, adaptive=False)
        scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(2), samples=samples)
        if n == 3:
            np.testing.assert_array_equal(scores, np.sum(sq < 9.0, axis=1))
            assert checks == 6 * 3
        else:  # the pre-test on point 3 alone
            passed = sq[:, 3] < 9.0
            np.testing.assert_array_equal(np.isinf(scores), ~passed)
            assert checks == (~passed).sum() + passed.sum() * 4


def test_tdd_measuring_counts_by_hand(monkeypatch):
    # numpy route, d = 1. Hypotheses with a sample point outside the best model are not good: nothing is measured,
    # nothing added to the checks; good ones that all passed are measured exactly, at no extra checks.
    monkeypatch.setattr(tdd_module, "ReprojectionResidual", _OtherResidual)
    frame, problem, ctx = tdd_setup(80)
    n, rng = problem.n, np.random.default_rng(5)
    inl, out = np.flatnonzero(frame.truth.inlier), np.flatnonzero(~frame.truth.inlier)
    verifier = TddVerification(d=1, measure_points=10, adaptive=False)
    verifier.on_new_best(frame.truth.inlier, None)
    R, t = near_truth_motions(frame, rng, 10)
    bad = np.stack([np.r_[rng.choice(inl, 2, replace=False), rng.choice(out, 1)] for _ in range(10)])
    g = np.random.default_rng(6)
    mask = ctx.residuals(R, t) < 9.0
    passed = np.take_along_axis(mask, random_points_excluding(bad, n, 1, g), axis=1)[:, 0]
    _, checks = verifier.verify(ctx, R, t, np.random.default_rng(6), samples=bad)
    assert checks == (~passed).sum() + passed.sum() * n
    assert verifier.counters()["tdd_good_measured"] == 0 and verifier.alpha() is None
    # all good and passing (no outliers, near-truth hypotheses): exact alphas, no extra checks
    frame, problem, ctx = tdd_setup(40, 0.0)
    n = problem.n
    verifier = TddVerification(d=1, measure_points=10, adaptive=False)
    verifier.on_new_best(np.ones(n, dtype=bool), None)
    R, t = near_truth_motions(frame, rng, 10, spread=0.01)
    good = np.stack([rng.choice(n, 3, replace=False) for _ in range(10)])
    mask = ctx.residuals(R, t) < 9.0
    assert mask.all()
    _, checks = verifier.verify(ctx, R, t, np.random.default_rng(7), samples=good)
    assert checks == 10 * n and verifier.counters()["tdd_measure_checks"] == 0
    assert verifier.alpha() == 1.0 and verifier.counters()["tdd_good_measured"] == 10


def test_tdd_measures_at_most_max_measured_and_keeps_the_samples(monkeypatch):
    # failed good hypotheses are measured only while fewer than max_measured good ones are on record (the room is
    # counted before the batch); the measuring checks add up over batches; a new best re-selects the good ones
    monkeypatch.setattr(tdd_module, "ReprojectionResidual", _OtherResidual)
    frame, problem, ctx = tdd_setup(150)
    n, rng = problem.n, np.random.default_rng(9)
    inl = np.flatnonzero(frame.truth.inlier)
    batches = []
    for _ in range(2):
        R, t = near_truth_motions(frame, rng, 30)
        samples = np.stack([rng.choice(inl, 3, replace=False) for _ in range(30)])
        batches.append((R, t, samples))

    def failed_in(R, t, samples, seed):
        mask = ctx.residuals(R, t) < 9.0
        g = np.random.default_rng(seed)
        consistent = np.take_along_axis(mask, random_points_excluding(samples, n, 2, g), axis=1)
        return np.flatnonzero(~consistent.all(axis=1)), mask, g

    f1, _, _ = failed_in(*batches[0], 11)
    f2, _, _ = failed_in(*batches[1], 12)
    assert f1.size >= 2 and f2.size >= 2 and f1.size < 29
    # max_measured = 1: the first failed one of batch 1 is measured, none of batch 2 (no room left)
    v = TddVerification(d=2, measure_points=20, max_measured=1, adaptive=False)
    v.on_new_best(frame.truth.inlier, None)
    v.verify(ctx, *batches[0][:2], np.random.default_rng(11), samples=batches[0][2])
    assert v.counters()["tdd_measure_checks"] == 20
    v.verify(ctx, *batches[1][:2], np.random.default_rng(12), samples=batches[1][2])
    assert v.counters()["tdd_measure_checks"] == 20
    # unbounded: every failed good one in both batches, the checks summed
    v = TddVerification(d=2, measure_points=20, adaptive=False)
    v.on_new_best(frame.truth.inlier, None)
    for (R, t, samples), seed in zip(batches, (11, 12)):
        v.verify(ctx, R, t, np.random.default_rng(seed), samples=samples)
    assert v.counters()["tdd_measure_checks"] == 20 * (f1.size + f2.size) and v.counters()["tdd_good_measured"] == 60
    alphas, measured = v._alphas.copy(), v._samples.copy()  # the measured chances and their samples, in record order
    # a new best that drops point samples[0, 0] of batch 1: the hypotheses using it are no longer good
    kept = frame.truth.inlier.copy()
    kept[batches[0][2][0, 0]] = False
    v.on_new_best(kept, None)
    still = kept[measured].all(axis=1)
    np.testing.assert_array_equal(np.sort(measured, axis=0), np.sort(np.concatenate([b[2] for b in batches]), axis=0))
    assert v.counters()["tdd_good_measured"] == still.sum() < 60
    assert v.alpha() == pytest.approx(np.mean(alphas[still]), rel=1e-12)
    v.on_new_best(kept.astype(np.int8), None)  # a 0/1 mask is a mask too
    assert v.counters()["tdd_good_measured"] == still.sum() and v.alpha() == pytest.approx(np.mean(alphas[still]), rel=1e-12)


def test_tdd_switched_off_scores_fully_and_measures_exactly(monkeypatch):
    # the test off: every hypothesis scored on all N points (H N checks), a good one's chance exact from its
    # support outside its sample, the pass rate of all hypotheses kept at its value from while it was on
    monkeypatch.setattr(tdd_module, "ReprojectionResidual", _OtherResidual)
    frame, problem, ctx = tdd_setup(150)
    n, rng = problem.n, np.random.default_rng(10)
    inl = np.flatnonzero(frame.truth.inlier)
    v = TddVerification(d=2, adaptive=False)
    R, t = near_truth_motions(frame, rng, 20)
    samples = np.stack([rng.choice(inl, 3, replace=False) for _ in range(20)])
    for seed in (1, 3):  # two batches, no best yet: nothing measured, the pass rate over both
        v.verify(ctx, R, t, np.random.default_rng(seed), samples=samples)
    rate = v._pass_sum / v.n_on
    assert v._pass_sum == v.counters()["tdd_passed"]
    assert 0 < rate < 1
    v.active = False
    v.on_new_best(frame.truth.inlier, None)
    R, t = near_truth_motions(frame, rng, 20)
    samples = np.stack([rng.choice(inl, 3, replace=False) for _ in range(19)] + [rng.choice(problem.n, 3, replace=False)])
    samples[-1, 0] = np.flatnonzero(~frame.truth.inlier)[0]  # the last one is not good
    mask = ctx.residuals(R, t) < 9.0
    scores, checks = v.verify(ctx, R, t, np.random.default_rng(2), samples=samples)
    np.testing.assert_array_equal(scores, mask.sum(axis=1))
    assert checks == 20 * n
    own = np.take_along_axis(mask, samples, axis=1).sum(axis=1)
    c = mask.sum(axis=1) - own
    chances = c[:19] * (c[:19] - 1) / ((n - 3) * (n - 4))
    counters = v.counters()
    assert (counters["tdd_on"], counters["tdd_off"], counters["tdd_good_measured"]) == (40, 20, 19)
    assert counters["tdd_alpha"] == pytest.approx(np.mean(chances), rel=1e-12)
    assert v._pass_sum / (v.n_on + v.n_off) == pytest.approx(rate, rel=1e-12)


def test_tdd_switched_off_after_a_single_hypothesis_keeps_its_pass_rate(monkeypatch):
    # one hypothesis verified with the test on (it passed: rate 1), then 20 fully: the rate stays 1
    monkeypatch.setattr(tdd_module, "ReprojectionResidual", _OtherResidual)
    frame, problem, ctx = tdd_setup(40, 0.0)
    rng = np.random.default_rng(12)
    v = TddVerification(d=1, adaptive=False)
    R, t = near_truth_motions(frame, rng, 1, spread=0.01)
    assert (ctx.residuals(R, t) < 9.0).all()
    v.verify(ctx, R, t, np.random.default_rng(1), samples=np.array([[0, 1, 2]]))
    v.active = False
    R, t = near_truth_motions(frame, rng, 20)
    v.verify(ctx, R, t, np.random.default_rng(2), samples=np.tile(np.arange(3), (20, 1)))
    assert (v.n_on, v.n_off) == (1, 20) and v._pass_sum / 21 == pytest.approx(1.0, rel=1e-12)


def test_random_points_excluding_are_the_d_smallest_keys_outside_the_sample_in_key_order(monkeypatch):
    # the definition: one uniform key per point (the generator's (H, n) draw), the sample's keys +inf, then the
    # d points of smallest key, in increasing key order; for every d from 1 to n - 3 (then all the other points),
    # with NumPy's argpartition and with one that keeps to its contract only
    n = 9
    for argpartition in (np.argpartition, _adversarial_argpartition):
        monkeypatch.setattr(np, "argpartition", argpartition)
        for d in range(1, n - 2):
            for seed in range(3):
                samples = np.stack([np.random.default_rng(100 + seed).choice(n, 3, replace=False) for _ in range(40)])
                keys = np.random.default_rng(seed).random((40, n))
                expected = []
                for row, sample in zip(keys, samples):
                    order = sorted((k, i) for i, k in enumerate(row) if i not in set(sample.tolist()))
                    expected.append([i for _, i in order[:d]])
                got = random_points_excluding(samples, n, d, np.random.default_rng(seed))
                assert got.tolist() == expected, (argpartition, d, seed)


def test_tdd_a_residual_at_the_gate_is_inconsistent_in_the_pretest_the_measuring_and_the_exact_chances():
    # Gate 4 px^2; N = 12, d = 1, every point an inlier of the best model, so every hypothesis is good, and
    # measure_points >= N - 3 so a failed one is measured on all 9 other points. Hypothesis 0 has residual exactly
    # 4 on every point outside its sample: it fails whichever point is drawn, is measured at 0 consistent of 9,
    # chance 0. Hypothesis 1 has residual 1 everywhere: it passes, scores 12, chance 9/9. Hypotheses 2..7 have
    # residual 4 on one point outside their sample: passed or failed, their chance is 8/9 (exact from the scored
    # residuals, where the model returns the capped 4, or measured on the 9). alpha = (0 + 1 + 6 * 8/9) / 8.
    frame, problem, _ = tdd_setup(12, 0.0)
    n, H = problem.n, 8
    table = np.ones((H, n))
    table[0, 3:] = 4.0
    for h in range(2, H):
        table[h, h - 2] = 4.0
    samples = np.array([[0, 1, 2], [3, 4, 5], *[[6, 7, 8]] * 6])
    ctx = ScoringContext(problem, _TableResidual(problem, table), InlierCount(), 4.0)
    R = np.tile(np.eye(3), (H, 1, 1))
    t = np.zeros((H, 3))
    t[:, 0] = np.arange(H)
    v = TddVerification(d=1, measure_points=64, adaptive=False)
    v.on_new_best(np.ones(n, dtype=bool), None)
    scores, checks = v.verify(ctx, R, t, np.random.default_rng(3), samples=samples)
    passed = np.isfinite(scores)
    assert scores[0] == -np.inf and scores[1] == 12.0
    assert passed[2:].any() and np.all(scores[2:][passed[2:]] == 11.0)
    assert checks == 12 * passed.sum() + (1 + 9) * (~passed).sum()
    c = v.counters()
    assert (c["tdd_good_measured"], c["tdd_measure_checks"]) == (8, 9 * (~passed).sum())
    assert c["tdd_alpha"] == pytest.approx((0 + 1 + 6 * 8 / 9) / 8, rel=1e-12)
    # the test switched off: every hypothesis scored on the capped residuals, the chances exact from them
    v = TddVerification(d=1, adaptive=False)
    v.active = False
    v.on_new_best(np.ones(n, dtype=bool), None)
    scores, checks = v.verify(ctx, R, t, np.random.default_rng(3), samples=samples)
    assert scores.tolist() == [3.0, 12.0, *[11.0] * 6] and checks == H * n
    assert v.counters()["tdd_alpha"] == pytest.approx((0 + 1 + 6 * 8 / 9) / 8, rel=1e-12)
