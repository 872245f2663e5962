"""Stopping rules against numbers worked out by hand: RANSAC, T(d,d), SPRT, PROSAC's g(t) and n*.

Every expected value is a literal, or arithmetic on literals written here from the papers' formulas
(Schoenberger, Larsson & Pollefeys 2025 for drawing without replacement; Matas & Chum 2002/2004
for T(d,d); Chum & Matas 2008 for the SPRT's bound; Chum & Matas 2005 for PROSAC), never a value
asked of the code under test.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from stereovo.estimation.methods.prosac import ProsacTermination, non_random_minimum, prefix_draws
from stereovo.estimation.roles.samplers import ProsacSampler, prosac_growth
from stereovo.estimation.methods.sprt import SprtTermination, SprtTest, SprtVerification
from stereovo.estimation.methods.tdd import TddTermination, random_points_excluding
from stereovo.estimation.roles.termination import (
    AdaptiveTermination,
    FixedBudget,
    all_inlier_probability,
    iterations_for,
    required_iterations,
)

# ---------------------------------------------------------------------------- RANSAC


def test_ransac_bound_draws_without_replacement():
    # N = 20, I = 6: q = 6 * 5 * 4 / (20 * 19 * 18) = 120 / 6840 = 0.017544.
    assert float(all_inlier_probability(6, 20)) == pytest.approx(120 / 6840, rel=1e-12)
    assert float(all_inlier_probability(6, 20)) == pytest.approx(0.017544, abs=1e-6)
    # k = ceil(log(0.01) / log(1 - 0.017544)) = ceil(260.2) = 261 (w^3 = 0.027 would give 169).
    assert required_iterations(6, 20, confidence=0.99) == 261
    assert AdaptiveTermination(confidence=0.99).required(6, 20) == 261
    # p = 0.95: ceil(log(0.05) / log(1 - 0.017544)) = ceil(169.3) = 170.
    assert required_iterations(6, 20, confidence=0.95) == 170
    # N = 300, I = 150: q = 150 * 149 * 148 / (300 * 299 * 298) = 0.123746, k = ceil(34.9) = 35.
    assert required_iterations(150, 300, confidence=0.99) == 35
    # Elementwise over an array of counts.
    np.testing.assert_array_equal(required_iterations(np.array([6, 20, 2]), 20, 0.99, 10_000), [261, 1, 10_000])


def test_ransac_bound_edges_and_clips():
    assert required_iterations(2, 20, confidence=0.99, max_iterations=777) == 777  # q = 0: never certain
    assert required_iterations(20, 20, confidence=0.99) == 1  # q = 1: one draw
    # q = 3 * 2 * 1 / (1000 * 999 * 998) ~ 6e-9 needs ~7.7e8 draws: clipped to max_iterations.
    assert required_iterations(3, 1000, confidence=0.99, max_iterations=5000) == 5000
    assert AdaptiveTermination(confidence=0.99, min_iterations=300).required(6, 20) == 300


def test_all_inlier_probability_is_zero_below_a_sample_and_elementwise():
    assert float(all_inlier_probability(2, 20)) == 0.0  # (2)(1)(0) / (20 * 19 * 18)
    assert float(all_inlier_probability(1, 20)) == 0.0
    assert float(all_inlier_probability(3, 3)) == 1.0  # (3/3)(2/2)(1/1): the last factor's denominator is 1
    q = all_inlier_probability(np.array([[6, 20], [2, 3]]), 20)
    assert q.dtype == np.float64 and q.shape == (2, 2)
    np.testing.assert_allclose(q, [[120 / 6840, 1.0], [0.0, 6 / 6840]], rtol=1e-12)
    # A 2-point sample: q = 6 * 5 / (20 * 19).
    assert float(all_inlier_probability(6, 20, sample_size=2)) == pytest.approx(30 / 380, rel=1e-12)


def test_required_iterations_defaults_shapes_and_sample_size():
    assert required_iterations(6, 20) == 261  # confidence 0.99 by default
    assert required_iterations(3, 1000) == 10_000  # max_iterations 10000 by default
    k = required_iterations(np.array([[150, 300], [2, 6]]), 300, 0.99, 10_000)
    assert k.dtype == np.int64 and k.shape == (2, 2)
    # (150, 300): 35; all inliers: 1; fewer than 3: the cap; (6, 300): q = 120 / (300 * 299 * 298), ~1e6: the cap.
    np.testing.assert_array_equal(k, [[35, 1], [10_000, 10_000]])
    # 2-point samples: q = 30 / 380, ceil(log(0.01) / log(1 - 30/380)) = ceil(55.998) = 56.
    assert math.ceil(math.log(0.01) / math.log(1 - 30 / 380)) == 56
    np.testing.assert_array_equal(required_iterations(np.array([6]), 20, 0.99, 10_000, sample_size=2), [56])
    assert AdaptiveTermination(confidence=0.99, max_iterations=123).required(3, 1000) == 123


def test_iterations_for_a_given_q():
    assert iterations_for(120 / 6840, 0.99, 10_000) == 261
    assert iterations_for(0.999999, 0.5, 100) == 1  # ceil(log 0.5 / log 1e-6) = ceil(0.05) = 1
    assert iterations_for(0.5, 0.99, 100) == 7  # ceil(log 0.01 / log 0.5) = ceil(6.64)
    assert iterations_for(1.0, 0.99, 100) == 1
    assert iterations_for(0.0, 0.99, 100) == 100
    assert iterations_for(float("nan"), 0.99, 100) == 100
    assert iterations_for(1e-9, 0.99, 100) == 100  # ~4.6e9 draws: the cap


def test_adaptive_termination_asks_a_guided_sampler_for_q():
    calls = []

    def q_of(inliers):
        calls.append(int(np.count_nonzero(inliers)))
        return 0.5

    guided = SimpleNamespace(all_inlier_probability=q_of)
    stop = AdaptiveTermination(confidence=0.99, max_iterations=500, sampler=guided)
    assert stop.required(6, 20) == 500  # no best model yet: q = 0, keep drawing
    assert stop.counters() == {"stop_guided": 1, "stop_q": 0.0}
    inliers = np.zeros(20, dtype=bool)
    inliers[:6] = True
    stop.on_new_best(inliers, None)
    assert calls == [6]
    assert stop.required(6, 20) == 7  # the sampler's q = 0.5, not the count formula's 261
    # What T(d,d)'s and the SPRT's bounds read: the sampler's q, and how often it was asked.
    assert stop.probability.of(6, 20) == 0.5 and stop.probability.updates == 1
    stop.on_new_best(inliers, None)
    assert stop.probability.updates == 2
    assert stop.counters() == {"stop_guided": 1, "stop_q": 0.5}
    floor = AdaptiveTermination(confidence=0.99, min_iterations=20, sampler=guided)
    floor.on_new_best(inliers, None)
    assert floor.required(6, 20) == 20  # 7 draws needed, but at least min_iterations
    # A sampler that declares itself uniform, or cannot tell its q, gets the count formula.
    for sampler in (SimpleNamespace(uniform=True, all_inlier_probability=q_of), SimpleNamespace(), None):
        stop = AdaptiveTermination(confidence=0.99, sampler=sampler)
        stop.on_new_best(inliers, None)
        assert stop.required(6, 20) == 261 and stop.counters() == {"stop_guided": 0}
    assert calls == [6, 6, 6]  # never asked by those
    assert stop.probability.of(6, 20) == pytest.approx(120 / 6840, rel=1e-12) and stop.probability.updates == 0


def test_termination_settings_are_validated():
    for confidence in (0.0, 1.0, 1.5):
        with pytest.raises(ValueError, match=rf"^confidence must be in \(0, 1\), got {confidence}$"):
            AdaptiveTermination(confidence=confidence)
    for low, high in ((0, 10), (1, 0), (5, 3)):
        with pytest.raises(ValueError, match=rf"^need 1 <= min_iterations <= max_iterations, got {low} and {high}$"):
            AdaptiveTermination(min_iterations=low, max_iterations=high)
    AdaptiveTermination(confidence=0.5, min_iterations=3, max_iterations=3)  # the edges are allowed
    assert AdaptiveTermination(min_iterations=1, max_iterations=1).required(2, 20) == 1
    with pytest.raises(ValueError, match=r"^hypothesis budget must be >= 1, got 0$"):
        FixedBudget(0)
    budget = FixedBudget(7)
    assert budget.required(0, 20) == budget.required(20, 20) == budget.max_iterations == 7
    assert FixedBudget(1).required(5, 5) == 1 and FixedBudget().budget == 32
    # The stops of T(d,d) and SPRT check the same settings themselves, not only through EstimatorOptions.
    for make in (lambda **kw: TddTermination(**kw), lambda **kw: SprtTermination(SprtVerification(20), **kw)):
        for confidence in (0.0, 1.0, -0.5):
            with pytest.raises(ValueError, match=rf"^confidence must be in \(0, 1\), got {confidence}$"):
                make(confidence=confidence)
        with pytest.raises(ValueError, match=r"^max_iterations must be >= 1, got 0$"):
            make(max_iterations=0)
        assert make(confidence=1e-9, max_iterations=1).required(5, 20) == 1  # the edges are allowed


# ---------------------------------------------------------------------------- T(d,d)


def test_tdd_bound_is_stretched_by_the_pass_probability():
    # N = 20, I = 6, d = 1: a good hypothesis' pre-test point is one of the 17 others, 3 of them inliers:
    # alpha = 3 / 17; k = ceil(log(0.01) / log(1 - 0.017544 * 3 / 17)) = ceil(1485.2) = 1486.
    q = 6 * 5 * 4 / (20 * 19 * 18)
    assert math.ceil(math.log(0.01) / math.log(1 - q * 3 / 17)) == 1486  # the arithmetic itself
    assert TddTermination(confidence=0.99, d=1).required(6, 20) == 1486
    # d = 2: alpha = (3 / 17) * (2 / 16); k = ceil(11897.3) = 11898.
    assert TddTermination(confidence=0.99, d=2, max_iterations=100_000).required(6, 20) == 11898
    # A measured pass probability replaces the fallback: alpha = 1/2 gives ceil(log(0.01) / log(1 - q / 2)) =
    # ceil(522.6) = 523, alpha = 1/4 gives ceil(1047.7) = 1048 (and no measurement yet: the fallback, 1486).
    assert math.ceil(math.log(0.01) / math.log(1 - q / 2)) == 523
    assert math.ceil(math.log(0.01) / math.log(1 - q / 4)) == 1048
    for measured, expected in ((0.5, 523), (0.25, 1048), (None, 1486)):
        # A verifier whose pre-test stayed on for every draw (n_off = 0), with the measured alpha.
        verifier = SimpleNamespace(alpha=lambda measured=measured: measured, active=True, n_on=0, n_off=0)
        assert TddTermination(confidence=0.99, d=1, verifier=verifier).required(6, 20) == expected, measured
    # Plain RANSAC's 261 is the d = 0 limit: the pre-test only ever stretches the bound.
    assert TddTermination(confidence=0.99, d=1).required(300, 300) == 1
    assert TddTermination(confidence=0.99, d=1, max_iterations=900).required(3, 300) == 900


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


# ---------------------------------------------------------------------------- SPRT


def sprt_bound(history: list[SprtTest], n_inliers: int, n: int, confidence: float = 0.99) -> int:
    verifier = SprtVerification(n=n)
    verifier.history[:] = history
    return SprtTermination(verifier, confidence=confidence).required(n_inliers, n)


def test_sprt_bound_uses_the_current_tests_alpha():
    # N = 100, I = 50: P_g = 50 * 49 * 48 / (100 * 99 * 98) = 4 / 33. One test designed for the model's
    # own epsilon = 0.5 (so h = 1) with a small A = 4 rejects a good model with alpha = 1 / 4:
    # k = ceil(log(0.01) / log(1 - (4/33)(3/4))) = ceil(log(0.01) / log(10/11)) = ceil(48.3) = 49.
    # Ignoring alpha would give ceil(log(0.01) / log(29/33)) = 36.
    assert math.ceil(math.log(0.01) / math.log(10 / 11)) == 49
    assert sprt_bound([SprtTest(epsilon=0.5, delta=0.05, A=4.0)], 50, 100) == 49
    # The test switched off (A = inf): alpha = 0, plain RANSAC's 36.
    assert sprt_bound([SprtTest(epsilon=0.5, delta=0.05, A=math.inf)], 50, 100) == 36


def test_sprt_bound_follows_a_replaced_test():
    # The same termination asked again after its verifier's test was replaced by another (A = 4,
    # alpha = 1/4: 49 draws, above; then A = inf, alpha = 0: plain RANSAC's 36). Its caches must
    # not keep the first test's alpha.
    verifier = SprtVerification(n=100)
    verifier.history[:] = [SprtTest(epsilon=0.5, delta=0.05, A=4.0)]
    stop = SprtTermination(verifier, confidence=0.99)
    assert stop.required(50, 100) == 49
    verifier.history[:] = [SprtTest(epsilon=0.5, delta=0.05, A=math.inf)]
    assert stop.required(50, 100) == 36
    verifier.history[:] = [SprtTest(epsilon=0.5, delta=0.05, A=4.0)]
    assert stop.required(50, 100) == 49


def test_sprt_bound_sums_over_the_history_of_tests():
    # Test 1 (A = 4, alpha = 1/4) ran 10 draws: log eta = 10 log(1 - (4/33)(3/4)) = 10 log(10/11) = -0.95310.
    # Test 2 (A = 2, alpha = 1/2) is current: k_2 = (log 0.01 + 0.95310) / log(1 - (4/33)/2) = 58.41,
    # so 10 + ceil(58.41) = 69 draws in all.
    log_eta = 10 * math.log(10 / 11)
    assert 10 + math.ceil((math.log(0.01) - log_eta) / math.log(31 / 33)) == 69
    history = [SprtTest(epsilon=0.5, delta=0.05, A=4.0, draws=10), SprtTest(epsilon=0.5, delta=0.05, A=2.0)]
    assert sprt_bound(history, 50, 100) == 69


def test_sprt_bound_when_the_current_test_rejects_every_good_model():
    # N = 100, I = 50 (P_g = 4/33). The current test, designed for epsilon_i = 0.99 with delta_i = 0.5,
    # has Wald's drift 0.5 log(0.5/0.99) + 0.5 log(0.5/0.01) = 1.61 > 0 for a good model of epsilon
    # 0.5: h = 0, alpha = A^0 = 1, so it can never find one (P_find = 0). A past test (A = 4,
    # alpha = 1/4) that ran 60 draws already has log eta = 60 log(10/11) = -5.72 < log 0.01: stop at
    # the 60 draws done. After only 10 (log eta = -0.95) no draw of the current test can help: the cap.
    assert 60 * math.log(10 / 11) < math.log(0.01) < 10 * math.log(10 / 11)
    blind = SprtTest(epsilon=0.99, delta=0.5, A=4.0)
    reached = [SprtTest(epsilon=0.5, delta=0.05, A=4.0, draws=60), blind]
    assert sprt_bound(reached, 50, 100) == 60
    short = [SprtTest(epsilon=0.5, delta=0.05, A=4.0, draws=10), SprtTest(epsilon=0.99, delta=0.5, A=4.0)]
    verifier = SprtVerification(n=100)
    verifier.history[:] = short
    assert SprtTermination(verifier, confidence=0.99, max_iterations=777).required(50, 100) == 777


def test_sprt_bound_uses_wald_exponent_for_a_mismatched_design():
    # A test designed for epsilon_i = 0.5, delta_i = 0.1 and a good model of epsilon = 0.7 (N = 100, I = 70):
    # h solves 0.7 (0.1/0.5)^h + 0.3 (0.9/0.5)^h = 1; h = 2 does (0.7 * 0.04 + 0.3 * 3.24 = 1).
    assert 0.7 * 0.2**2 + 0.3 * 1.8**2 == pytest.approx(1.0, abs=1e-12)
    # alpha = A^-2 = 1/9 for A = 3; P_g = 70 * 69 * 68 / (100 * 99 * 98) = 0.338528;
    # k = ceil(log(0.01) / log(1 - 0.338528 * 8/9)) = ceil(12.1) = 13 (h = 1 would give 19, alpha = 0 gives 12).
    p_good = 70 * 69 * 68 / (100 * 99 * 98)
    assert math.ceil(math.log(0.01) / math.log(1 - p_good * 8 / 9)) == 13
    assert sprt_bound([SprtTest(epsilon=0.5, delta=0.1, A=3.0)], 70, 100) == 13


# ---------------------------------------------------------------------------- PROSAC


def test_prosac_growth_matches_the_hand_listed_schedule():
    # N = 500, T_N = 200000: T_3 = 200000 * 3 * 2 * 1 / (500 * 499 * 498), T_{k+1} = T_k (k+1) / (k+1-3),
    # T'_3 = 1, T'_{k+1} = T'_k + ceil(T_{k+1} - T_k), worked out once on paper and listed here.
    growth = prosac_growth(500, 3, 200_000)
    listed = {3: 1, 4: 2, 5: 3, 6: 4, 7: 5, 8: 6, 9: 7, 10: 8, 20: 23, 50: 216, 100: 1613, 200: 12783}
    assert {n: int(growth[n]) for n in listed} == listed


def test_prosac_first_draws_follow_g_of_t():
    # g(t) = min{n : T'_n >= t}: the first eight draws use n = 3, 4, ..., 10, then the schedule's steps.
    sampler = ProsacSampler(np.arange(500), t_n=200_000)
    t = np.array([1, 2, 3, 4, 5, 6, 7, 8, 9, 23, 24, 216, 217, 1613, 1614, 12783, 12784])
    n = [3, 4, 5, 6, 7, 8, 9, 10, 11, 20, 21, 50, 51, 100, 101, 200, 201]
    np.testing.assert_array_equal(sampler.subset_sizes(t), n)
    # The samples themselves: draw t holds u_n (rank n - 1) and two of the n - 1 better ones.
    order = np.random.default_rng(3).permutation(500)
    sampler = ProsacSampler(order, t_n=200_000)
    samples = sampler.draw(8, np.random.default_rng(0))
    rank = np.empty(500, dtype=int)
    rank[order] = np.arange(500)
    assert sorted(rank[samples[0]]) == [0, 1, 2]  # t = 1: the top three
    for t_index, n_t in enumerate([4, 5, 6, 7, 8, 9, 10], start=1):
        ranks = sorted(rank[samples[t_index]])
        assert ranks[-1] == n_t - 1 and len(set(ranks)) == 3, (t_index + 1, ranks)


def test_prosac_n_star_on_exact_ties_is_the_largest_prefix():
    # The 40 top-ranked matches are inliers, the other 60 outliers. Every prefix n = 20..40 is all-inlier:
    # q_n = 1, k_n = 1, an exact tie; n = 41 has q < 1. n* is the largest tied prefix, 40, the most data.
    sampler = ProsacSampler(np.arange(100))
    stop = ProsacTermination(sampler, confidence=0.99)
    inliers = np.zeros(100, dtype=bool)
    inliers[:40] = True
    stop.on_new_best(inliers, None)
    assert stop.n_star == 40
    assert sampler.n_max == 40
    assert stop.required(40, 100) == 1


def test_prosac_n_star_minimises_the_draws():
    # Top 30 all inliers, then every other match from rank 31 on (I_100 = 30 + 35 = 65).
    # n = 30: k = 1. n = 100: q = 65 * 64 * 63 / (100 * 99 * 98) < 1, k > 1. So n* = 30.
    sampler = ProsacSampler(np.arange(100))
    stop = ProsacTermination(sampler, confidence=0.99)
    inliers = np.zeros(100, dtype=bool)
    inliers[:30] = True
    inliers[31::2] = True
    stop.on_new_best(inliers, None)
    assert stop.n_star == 30 and stop.required(65, 100) == 1


def test_prosac_maximality_counts_only_the_draws_from_u_n_star():
    # Chum & Matas 2005: eta = (1 - q_n)^k for k samples all drawn from U_n. N = 500, T'_20 = 23 (the
    # schedule above): of the first 100 draws, draws 1..23 lie in U_20 (draw t holds u_g(t)), 24..100
    # hold a point ranked 21st or lower. A best with 10 inliers, the top 10: n* = 20 (min_n),
    # q_20 = 10 * 9 * 8 / (20 * 19 * 18) = 2/19, k_20 = ln 0.01 / ln(17/19) = 41.40 -> 42 draws from U_20,
    # 23 done: 19 more, every one in U_20 now; the stop is at draw 100 + 19 = 119, not at once (t >= k).
    sampler = ProsacSampler(np.arange(500), t_n=200_000)
    sampler.draw(100, np.random.default_rng(0))
    assert sampler.drawn_within(20) == 23 and sampler.drawn_within(500) == 100
    assert sampler.drawn_within(10) == 8  # T'_10 = 8
    stop = ProsacTermination(sampler, confidence=0.99)
    inliers = np.zeros(500, dtype=bool)
    inliers[:10] = True
    stop.on_new_best(inliers, None)
    assert stop.n_star == 20 and stop.k_stop == pytest.approx(math.log(0.01) / math.log(17 / 19))
    assert stop.required(10, 500) == 119
    later = sampler.draw(19, np.random.default_rng(1))
    assert later.max() < 20 and sampler.drawn_within(20) == 42
    # When every draw so far lies in U_n*, the stop is the paper's t >= k_n*: here at once.
    inliers[:20] = True
    stop.on_new_best(inliers, None)
    assert stop.n_star == 20 and stop.required(20, 500) == 119  # k_20 = 1 <= 42 draws from U_20: stop now


def test_prosac_counters_and_validation():
    sampler = ProsacSampler(np.arange(100))
    stop = ProsacTermination(sampler, confidence=0.99, max_iterations=777)
    # Before any model: n* is N, the bound the cap, no update.
    assert stop.counters() == {"prosac_n_star": 100, "prosac_k_stop": 777.0, "prosac_stop_at": 777, "prosac_updates": 0}
    inliers = np.zeros(100, dtype=bool)
    inliers[:40] = True
    stop.on_new_best(inliers, None)
    assert stop.counters() == {"prosac_n_star": 40, "prosac_k_stop": 1.0, "prosac_stop_at": 1, "prosac_updates": 1}
    stop.on_new_best(inliers, None)
    assert stop.counters()["prosac_updates"] == 2
    for name, value in (("beta", 0.0), ("beta", 1.0), ("psi", 0.0), ("psi", 1.0), ("min_n", 3), ("min_n", 20.5)):
        with pytest.raises(ValueError, match=rf"^option prosac_{name} has an invalid value {value!r}$"):
            ProsacTermination(ProsacSampler(np.arange(100)), **{name: value})
    ProsacTermination(ProsacSampler(np.arange(100)), min_n=4)  # the smallest allowed prefix, 3 + 1


def binomial_cdf(x: int, trials: int, beta: float) -> float:
    return sum(math.comb(trials, i) * beta**i * (1 - beta) ** (trials - i) for i in range(x + 1))


def test_prosac_non_random_minimum_exact_and_normal():
    # I_min = m + x + 1 with x the smallest count whose binomial cdf exceeds 1 - psi (chance agreements
    # of the n - 3 points outside the sample). Bin(17, 0.05): cdf(2) = 0.9497, cdf(3) = 0.9912 -> x = 3, I_min 7;
    # Bin(20, 0.05): cdf(2) = 0.9245, cdf(3) = 0.9841 -> 7; Bin(97, 0.05) -> x = 9, 13; Bin(497, 0.05) -> 33, 37.
    assert binomial_cdf(2, 17, 0.05) < 0.95 < binomial_cdf(3, 17, 0.05)
    assert binomial_cdf(8, 97, 0.05) < 0.95 < binomial_cdf(9, 97, 0.05)
    np.testing.assert_array_equal(non_random_minimum(np.array([20, 23, 100, 500]), 0.05, 0.05), [7, 7, 13, 37])
    # beta 0.1, psi 0.01: x = 6, 17, 66 for 20, 97, 497 trials.
    assert binomial_cdf(5, 20, 0.1) <= 0.99 < binomial_cdf(6, 20, 0.1)
    np.testing.assert_array_equal(non_random_minimum(np.array([23, 100, 500]), 0.1, 0.01), [10, 21, 70])
    # Edges: one trial, P(X <= 0) = 0.95 is not above 0.95, so x = 1 and I_min = 5; below a sample, n is m.
    np.testing.assert_array_equal(non_random_minimum(np.array([4, 2]), 0.05, 0.05), [5, 4])
    # The normal approximation: 3 + 97 * 0.05 + z_0.95 sqrt(97 * 0.05 * 0.95), z_0.95 = 1.6448536.
    normal = non_random_minimum(np.array([100, 500]), 0.05, 0.05, exact=False)
    np.testing.assert_allclose(normal, [3 + 97 * 0.05 + 1.6448536 * math.sqrt(97 * 0.0475),
                                        3 + 497 * 0.05 + 1.6448536 * math.sqrt(497 * 0.0475)], rtol=1e-7)
    assert non_random_minimum(np.array([100]), 0.1, 0.01, exact=False)[0] == pytest.approx(
        3 + 9.7 + 2.3263479 * math.sqrt(97 * 0.09), rel=1e-7)


def test_prosac_prefix_draws_by_hand_and_silently():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # log(0) and 0/0 at the edges are handled, not warned about
        k = prefix_draws(np.array([3, 2, 30, 0]), np.array([3, 20, 100, 50]), 0.01)
    assert k.dtype == np.float64
    # (3, 3): q = (3/3)(2/2)(1/1) = 1, one draw; (2, 20) and (0, 50): q = 0, never certain.
    assert k[0] == 1.0 and k[1] == np.inf and k[3] == np.inf
    # (30, 100): q = 30 * 29 * 28 / (100 * 99 * 98) = 0.025108, k = log(0.01) / log(1 - q) = 181.1.
    q = 30 * 29 * 28 / (100 * 99 * 98)
    assert k[2] == pytest.approx(math.log(0.01) / math.log(1 - q), rel=1e-12)
    assert 181 < k[2] < 182


def test_prosac_n_star_needs_a_non_random_prefix_of_at_least_min_n():
    N = 100
    # Six top-ranked inliers only: I_n = 6 < I_min(n) >= 7 for every n >= 20, so no prefix is trusted.
    inliers = np.zeros(N, dtype=bool)
    inliers[:6] = True
    stop = ProsacTermination(ProsacSampler(np.arange(N)), confidence=0.99, max_iterations=999)
    stop.on_new_best(inliers, None)
    assert stop.n_star is None and stop.required(6, N) == 999
    # Seven: I_20 = 7 = I_min(20) is non-random (>=), and n = 20 has the largest q:
    # k = log(0.01) / log(1 - 7 * 6 * 5 / (20 * 19 * 18)) = 147.7, n* = 20.
    inliers[6] = True
    stop.on_new_best(inliers, None)
    assert stop.n_star == 20
    assert stop.k_stop == pytest.approx(math.log(0.01) / math.log(1 - 210 / 6840), rel=1e-12)
    assert stop.required(7, N) == 148
    capped = ProsacTermination(ProsacSampler(np.arange(N)), confidence=0.99, max_iterations=100)
    capped.on_new_best(inliers, None)
    assert capped.n_star == 20 and capped.required(7, N) == 100  # the bound 148 is capped at max_iterations
    # The top 20 all inliers, the rest outliers: n = 20 itself is the (unique) one-draw prefix.
    inliers = np.zeros(N, dtype=bool)
    inliers[:20] = True
    stop = ProsacTermination(ProsacSampler(np.arange(N)), confidence=0.99)
    stop.on_new_best(inliers, None)
    assert stop.n_star == 20 and stop.k_stop == 1.0
