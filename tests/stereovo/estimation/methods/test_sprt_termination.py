"""The SPRT stop (SprtTermination; Chum & Matas 2008): the bound summed over the history of tests,
each charged with the draws made while it was in force, against values worked out by hand."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from stereovo.estimation.methods.sprt import SprtTermination, SprtTest, SprtVerification


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


# --- The SPRT stopping bound, summed over its tests, against values derived by hand ---

def _sprt_term(history, sampler=None):
    verifier = SimpleNamespace(history=history)
    return SprtTermination(verifier, confidence=0.99, max_iterations=10_000, sampler=sampler)


def _bound_at_half(past, current_A):
    """The SPRT bound at I = 50 of N = 100 (P_g = 4/33) for tests designed at epsilon 0.5 (h = 1, alpha = 1/A):
    ``past`` the (A, draws) of the past tests, ``current_A`` the current test's A."""
    q = 4 / 33
    log_eta = sum(d * math.log(1 - q * (1 - 1 / A)) for A, d in past)
    k = (math.log(0.01) - log_eta) / math.log(1 - q * (1 - 1 / current_A))
    return sum(d for _, d in past) + math.ceil(max(k, 0.0))


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
