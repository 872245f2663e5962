"""Tests written against the survivors of the mutmut runs (docs/mutation-testing.md): SPRT's design
and bookkeeping, and the samplers' probabilities, validation and draws.

Expected values are literals or arithmetic on literals from the papers' formulas (Matas & Chum,
"Randomized RANSAC with sequential probability ratio test", ICCV 2005; Chum & Matas, "Optimal
randomized RANSAC", PAMI 2008; Tordoff & Murray, "Guided sampling and consensus for motion
estimation", ECCV 2002; Chum & Matas, "Matching with PROSAC", CVPR 2005), never a value asked of the
code under test.
"""

from __future__ import annotations

import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest

from stereovo.estimation.roles.samplers import (
    ProsacSampler,
    ReplaySampler,
    UniformSampler,
    WeightedSampler,
    normalised_weights,
    prosac_growth,
    validate_priors,
)
from stereovo.estimation.methods.sprt import (
    SprtTermination,
    SprtTest,
    SprtVerification,
    good_model_exponent,
    rejection_probability,
    sprt_design,
)

# ---------------------------------------------------------------------------- SPRT design


def test_sprt_design_by_hand():
    # epsilon 0.5, delta 0.05: C = 0.95 ln(0.95 / 0.5) + 0.05 ln(0.05 / 0.5) = 0.4946319;
    # t_M = 10: K = 4.946319; A solves A = K + 1 + ln A: A = 8.029433 (8.0294 - ln 8.0294 = 5.9463).
    C, K, A = sprt_design(0.5, 0.05, 10.0)
    assert C == pytest.approx(0.95 * math.log(1.9) + 0.05 * math.log(0.1), rel=1e-12)
    assert C == pytest.approx(0.4946319372, rel=1e-9)
    assert K == pytest.approx(4.946319372, rel=1e-9)
    assert A == pytest.approx(8.029433328, rel=1e-8)
    assert A - math.log(A) == pytest.approx(K + 1.0, rel=1e-9)
    # Two models per sample halve K.
    _, K2, A2 = sprt_design(0.5, 0.05, 10.0, m_s=2.0)
    assert K2 == pytest.approx(4.946319372 / 2, rel=1e-9)
    assert A2 - math.log(A2) == pytest.approx(K2 + 1.0, rel=1e-9)
    # The default initial design (0.1, 0.01) at t_M = 500: C = 0.0713312, K = 35.66561, A = 40.36354.
    C, K, A = sprt_design(0.1, 0.01, 500.0)
    assert (C, K, A) == pytest.approx((0.07133122708, 35.66561354, 40.36354045), rel=1e-8)


def test_sprt_design_switches_the_test_off():
    # t_M = 1 at (0.1, 0.01): K = 0.0713, A = 1.0713 + ln A has its fixed point near 1.5 < 2: off.
    C, K, A = sprt_design(0.1, 0.01, 1.0)
    assert C == pytest.approx(0.07133122708, rel=1e-8) and K == pytest.approx(0.07133122708, rel=1e-8)
    assert A == math.inf
    # delta >= epsilon: no test (K reported 0).
    C, K, A = sprt_design(0.3, 0.3, 500.0)
    assert (K, A) == (0.0, math.inf)
    # Probabilities outside (0, 1): (0, 0, inf).
    for epsilon, delta in ((0.0, 0.01), (1.0, 0.01), (0.5, 0.0), (0.5, 1.0)):
        assert sprt_design(epsilon, delta, 500.0) == (0.0, 0.0, math.inf)
    # A just above 2 is kept: t_M such that K + 1 + ln 2 = 2 gives A = 2; a little more stays finite.
    C = 0.95 * math.log(1.9) + 0.05 * math.log(0.1)
    t_m = (1.0 - math.log(2.0)) / C * 1.01
    assert 2.0 < sprt_design(0.5, 0.05, t_m)[2] < 2.1


def test_good_model_exponent_by_hand():
    # 0.7 (0.1/0.5)^h + 0.3 (0.9/0.5)^h = 1 at h = 2 (0.028 + 0.972).
    assert good_model_exponent(0.7, 0.5, 0.1) == pytest.approx(2.0, rel=1e-9)
    # 0.6 (0.2)^h + 0.4 (1.8)^h = 1: h = 1 gives 0.12 + 0.72 = 0.84 < 1, so h > 1, and h = 2 gives
    # 0.024 + 1.296 > 1, so 1 < h < 2.
    h = good_model_exponent(0.6, 0.5, 0.1)
    assert 1.0 < h < 2.0 and 0.6 * 0.2**h + 0.4 * 1.8**h == pytest.approx(1.0, abs=1e-9)
    assert good_model_exponent(0.5, 0.5, 0.1) == 1.0  # the design's own epsilon
    assert good_model_exponent(1.0, 0.5, 0.1) == math.inf  # every point consistent: never rejected
    assert good_model_exponent(0.0, 0.5, 0.1) == 0.0
    # A good model worse than the design drifts upwards (0.05 ln 0.2 + 0.95 ln 1.8 > 0): always rejected.
    assert good_model_exponent(0.05, 0.5, 0.1) == 0.0
    for eps_i, delta_i in ((0.0, 0.1), (1.0, 0.1), (0.5, 0.0), (0.5, 1.0)):
        assert good_model_exponent(0.7, eps_i, delta_i) == 0.0


def test_rejection_probability_is_a_to_the_minus_h():
    assert rejection_probability(4.0, 1.0) == pytest.approx(0.25, rel=1e-12)
    assert rejection_probability(9.0, 0.5) == pytest.approx(1 / 3, rel=1e-12)
    assert rejection_probability(3.0, 2.0) == pytest.approx(1 / 9, rel=1e-12)
    assert rejection_probability(math.inf, 1.0) == 0.0
    assert rejection_probability(4.0, math.inf) == 0.0
    assert rejection_probability(4.0, 0.0) == 1.0


# ---------------------------------------------------------------------------- SPRT verifier bookkeeping


@pytest.mark.parametrize(("option", "value"), [("t_m", 0.0), ("epsilon0", 1.0), ("epsilon0", 0.0), ("delta0", 0.0),
                                               ("delta0", 1.0), ("chunk", 1.5), ("chunk", 0)])
def test_sprt_options_are_validated_by_name(option, value):
    with pytest.raises(ValueError, match=rf"option sprt_{option} has an invalid value {value!r}"):
        SprtVerification(n=100, **{option: value})


def test_sprt_verifier_initial_design_and_new_bests():
    v = SprtVerification(n=100)
    c = v.counters()
    assert c["sprt_designs"] == 1 and c["sprt_epsilon"] == 0.1 and c["sprt_delta"] == 0.01
    assert c["sprt_A"] == pytest.approx(40.36354045, rel=1e-8)
    assert (c["sprt_tested"], c["sprt_rejected"], c["sprt_accepted"], c["sprt_full"]) == (0, 0, 0, 0)
    assert isinstance(v.chunk, int)
    # delta0 below the floor is clamped to 1e-3.
    assert SprtVerification(n=100, delta0=1e-5).delta == 1e-3
    assert SprtVerification(n=100, delta0=0.9).delta == 0.3
    mask = np.zeros(100, bool)
    mask[:30] = True
    v.on_new_best(mask, None)
    assert v.epsilon == 0.3 and len(v.history) == 2
    assert (v.current.epsilon, v.current.delta) == (0.3, 0.01)
    _, _, A = sprt_design(0.3, 0.01, 500.0)
    assert v.current.A == A
    v.on_new_best(mask, None)  # the same inlier ratio: no new test
    assert len(v.history) == 2
    v.on_new_best(np.ones(100, bool), None)  # epsilon = 1 is no design
    v.on_new_best(np.zeros(100, bool), None)
    assert len(v.history) == 2 and v.epsilon == 0.3


def test_sprt_termination_charges_draws_to_the_test_in_force():
    v = SprtVerification(n=100)
    term = SprtTermination(v)
    term.on_batch(SimpleNamespace(n_hypotheses=16))
    assert [t.draws for t in v.history] == [16]
    mask = np.zeros(100, bool)
    mask[:50] = True
    v.on_new_best(mask, None)  # a new test begins between batches
    term.on_batch(SimpleNamespace(n_hypotheses=40))  # this batch began under test 1
    assert [t.draws for t in v.history] == [40, 0]
    term.on_batch(SimpleNamespace(n_hypotheses=50))
    assert [t.draws for t in v.history] == [40, 10]


# ---------------------------------------------------------------------------- samplers


def test_uniform_sampler_needs_three_and_gives_the_count_formula():
    with pytest.raises(ValueError, match="need at least 3 correspondences to sample, got 2"):
        UniformSampler(2)
    mask = np.zeros(10, bool)
    mask[:5] = True
    assert UniformSampler(10).all_inlier_probability(mask) == pytest.approx(5 * 4 * 3 / (10 * 9 * 8), rel=1e-12)
    with pytest.raises(ValueError, match=r"inliers must be a bool mask of shape \(10,\), got int64 \(10,\)"):
        UniformSampler(10).all_inlier_probability(mask.astype(np.int64))
    with pytest.raises(ValueError, match=r"inliers must be a bool mask of shape \(10,\)"):
        UniformSampler(10).all_inlier_probability(np.ones(9, bool))
    draws = UniformSampler(5).draw(400, np.random.default_rng(0))
    assert draws.shape == (400, 3) and draws.min() >= 0 and draws.max() <= 4
    assert np.all((draws[:, 0] != draws[:, 1]) & (draws[:, 0] != draws[:, 2]) & (draws[:, 1] != draws[:, 2]))
    assert set(np.unique(draws)) == {0, 1, 2, 3, 4}


def test_validate_priors_names_each_defect():
    with pytest.raises(ValueError, match="priors must be real weights, got complex dtype complex128"):
        validate_priors(np.ones(5, complex), 5)
    with pytest.raises(ValueError, match="priors must be an array of real weights, got dict"):
        validate_priors({"a": 1}, 5)
    with pytest.raises(ValueError, match=r"priors must have shape \(5,\), one weight per correspondence, got \(4,\)"):
        validate_priors(np.ones(4), 5)
    with pytest.raises(ValueError, match="priors contain NaN or inf"):
        validate_priors(np.array([1.0, np.nan, 1, 1, 1]), 5)
    with pytest.raises(ValueError, match="priors must be non-negative, got minimum -0.5"):
        validate_priors(np.array([1.0, -0.5, 1, 1, 1]), 5)
    with pytest.raises(ValueError, match="priors need at least 3 positive weights"):
        validate_priors(np.array([1.0, 1, 0, 0, 0]), 5)
    p = validate_priors([1, 2, 0, 3, 4], 5)
    assert p.dtype == float and p.tolist() == [1.0, 2.0, 0.0, 3.0, 4.0]
    with pytest.raises(ValueError, match=r"priors must be a 1-D array, one weight per correspondence, got shape \(2, 3\)"):
        WeightedSampler(np.ones((2, 3)))


def test_normalised_weights_direct_overflowing_and_tiny():
    np.testing.assert_array_equal(normalised_weights(np.array([1.0, 1.0, 2.0])), [0.25, 0.25, 0.5])
    np.testing.assert_allclose(normalised_weights(np.full(4, 1e308)), np.full(4, 0.25), rtol=1e-15)
    # A subnormal weight would be lost (below the smallest normal number): it keeps tiny, stays drawable
    # (the renormalisation by 1 + tiny == 1 leaves it tiny), and a zero weight stays zero.
    tiny = np.finfo(float).tiny
    w = normalised_weights(np.array([1.0, 1.0, 1e-320]))
    assert w.tolist() == [0.5, 0.5, tiny]
    assert normalised_weights(np.array([1.0, 3.0, 1e-320, 0.0])).tolist() == [0.25, 0.75, tiny, 0.0]
    # All weights subnormal: the sum is below tiny, so they are divided by the largest first.
    np.testing.assert_allclose(normalised_weights(np.array([1e-320, 1e-320, 2e-320])), [0.25, 0.25, 0.5], rtol=1e-3)


def test_weighted_sampler_probabilities_by_hand():
    s = WeightedSampler(np.array([1.0, 2.0, 3.0, 4.0]))
    # Ordered draw (3, 2, 1): 4/10 * 3/(10 - 4) * 2/(10 - 7).
    expected = math.log(0.4) + math.log(3 / 6) + math.log(2 / 3)
    np.testing.assert_allclose(s.log_probability(np.array([[3, 2, 1], [0, 1, 2]])),
                               [expected, math.log(0.1) + math.log(2 / 9) + math.log(3 / 7)], rtol=1e-12)
    # q for the inliers {0, 1, 2}: the sum over their 6 orders of w_a/W w_b/(W - w_a) w_c/(W - w_a - w_b).
    w = {0: 1.0, 1: 2.0, 2: 3.0}
    q = sum(w[a] / 10 * w[b] / (10 - w[a]) * w[c] / (10 - w[a] - w[b]) for a, b, c in itertools.permutations(w))
    assert s.all_inlier_probability(np.array([True, True, True, False])) == pytest.approx(q, rel=1e-12)
    assert s.all_inlier_probability(np.array([True, True, False, False])) == pytest.approx(0.0, abs=1e-15)
    assert s.all_inlier_probability(np.ones(4, bool)) == pytest.approx(1.0, rel=1e-12)
    # Equal positive weights: the count formula over the positive ones (one zero weight of five).
    e = WeightedSampler(np.array([1.0, 1.0, 0.0, 1.0, 1.0]))
    mask = np.array([True, True, True, False, False])  # two inliers of positive weight
    assert e.all_inlier_probability(mask) == 0.0
    mask = np.array([True, True, True, True, False])  # three inliers among four positive
    assert e.all_inlier_probability(mask) == pytest.approx(3 * 2 * 1 / (4 * 3 * 2), rel=1e-12)


def test_weighted_sampler_draws_follow_the_weights():
    s = WeightedSampler(np.array([0.0, 1.0, 1.0, 1.0, 6.0]))
    draws = s.draw(20_000, np.random.default_rng(3))
    assert draws.dtype == np.int64 and draws.shape == (20_000, 3)
    assert not np.any(draws == 0)  # zero weight: never drawn
    assert np.all((draws[:, 0] != draws[:, 1]) & (draws[:, 0] != draws[:, 2]) & (draws[:, 1] != draws[:, 2]))
    # First pick: index 4 with probability 6/9 (binomial sd 0.0033 at n = 20000).
    assert np.mean(draws[:, 0] == 4) == pytest.approx(6 / 9, abs=0.015)
    # The exact fix-up path draws the same distribution: from u, by inverting explicit cumulative weights.
    np.testing.assert_array_equal(s._draw_exactly(np.array([0.0, 0.0, 0.0])), [1, 2, 3])
    np.testing.assert_array_equal(s._draw_exactly(np.array([0.99, 0.99, 0.99])), [4, 3, 2])


def test_prosac_growth_and_sampler_start():
    assert prosac_growth(2).tolist() == [0, 0, 0]
    g = prosac_growth(5, 3, 100)
    # T_3 = 100 * (3 * 2 * 1) / (5 * 4 * 3) = 10, T_4 = 10 * 4 / 1 = 40, T_5 = 40 * 5 / 2 = 100:
    # T'_3 = 1, T'_4 = 1 + 30 = 31, T'_5 = 31 + 60 = 91.
    assert g.tolist() == [0, 0, 0, 1, 31, 91]
    order = np.array([4, 2, 0, 1, 3])
    s = ProsacSampler(order, t_n=100)
    mask = np.zeros(5, bool)
    mask[[4, 2, 0]] = True  # the top three are inliers: the first draw (the top three) is all-inlier
    assert s.all_inlier_probability(mask) == 1.0
    first = s.draw(1, np.random.default_rng(0))
    assert sorted(first[0].tolist()) == [0, 2, 4]
    # Draw 2 uses n = g(2) = 4, anchored (2 <= T'_4 = 31): u_4 = order[3] = 1 plus two of the top three.
    mask = np.zeros(5, bool)
    mask[[4, 2, 1]] = True
    assert s.all_inlier_probability(mask) == pytest.approx(2 * 1 / (3 * 2), rel=1e-12)
    mask[1] = False
    assert s.all_inlier_probability(mask) == 0.0  # the anchor u_4 is an outlier
    second = s.draw(1, np.random.default_rng(1))[0]
    assert second[2] == 1 and set(second[:2]) <= {4, 2, 0}
    with pytest.raises(ValueError, match="need at least 3 correspondences to sample, got 2"):
        ProsacSampler(np.array([1, 0]))
    with pytest.raises(ValueError, match="order must be a permutation of range"):
        ProsacSampler(np.array([0, 0, 1]))
    with pytest.raises(ValueError, match=r"order must be an integer array of shape \(3,\), got float64"):
        ProsacSampler(np.array([0.0, 1.0, 2.0]))


def test_replay_sampler_hands_out_the_samples_in_order():
    samples = np.array([[0, 1, 2], [3, 4, 5], [1, 3, 5]])
    r = ReplaySampler(samples, 6)
    np.testing.assert_array_equal(r.draw(2, None), samples[:2])
    np.testing.assert_array_equal(r.draw(1, None), samples[2:])
    with pytest.raises(ValueError, match="replay exhausted: 3 samples, asked for 4"):
        r.draw(1, None)
    with pytest.raises(ValueError, match=r"samples must have shape \(M, 3\), got \(2, 2\)"):
        ReplaySampler(np.zeros((2, 2)), 6)
    with pytest.raises(ValueError, match=r"sample indices must lie in \[0, 6\)"):
        ReplaySampler(np.array([[0, 1, 6]]), 6)
    with pytest.raises(ValueError, match=r"sample indices must lie in \[0, 6\)"):
        ReplaySampler(np.array([[0, -1, 2]]), 6)


def _sprt_term(history, sampler=None):
    verifier = SimpleNamespace(history=history)
    return SprtTermination(verifier, confidence=0.99, max_iterations=10_000, sampler=sampler)


def test_sprt_termination_gives_a_guided_samplers_q_the_best_inliers():
    seen = []

    def q_of(inliers):
        seen.append(np.flatnonzero(inliers).tolist())
        return 0.5

    term = _sprt_term([SprtTest(epsilon=0.5, delta=0.05, A=math.inf)], SimpleNamespace(all_inlier_probability=q_of))
    assert term.required(3, 10) == 10_000  # no best yet: q = 0
    inliers = np.zeros(10, bool)
    inliers[[1, 4, 7]] = True
    term.on_new_best(inliers, None)
    assert seen == [[1, 4, 7]]
    # q = 0.5, the test off (alpha 0): ceil(log 0.01 / log 0.5) = ceil(6.64) = 7.
    assert term.required(3, 10) == 7


def test_sprt_alphas_are_per_inlier_count_and_survive_many_counts():
    # A test for epsilon_i = 0.5, delta_i = 0.1, A = 3. At I = 50 of 100, h = 1 (the design's own epsilon):
    # alpha = 1/3, P_g = 4/33, k = ceil(log 0.01 / log(1 - (4/33)(2/3))) = ceil(54.65) = 55.
    # At I = 70, h = 2: alpha = 1/9, k = 13 (test_stopping_bounds). Asked one after the other, each count
    # gets its own alpha (one shared cache entry would give 19 for I = 70).
    assert math.ceil(math.log(0.01) / math.log(1 - (4 / 33) * (2 / 3))) == 55
    term = _sprt_term([SprtTest(epsilon=0.5, delta=0.1, A=3.0)])
    assert term.required(50, 100) == 55
    assert term.required(70, 100) == 13
    assert term.required(50, 100) == 55
    # Many different counts (more than the 16 the cache keeps) still give the same bounds.
    for count in range(40, 80):
        term.required(count, 100)
    assert term.required(70, 100) == 13 and term.required(50, 100) == 55


def test_sprt_bound_sums_three_tests():
    # N = 100, I = 50, P_g = 4/33; tests designed for epsilon 0.5 (h = 1): alpha = 1/A.
    # Test 1 (A = 4) ran 10 draws, test 2 (A = 2) 5 draws, test 3 (A = 4) is current:
    # log eta = 10 log(1 - (4/33)(3/4)) + 5 log(1 - (4/33)(1/2)) = 10 log(10/11) + 5 log(31/33);
    # k_3 = (log 0.01 - log eta) / log(10/11) = 35.04, so 15 + 36 = 51 draws in all.
    log_eta = 10 * math.log(10 / 11) + 5 * math.log(31 / 33)
    expected = 15 + math.ceil((math.log(0.01) - log_eta) / math.log(10 / 11))
    assert expected == 51
    history = [SprtTest(0.5, 0.05, 4.0, draws=10), SprtTest(0.5, 0.05, 2.0, draws=5), SprtTest(0.5, 0.05, 4.0)]
    assert _sprt_term(history).required(50, 100) == 51


def test_sprt_bound_when_one_draw_surely_finds_the_model():
    # A guided sampler whose q = 1 and the tests off (alpha = 0): P_find = 1, one more draw than done.
    sure = SimpleNamespace(all_inlier_probability=lambda inliers: 1.0)
    term = _sprt_term([SprtTest(0.5, 0.05, math.inf, draws=10), SprtTest(0.5, 0.05, math.inf)], sure)
    term.on_new_best(np.ones(100, bool), None)
    assert term.required(50, 100) == 11
    # A past test with no draws and q = 1 contributes nothing (0 draws x a clipped log, not 0 x -inf):
    # the current test (A = 4, alpha 1/4) needs ceil(log 0.01 / log(1/4)) = ceil(3.32) = 4.
    term = _sprt_term([SprtTest(0.5, 0.05, math.inf, draws=0), SprtTest(0.5, 0.05, 4.0)], sure)
    term.on_new_best(np.ones(100, bool), None)
    assert term.required(50, 100) == 4


def test_sprt_bound_clips_to_one_and_the_cap_and_stops_after_enough_draws():
    # Test 1 (off) ran 100 draws at P_g = 29/33's complement: log eta = 100 log(29/33) = -12.92 < log 0.01,
    # so the confidence is already reached: no further draw, the bound is the 100 done.
    history = [SprtTest(0.5, 0.05, math.inf, draws=100), SprtTest(0.5, 0.05, 4.0)]
    assert 100 * math.log(29 / 33) < math.log(0.01)
    assert _sprt_term(history).required(50, 100) == 100
    # The cap: 49 draws needed (test_stopping_bounds), max_iterations 10.
    term = SprtTermination(SimpleNamespace(history=[SprtTest(0.5, 0.05, 4.0)]), confidence=0.99, max_iterations=10)
    assert term.required(50, 100) == 10
    # q = 0.999 with the test off: ceil(log 0.01 / log 0.001) = ceil(0.67) = 1 draw.
    almost = SimpleNamespace(all_inlier_probability=lambda inliers: 0.999)
    term = _sprt_term([SprtTest(0.5, 0.05, math.inf)], almost)
    term.on_new_best(np.ones(100, bool), None)
    assert term.required(50, 100) == 1


def _bound_at_half(past, current_A):
    """The SPRT bound at I = 50 of N = 100 (P_g = 4/33) for tests designed at epsilon 0.5 (h = 1, alpha = 1/A):
    ``past`` the (A, draws) of the past tests, ``current_A`` the current test's A."""
    q = 4 / 33
    log_eta = sum(d * math.log(1 - q * (1 - 1 / A)) for A, d in past)
    k = (math.log(0.01) - log_eta) / math.log(1 - q * (1 - 1 / current_A))
    return sum(d for _, d in past) + math.ceil(max(k, 0.0))


def test_sprt_bound_kept_between_batches_follows_the_past_draws_and_redesigns():
    # The loop asks after every batch and the answer is kept; it must be recomputed whenever what it reads
    # changes: the draws of a past test (a batch begun under it is charged after the redesign), a new test.
    history = [SprtTest(0.5, 0.05, 4.0, draws=10), SprtTest(0.5, 0.05, 2.0, draws=5), SprtTest(0.5, 0.05, 4.0)]
    term = SprtTermination(SimpleNamespace(history=history), confidence=0.99, max_iterations=10_000)
    assert term.required(50, 100) == _bound_at_half([(4.0, 10), (2.0, 5)], 4.0) == 51
    history[2].draws = 7  # the current test's draws are not read
    assert term.required(50, 100) == 51
    history[1].draws += 10
    assert term.required(50, 100) == _bound_at_half([(4.0, 10), (2.0, 15)], 4.0) == 54
    history.append(SprtTest(0.5, 0.05, 8.0))
    assert term.required(50, 100) == _bound_at_half([(4.0, 10), (2.0, 15), (4.0, 7)], 8.0) != 54


def test_good_model_exponent_beyond_the_bracket_is_its_end_not_an_error():
    # epsilon 0.9 against a test for epsilon_i 0.5 with delta_i just under it: log a = -log b = 2 x 10^-r
    # (nearly), so eps a^h + (1 - eps) b^h = 1 is 0.9 / y + 0.1 y = 1 with y = b^h: y = 9, h = ln 9 / (2 x 10^-r).
    # At r = 5 that is 1.1e5, found by the solver; at r = 6 it is 1.1e6, past the bracket's end (2^20 = 1.05e6),
    # which is returned: a good model is then never rejected (alpha = A^-h = 0) either way.
    assert good_model_exponent(0.9, 0.5, 0.5 - 1e-5) == pytest.approx(math.log(9) / 2e-5, rel=1e-4)
    h = good_model_exponent(0.9, 0.5, 0.5 - 1e-6)
    assert 1e6 <= h < math.log(9) / 2e-6
    assert rejection_probability(10.0, h) == 0.0


def _sprt_frame(n=200, epsilon=0.5, seed=11):
    from stereovo.estimation.problem import StereoProblem
    from stereovo.estimation.roles.scoring import InlierCount, ReprojectionResidual
    from stereovo.estimation.roles.verification import ScoringContext
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=epsilon), seed)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    return frame, problem, ScoringContext(problem, ReprojectionResidual(9.0), InlierCount(), 9.0)


def test_sprt_verifier_with_its_test_off_scores_every_point_and_counts_each_batch():
    # delta0 >= epsilon0 switches the test off (A = inf): every hypothesis is scored on all N points (its
    # inlier count, the quality), accepted and counted as verified fully, batch after batch.
    from stereovo.geometry import random_rotation

    _, problem, ctx = _sprt_frame()
    rng = np.random.default_rng(2)
    R = np.stack([np.eye(3)] * 3 + [random_rotation(rng, 0.1) for _ in range(2)])
    t = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -0.9], [0.1, 0.0, -1.0], [0.0, 0.0, -1.0], [0.2, 0.1, -1.1]])
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(5)])
    verifier = SprtVerification(problem.n, epsilon0=0.1, delta0=0.2)
    assert not verifier.current.active
    counts = np.sum(ctx.residuals(R, t) < 9.0, axis=1)
    for batch in (1, 2):
        scores, checks = verifier.verify(ctx, R, t, rng, samples=samples)
        np.testing.assert_array_equal(scores, counts)
        assert checks == 5 * problem.n
        c = verifier.counters()
        assert (c["sprt_accepted"], c["sprt_full"], c["sprt_tested"]) == (5 * batch, 5 * batch, 0)


def _sprt_by_hand(sq, samples, perm, test, gate=9.0):
    """The SPRT point by point (docs: Matas & Chum 2005) for each hypothesis' squared residuals ``sq (H, N)``:
    in the order ``perm``, its own ``samples`` skipped, log lambda grows by log(delta / epsilon) per consistent
    point and by log((1 - delta) / (1 - epsilon)) per inconsistent one; rejected once above log A. Returns the
    rejected mask and, per hypothesis, the points checked and the consistent ones up to the rejection."""
    log_c, log_i, log_A = math.log(test.delta / test.epsilon), math.log((1 - test.delta) / (1 - test.epsilon)), math.log(test.A)
    rejected, checked, consistent = [], [], []
    for h in range(sq.shape[0]):
        lam, c, k, out = 0.0, 0, 0, False
        for j in perm:
            if j in samples[h]:
                continue
            k += 1
            inside = sq[h, j] < gate
            c += inside
            lam += log_c if inside else log_i
            if lam > log_A:
                out = True
                break
        rejected.append(out)
        checked.append(k)
        consistent.append(c)
    return np.array(rejected), np.array(checked), np.array(consistent)


class _OtherResidual:
    """Stands in for ReprojectionResidual in the sprt module's type test: the numpy route is taken."""


@pytest.mark.parametrize("route", ["compiled", "numpy"])
def test_sprt_verifier_decides_counts_and_reestimates_delta_point_by_point(monkeypatch, route):
    # Two batches of wrong motions near the truth, by hand: which are rejected, the point checks paid (a
    # rejected hypothesis the points up to its rejection, an accepted one all N), the accepted ones' scores,
    # and delta re-estimated as the mean over all rejected hypotheses so far of consistent / checked, a new
    # test designed when it moves by more than 5 %. Then a batch of the true motion, all accepted: no new
    # evidence, no new test, N checks each. Both routes: the compiled pass and the numpy one (chunks of 16,
    # 32, ... points: most of these hypotheses are rejected after the first chunk).
    import stereovo.estimation.methods.sprt as sprt_module
    from stereovo.geometry import random_rotation

    if route == "numpy":
        monkeypatch.setattr(sprt_module, "ReprojectionResidual", _OtherResidual)

    frame, problem, ctx = _sprt_frame()
    rng = np.random.default_rng(5)
    verifier = SprtVerification(problem.n, t_m=200.0, epsilon0=0.4, delta0=0.05)
    ratios, designs = [], 1
    for batch, seed in enumerate((1, 2)):
        R = np.stack([random_rotation(rng, np.radians(0.5)) @ frame.truth.rotation for _ in range(40)])
        t = frame.truth.translation + rng.normal(0, 0.05, (40, 3))
        samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(40)])
        test = verifier.current
        sq = ctx.residuals(R, t)
        rejected, checked, consistent = _sprt_by_hand(sq, samples, np.random.default_rng(seed).permutation(problem.n), test)
        assert 5 <= rejected.sum() <= 35
        scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(seed), samples=samples)
        np.testing.assert_array_equal(np.isinf(scores), rejected)
        np.testing.assert_array_equal(scores[~rejected], np.sum(sq[~rejected] < 9.0, axis=1))
        assert checks == checked[rejected].sum() + (~rejected).sum() * problem.n
        # the accepted ones' inliers come from the residuals just computed; a rejected one's are computed
        i, j = np.flatnonzero(~rejected)[0], np.flatnonzero(rejected)[0]
        for k, fresh in ((i, False), (j, True)):
            mask, computed = ctx.inliers_of(R, t, k)
            np.testing.assert_array_equal(mask, sq[k] < 9.0)
            assert computed is fresh
        ratios += list(consistent[rejected] / checked[rejected])
        delta = min(max(np.mean(ratios), 1e-3), 0.3)
        c = verifier.counters()
        if abs(delta - test.delta) > 0.05 * test.delta:
            designs += 1
            assert c["sprt_delta"] == pytest.approx(delta, rel=1e-12)
        assert c["sprt_designs"] == designs and c["sprt_rejected"] == len(ratios)
        assert c["sprt_accepted"] == 40 * (batch + 1) - len(ratios)
    assert designs >= 2
    accepted = verifier.counters()["sprt_accepted"]
    assert accepted + len(ratios) == 80 and verifier.counters()["sprt_tested"] == 80
    good_R = np.repeat(frame.truth.rotation[None], 4, axis=0)
    good_t = np.repeat(frame.truth.translation[None], 4, axis=0)
    scores, checks = verifier.verify(ctx, good_R, good_t, np.random.default_rng(3), samples=samples[:4])
    assert np.all(np.isfinite(scores)) and checks == 4 * problem.n
    c = verifier.counters()
    assert c["sprt_designs"] == designs and c["sprt_rejected"] == len(ratios) and c["sprt_accepted"] == accepted + 4


def test_sprt_verifier_accepts_cheap_fits_and_single_point_chunks_and_designs_with_its_models_per_sample():
    # t_m in (0, 1] (a fit cheaper than a point check) and chunk = 1 are valid settings; m_s divides
    # K = t_m C / m_s, and A is the fixed point of A = K + 1 + log A.
    SprtVerification(50, t_m=0.5, chunk=1)
    epsilon, delta = 0.1, 0.01
    C = (1 - delta) * math.log((1 - delta) / (1 - epsilon)) + delta * math.log(delta / epsilon)
    for m_s in (1.0, 2.0):
        K = 500.0 * C / m_s
        A = K + 1.0
        for _ in range(200):
            A = K + 1.0 + math.log(A)
        assert SprtVerification(50, m_s=m_s).current.A == pytest.approx(A, rel=1e-9)


def test_sprt_bound_when_the_current_test_is_blind_and_the_past_ones_reached_the_confidence_exactly():
    # The current test, designed for epsilon_i = 0.99 with delta_i = 0.5, rejects every good model of epsilon 0.5
    # (h = 0, alpha = 1: P_find = 0; test_stopping_bounds). A guided q = 0.5 and one draw under a past test that was
    # off (alpha 0): log eta = log(1 - 0.5), exactly log(1 - confidence) at confidence 0.5, so the confidence is
    # reached (eta <= 1 - p): stop at the one draw done.
    blind = SprtTest(epsilon=0.99, delta=0.5, A=4.0)
    half = SimpleNamespace(all_inlier_probability=lambda inliers: 0.5)
    term = SprtTermination(SimpleNamespace(history=[SprtTest(0.5, 0.05, math.inf, draws=1), blind]), confidence=0.5,
                           max_iterations=10_000, sampler=half)
    term.on_new_best(np.ones(100, bool), None)
    assert term.required(50, 100) == 1
    # Reached after 60 draws (P_g = 4/33, A = 4: 60 log(10/11) < log 0.01; test_stopping_bounds), with a cap of 50:
    # the draws done are past the cap, the bound is the cap.
    reached = [SprtTest(epsilon=0.5, delta=0.05, A=4.0, draws=60), blind]
    assert SprtTermination(SimpleNamespace(history=reached), confidence=0.99, max_iterations=50).required(50, 100) == 50
    assert SprtTermination(SimpleNamespace(history=reached), confidence=0.99, max_iterations=60).required(50, 100) == 60


def test_sprt_verifier_hands_the_kernel_float64_motions_and_int64_samples():
    # kernels_verification takes float64 / int64 arrays, which its wrappers ensure: motions in half precision and
    # sample indices held as float16 (numba compiles no float16) or int32 give the verdicts, checks, scores and
    # delta of their float64 / int64 copies on the compiled route.
    from stereovo.geometry import random_rotation

    frame, problem, ctx = _sprt_frame()
    rng = np.random.default_rng(7)
    R = np.stack([random_rotation(rng, np.radians(0.5)) @ frame.truth.rotation for _ in range(30)]).astype(np.float16)
    t = (frame.truth.translation + rng.normal(0, 0.05, (30, 3))).astype(np.float16)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(30)])

    def run(R, t, samples):
        verifier = SprtVerification(problem.n, t_m=200.0, epsilon0=0.4, delta0=0.05)
        scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(3), samples=samples)
        return scores.tolist(), checks, verifier.delta, verifier.n_accepted

    expected = run(R.astype(float), t.astype(float), samples)
    assert 0 < expected[3] < 30
    assert run(R, t, samples) == expected
    assert run(R.astype(float), t.astype(float), samples.astype(np.float16)) == expected
    assert run(R.astype(float), t.astype(float), samples.astype(np.int32)) == expected


def test_prosac_stop_past_the_cap_is_the_cap():
    # test_stopping_bounds' maximality case: N = 500, 100 draws of which T'_20 = 23 lie in U_20, a best of the top
    # 10: n* = 20, k_20 = 41.40 -> 42 draws from U_20, 19 more; the stop at draw 100 + 19 = 119. With a cap of 110
    # draws the stop is the cap, even though the draws still needed from U_20 (19) are within it.
    from stereovo.estimation.methods.prosac import ProsacTermination

    sampler = ProsacSampler(np.arange(500), t_n=200_000)
    sampler.draw(100, np.random.default_rng(0))
    assert sampler.drawn_within(20) == 23
    inliers = np.zeros(500, dtype=bool)
    inliers[:10] = True
    for cap, expected in ((110, 110), (119, 119), (10_000, 119)):
        stop = ProsacTermination(sampler, confidence=0.99, max_iterations=cap)
        stop.on_new_best(inliers, None)
        assert stop.n_star == 20 and stop.required(10, 500) == expected, cap
