"""T(d,d)'s verifier and bound by hand, for the survivors of the mutmut run of ``stereovo/estimation/methods/tdd.py``
(docs/mutation-testing.md): the numpy route (taken for residual models other than the reprojection one,
whose compiled route test_classical_verification checks), point by point.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

import stereovo.estimation.methods.tdd as tdd_module
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.scoring import InlierCount, ReprojectionResidual
from stereovo.estimation.methods.tdd import (
    TddTermination,
    TddVerification,
    pass_probability,
    random_points_excluding,
)
from stereovo.estimation.roles.verification import ScoringContext
from stereovo.geometry import random_rotation
from stereovo.simulation import SimulationConfig, simulate_frame


class _OtherResidual:
    """Stands in for ReprojectionResidual in the tdd module's type test: the numpy route is taken."""


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


def _two_point_chance(c, m):
    """The chance that 2 distinct points drawn from m, c of them consistent, are both consistent."""
    c, m = np.asarray(c, float), np.asarray(m, float)
    return np.maximum(c, 0) * np.maximum(c - 1, 0) / (np.maximum(m, 1) * np.maximum(m - 1, 1))


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


# ---------------------------------------------------------------- the formulas and the bound, by hand


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


def _q(i, n):
    return math.comb(i, 3) / math.comb(n, 3)


def _k(q, p=0.99, cap=10_000):
    if q >= 1:
        return 1
    return cap if q <= 0 else min(max(math.ceil(math.log(1 - p) / math.log(1 - q)), 1), cap)


class _Verifier:
    """Stands in for TddVerification in the bound: a measured alpha and the draws with the test on and off."""

    def __init__(self, alpha, n_on, n_off, active):
        self._a, self.n_on, self.n_off, self.active = alpha, n_on, n_off, active

    def alpha(self):
        return self._a


def test_tdd_bound_without_a_verifier_by_hand():
    # uniform sampling, no measured alpha: k = log(1 - p) / log(1 - q alpha) with q = C(I, 3) / C(N, 3) and
    # alpha = prod_{j<d} (I - 3 - j) / (N - 3 - j), the chance for a hypothesis explaining the whole support
    for i, n, d in ((60, 100, 1), (60, 100, 2), (20, 150, 1), (40, 50, 3)):
        term = TddTermination(d=d)
        alpha = math.comb(i - 3, d) / math.comb(n - 3, d)
        assert term.required(i, n) == _k(_q(i, n) * alpha)
        assert term.last_alpha == pytest.approx(alpha, rel=1e-12)
        assert term.counters() == {"tdd_alpha_used": term.last_alpha}
        assert term.required(i, n) == _k(_q(i, n) * alpha)  # the cached q
    # a support of only the sample: no point outside it is consistent, alpha = 0, the cap
    term = TddTermination(d=1)
    assert term.required(3, 8) == 10_000 and term.last_alpha == 0.0
    # before any bound: no alpha used yet
    assert math.isnan(TddTermination().counters()["tdd_alpha_used"])


class _Guided:
    """A guided sampler: q is a function of the inlier mask it is given."""

    def all_inlier_probability(self, inliers):
        return 0.5 * float(np.mean(inliers))


def test_tdd_bound_with_a_guided_sampler_takes_its_q():
    term = TddTermination(d=1, sampler=_Guided())
    mask = np.zeros(100, dtype=bool)
    mask[:40] = True
    term.on_new_best(mask, None)
    alpha = 37 / 97
    assert term.required(40, 100) == _k(0.2 * alpha)


def test_tdd_bound_with_the_test_switched_on_and_off_by_hand():
    # the draws so far under each mode: (1 - q alpha)^k_on (1 - q)^k_off <= 1 - p, then what the current mode
    # needs beyond the draws made: drawn + ceil((log(1 - p) - log_miss) / log(1 - per_draw))
    i, n = 25, 100
    q = _q(i, n)
    for alpha, n_on, n_off, active, drawn in ((0.3, 10, 20, True, 30), (0.3, 10, 1, True, 11), (0.3, 10, 20, False, 30),
                                              (0.3, 50, 0, False, 50), (0.25, 5, 3, True, 0)):
        term = TddTermination(d=1, verifier=_Verifier(alpha, n_on, n_off, active))
        if drawn:
            term.on_batch(SimpleNamespace(n_hypotheses=drawn))
        log_miss = n_on * math.log(1 - q * alpha) + n_off * math.log(1 - q)
        per_draw = q * alpha if active else q
        remaining = (math.log(0.01) - log_miss) / math.log(1 - per_draw)
        assert remaining > 0 and term.required(i, n) == drawn + math.ceil(remaining), (alpha, n_on, n_off, active)
        assert term.last_alpha == alpha
    # with the test on throughout the bound ignores the draws: the plain T(d,d) bound
    term = TddTermination(d=1, verifier=_Verifier(0.3, 50, 0, True))
    assert term.required(i, n) == _k(q * 0.3)
    # the draws so far already suffice: at least one
    term = TddTermination(d=1, verifier=_Verifier(0.3, 10, 1000, False))
    assert term.required(i, n) == 1
    # a good hypothesis that cannot pass the test (alpha = 0) while it is on: never enough, the cap
    assert TddTermination(d=1, verifier=_Verifier(0.0, 10, 5, True)).required(i, n) == 10_000
    assert TddTermination(d=1, verifier=_Verifier(0.3, 10, 5, True)).required(2, n) == 10_000  # q = 0


def test_tdd_bound_when_every_draw_is_good():
    # q = 1 and alpha = 1 (every point an inlier): the next draw is good; the draws' misses are clamped below 1
    for active in (True, False):
        term = TddTermination(d=1, max_iterations=50, verifier=_Verifier(1.0, 5, 2, active))
        assert term.required(20, 20) == 1
        term.on_batch(SimpleNamespace(n_hypotheses=7))
        assert term.required(20, 20) == 8
        term.on_batch(SimpleNamespace(n_hypotheses=50))
        assert term.required(20, 20) == 50


# ---------------------------------------------------------------- the verifier's options, state and cost model


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


def _rates(v, *, on, off, passed, alpha=None, good=0):
    """The verifier's measured rates as its verify calls leave them: hypotheses verified with the test on and
    off, the sum of their pass chances, the mean pass chance of the good ones measured and how many."""
    v.n_on, v.n_off, v._pass_sum, v._alpha, v._good = on, off, passed, alpha, good


def _pays(t_m, d, p_pass, alpha, n):
    return (t_m + d + p_pass * (n - d)) / alpha < t_m + n


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


# ---------------------------------------------------------------- verify's counts on small problems


def _setup(n, outlier_ratio=0.3, seed=4):
    frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=outlier_ratio), seed)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    return frame, problem, ScoringContext(problem, ReprojectionResidual(9.0), InlierCount(), 9.0)


def _near_truth(frame, rng, h, spread=0.1):
    R = np.stack([random_rotation(rng, np.radians(spread)) @ frame.truth.rotation for _ in range(h)])
    return R, frame.truth.translation + rng.normal(0, spread / 10, (h, 3))


def test_tdd_verify_without_points_outside_the_sample():
    # N = 3: nothing to pre-test on, every hypothesis is scored on all points; N = 4 with d = 2: one point left
    for n, d in ((3, 1), (4, 2)):
        frame, problem, ctx = _setup(n, 0.0)
        rng = np.random.default_rng(1)
        R, t = _near_truth(frame, rng, 6, spread=2.0)
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


def test_tdd_compiled_pretest_stops_at_the_first_miss():
    # hypotheses far off explain no point: with d = 3 each fails at its first point and costs one check
    frame, problem, ctx = _setup(60)
    rng = np.random.default_rng(3)
    R = np.stack([random_rotation(rng, np.radians(40)) for _ in range(12)])
    t = rng.normal(0, 5.0, (12, 3))
    assert not np.any(ctx.residuals(R, t) < 9.0)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(12)])
    verifier = TddVerification(d=3, adaptive=False)
    scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(2), samples=samples)
    assert np.all(np.isinf(scores)) and checks == 12


def test_tdd_measuring_counts_by_hand(monkeypatch):
    # numpy route, d = 1. Hypotheses with a sample point outside the best model are not good: nothing is measured,
    # nothing added to the checks; good ones that all passed are measured exactly, at no extra checks.
    monkeypatch.setattr(tdd_module, "ReprojectionResidual", _OtherResidual)
    frame, problem, ctx = _setup(80)
    n, rng = problem.n, np.random.default_rng(5)
    inl, out = np.flatnonzero(frame.truth.inlier), np.flatnonzero(~frame.truth.inlier)
    verifier = TddVerification(d=1, measure_points=10, adaptive=False)
    verifier.on_new_best(frame.truth.inlier, None)
    R, t = _near_truth(frame, rng, 10)
    bad = np.stack([np.r_[rng.choice(inl, 2, replace=False), rng.choice(out, 1)] for _ in range(10)])
    g = np.random.default_rng(6)
    mask = ctx.residuals(R, t) < 9.0
    passed = np.take_along_axis(mask, random_points_excluding(bad, n, 1, g), axis=1)[:, 0]
    _, checks = verifier.verify(ctx, R, t, np.random.default_rng(6), samples=bad)
    assert checks == (~passed).sum() + passed.sum() * n
    assert verifier.counters()["tdd_good_measured"] == 0 and verifier.alpha() is None
    # all good and passing (no outliers, near-truth hypotheses): exact alphas, no extra checks
    frame, problem, ctx = _setup(40, 0.0)
    n = problem.n
    verifier = TddVerification(d=1, measure_points=10, adaptive=False)
    verifier.on_new_best(np.ones(n, dtype=bool), None)
    R, t = _near_truth(frame, rng, 10, spread=0.01)
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
    frame, problem, ctx = _setup(150)
    n, rng = problem.n, np.random.default_rng(9)
    inl = np.flatnonzero(frame.truth.inlier)
    batches = []
    for _ in range(2):
        R, t = _near_truth(frame, rng, 30)
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
    frame, problem, ctx = _setup(150)
    n, rng = problem.n, np.random.default_rng(10)
    inl = np.flatnonzero(frame.truth.inlier)
    v = TddVerification(d=2, adaptive=False)
    R, t = _near_truth(frame, rng, 20)
    samples = np.stack([rng.choice(inl, 3, replace=False) for _ in range(20)])
    for seed in (1, 3):  # two batches, no best yet: nothing measured, the pass rate over both
        v.verify(ctx, R, t, np.random.default_rng(seed), samples=samples)
    rate = v._pass_sum / v.n_on
    assert v._pass_sum == v.counters()["tdd_passed"]
    assert 0 < rate < 1
    v.active = False
    v.on_new_best(frame.truth.inlier, None)
    R, t = _near_truth(frame, rng, 20)
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
    frame, problem, ctx = _setup(40, 0.0)
    rng = np.random.default_rng(12)
    v = TddVerification(d=1, adaptive=False)
    R, t = _near_truth(frame, rng, 1, spread=0.01)
    assert (ctx.residuals(R, t) < 9.0).all()
    v.verify(ctx, R, t, np.random.default_rng(1), samples=np.array([[0, 1, 2]]))
    v.active = False
    R, t = _near_truth(frame, rng, 20)
    v.verify(ctx, R, t, np.random.default_rng(2), samples=np.tile(np.arange(3), (20, 1)))
    assert (v.n_on, v.n_off) == (1, 20) and v._pass_sum / 21 == pytest.approx(1.0, rel=1e-12)


# ---------------------------------------------------------------- the gate's edge, the draws, the dtypes


def _adversarial_argpartition(a, kth, axis=-1, **_):
    """np.argpartition's contract and no more: the kth entry in place, the entries before it no larger, those after
    no smaller, each side in an undefined order, here the worst one (reversed); NumPy's own SIMD selection sorts
    small blocks, which would hide a wrong kth."""
    assert a.ndim == 2 and axis in (1, -1)
    kth = kth + a.shape[1] if kth < 0 else kth
    order = np.argsort(a, axis=1, kind="stable")
    return np.concatenate([order[:, :kth][:, ::-1], order[:, kth:kth + 1], order[:, kth + 1:][:, ::-1]], axis=1)


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


def test_tdd_a_residual_at_the_gate_is_inconsistent_in_the_pretest_the_measuring_and_the_exact_chances():
    # Gate 4 px^2; N = 12, d = 1, every point an inlier of the best model, so every hypothesis is good, and
    # measure_points >= N - 3 so a failed one is measured on all 9 other points. Hypothesis 0 has residual exactly
    # 4 on every point outside its sample: it fails whichever point is drawn, is measured at 0 consistent of 9,
    # chance 0. Hypothesis 1 has residual 1 everywhere: it passes, scores 12, chance 9/9. Hypotheses 2..7 have
    # residual 4 on one point outside their sample: passed or failed, their chance is 8/9 (exact from the scored
    # residuals, where the model returns the capped 4, or measured on the 9). alpha = (0 + 1 + 6 * 8/9) / 8.
    frame, problem, _ = _setup(12, 0.0)
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


def test_tdd_compiled_route_measures_failed_good_hypotheses_with_the_kernels_draws():
    # The reprojection residual: the pre-test (d = 1) and the measuring of failed good ones both run compiled, on
    # the verifier's generator in that order: (H, 1) uniforms for the pre-test, then (failed, measure_points) for the
    # measuring, each turned into points by the kernel's rule. alpha is the mean of the good ones' chances: exact
    # (support outside the sample / (N - 3)) for those that passed, consistent / measure_points for those that failed.
    frame, problem, ctx = _setup(150)
    n, H, m, rng = problem.n, 30, 20, np.random.default_rng(21)
    inl = np.flatnonzero(frame.truth.inlier)
    R, t = _near_truth(frame, rng, H)
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
    frame, problem, ctx = _setup(150)
    rng = np.random.default_rng(22)
    inl = np.flatnonzero(frame.truth.inlier)
    R, t = _near_truth(frame, rng, 30)
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
