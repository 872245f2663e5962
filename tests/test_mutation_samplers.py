"""The samplers' contracts that the mutmut run of ``stereovo/estimation/roles/samplers.py`` found untested
(docs/mutation-testing.md): which triplet a given set of uniforms is, bit-for-bit normalisation,
the equal-weights shortcut, the exact fix-up draw, PROSAC's schedule at its boundaries, and the
replay sampler's bookkeeping.

Expected values are literals, arithmetic on literals, or an independent reference written from the
samplers' definitions (the k-th pick is the floor(u_k * size)-th of what is left; a weighted pick
inverts the cumulative weights left, interval i being ``[mass before i, mass up to i)``), never a
value asked of the code under test. PROSAC: Chum & Matas, "Matching with PROSAC", CVPR 2005; guided
sampling: Tordoff & Murray, "Guided sampling and consensus for motion estimation", ECCV 2002.
"""

from __future__ import annotations

import math
import warnings
from fractions import Fraction

import numpy as np
import pytest

from stereovo.estimation.roles.samplers import (
    ProsacSampler,
    ReplaySampler,
    UniformSampler,
    WeightedSampler,
    distinct_uniform_triplets,
    normalised_weights,
    prosac_growth,
    validate_order,
    validate_priors,
)

TINY = np.finfo(float).tiny


def _uniform_reference(u: np.ndarray, m: int) -> list[int]:
    """Pick k is the floor(u_k (m - k))-th smallest index not yet picked."""
    left = list(range(m))
    return [left.pop(min(int(x * (m - k)), m - k - 1)) for k, x in enumerate(u)]


def _weighted_reference(u: np.ndarray, w: np.ndarray) -> list[int]:
    """Sequential inversion of the cumulative weights left: the index whose interval holds u * mass."""
    w = [Fraction(x) for x in w]
    picked = []
    for x in u:
        target, before = Fraction(float(x)) * sum(w), Fraction(0)
        for i, wi in enumerate(w):
            if wi > 0 and before <= target < before + wi:
                break
            before += wi
        picked.append(i)
        w[i] = Fraction(0)
    return picked


# ---------------------------------------------------------------------------- uniform triplets


def test_uniform_triplets_are_three_uniforms_per_row_indexing_what_is_left():
    pools = np.array([3, 4, 5, 10, 1000, 3, 7])
    triplets = distinct_uniform_triplets(pools, np.random.default_rng(11))
    # The same generator, read directly: three uniforms per row, row after row, nothing else drawn.
    rng = np.random.default_rng(11)
    u = rng.random((pools.size, 3))
    assert triplets.dtype == np.int64 and triplets.shape == (pools.size, 3)
    assert triplets.tolist() == [_uniform_reference(row, m) for row, m in zip(u, pools)]
    after = np.random.default_rng(11)
    distinct_uniform_triplets(pools, after)
    assert after.random() == rng.random()
    # Three correspondences are enough to sample: the only triplet, in a random order.
    draws = UniformSampler(3).draw(50, np.random.default_rng(0))
    assert {tuple(sorted(row)) for row in draws.tolist()} == {(0, 1, 2)}


# ---------------------------------------------------------------------------- normalisation


def test_normalised_weights_keep_the_direct_quotient_bit_for_bit():
    # A finite normal sum: exactly p / sum(p) (dividing by the largest weight first would round differently).
    p = np.random.default_rng(0).random(6)
    np.testing.assert_array_equal(normalised_weights(p), p / np.sum(p))
    # A sum of exactly the smallest normal number (2^52 subnormal units) is still divided directly.
    sub = 2.0**-1074
    p = np.array([1863820546551667, 1080195320076443, 1559583760742386], dtype=float) * sub
    assert np.sum(p) == TINY
    np.testing.assert_array_equal(normalised_weights(p), p / TINY)
    # A weight that comes out at exactly the smallest normal number is kept as it is (not renormalised).
    p = np.array([0.1, 1.3, TINY * (0.1 + 1.3)])
    assert p[2] / np.sum(p) == TINY
    np.testing.assert_array_equal(normalised_weights(p), p / np.sum(p))
    # Single-precision or integer priors: float64 weights, the quotient of the float64 values.
    p32 = np.array([1.0, 2.0, 3.0, 4.0], dtype=np.float32)
    w = normalised_weights(p32)
    assert w.dtype == np.float64
    np.testing.assert_array_equal(w, np.array([1.0, 2.0, 3.0, 4.0]) / 10.0)


def test_normalised_weights_of_an_overflowing_sum_keep_their_ratios_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow warning, no deprecated NumPy call
        w = normalised_weights(np.array([1e308, 1e308, 5e307]))
        np.testing.assert_allclose(w, [0.4, 0.4, 0.2], rtol=1e-15)
        np.testing.assert_array_equal(normalised_weights(np.array([1.0, 3.0])), [0.25, 0.75])


def test_validation_messages_are_exact():
    with pytest.raises(ValueError, match=r"^priors contain NaN or inf$"):
        validate_priors(np.array([1.0, 1.0, np.inf, 1.0]), 4)
    with pytest.raises(ValueError, match=r"^order must be a permutation of range\(N\): each correspondence exactly once$"):
        validate_order(np.array([0, 2, 2, 1]), 4)


# ---------------------------------------------------------------------------- weighted sampler


def test_equal_weights_give_the_uniform_samplers_probability_bit_for_bit():
    mask = np.array([True, True, True, False, False])
    # (3/5)(2/4)(1/3) as the count formula multiplies it; the weighted sum over orders gives 0.1 + 2e-17.
    assert WeightedSampler(np.ones(5)).all_inlier_probability(mask) == UniformSampler(5).all_inlier_probability(mask)
    # A zero weight: the count formula over the five positive ones.
    with_zero = WeightedSampler(np.array([0.0, 2.0, 2.0, 2.0, 2.0, 2.0]))
    mask = np.array([True, True, True, True, False, False])
    assert with_zero.all_inlier_probability(mask) == UniformSampler(5).all_inlier_probability(mask[1:])


@pytest.mark.parametrize("priors", [[1.0, 2.0, 3.0, 4.0], [0.5, 0.0, 1.0, 0.25, 8.0], [3.0, 1.0, 1.0, 0.0, 1.0, 2.0]])
def test_weighted_draws_invert_the_cumulative_weights_left(priors):
    s = WeightedSampler(np.array(priors))
    draws = s.draw(300, np.random.default_rng(5))
    u = np.random.default_rng(5).random((300, 3))
    assert draws.tolist() == [_weighted_reference(row, s._w) for row in u]


def test_weighted_rows_that_rounding_cannot_place_are_drawn_exactly():
    # The three small weights vanish in the cumulative sums (0.5 + 5e-18 == 0.5): every compiled row is
    # flagged, and the exact draw takes both large weights first and one of the small ones third.
    s = WeightedSampler(np.array([1.0, 1e-17, 1e-17, 1e-17, 1.0]))
    draws = s.draw(400, np.random.default_rng(2))
    assert draws.dtype == np.int64
    assert all(sorted(row[:2]) == [0, 4] for row in draws.tolist())
    assert set(draws[:, 2].tolist()) == {1, 2, 3}
    # The exact draw from u: u * mass in [0.5, 0.75) is index 2 of four equal weights, and so on.
    np.testing.assert_array_equal(WeightedSampler(np.ones(4))._draw_exactly(np.array([0.5, 0.5, 0.5])), [2, 1, 3])


def test_exact_draw_at_the_top_of_the_mass_takes_the_last_positive_weight_left():
    # u * mass can round up to the whole mass when what is left is subnormal; u = 1 is that position.
    s = WeightedSampler(np.array([1.0, 2.0, 3.0, 0.0, 0.0]))
    np.testing.assert_array_equal(s._draw_exactly(np.array([1.0, 1.0, 1.0])), [2, 1, 0])
    t = WeightedSampler(np.array([0.0, 5.0, 0.0, 1.0, 1.0, 0.0]))
    np.testing.assert_array_equal(t._draw_exactly(np.array([1.0, 0.0, 1.0])), [4, 1, 3])


def test_log_probability_stays_a_finite_log_probability_when_the_mass_left_rounds_to_zero():
    # w = (0.5, 0.5, 5e-18): before the third pick 0.5 + 0.5 == 1.0, so the mass left rounds to 0.
    s = WeightedSampler(np.array([1.0, 1.0, 1e-17]))
    log_p = s.log_probability(np.array([[0, 1, 2], [2, 0, 1]]))
    assert np.all(np.isfinite(log_p)) and np.all(log_p <= 0.0)
    assert log_p[0] == pytest.approx(math.log(0.5), rel=1e-12)  # the third pick is all the mass left
    assert log_p[1] == pytest.approx(math.log(5e-18) + math.log(0.5) + 0.0, rel=1e-12)


# ---------------------------------------------------------------------------- PROSAC


def test_prosac_growth_at_the_default_t_n_by_hand():
    # T_N = 200000, N = 5: T_3 = 200000 (3 2 1)/(5 4 3) = 20000, T_4 = 80000, T_5 = 200000:
    # T'_3 = 1, T'_4 = 1 + 60000, T'_5 = 60001 + 120000.
    T = [Fraction(0)] * 3 + [Fraction(200000) * Fraction(6, 60)]
    T += [T[3] * 4 / 1, T[3] * 4 / 1 * 5 / 2]
    assert [T[k + 1] - T[k] for k in (3, 4)] == [60000, 120000]
    g = prosac_growth(5)
    assert g.dtype == np.int64 and g.tolist() == [0, 0, 0, 1, 60001, 180001]
    # N = m: one triplet, T'_3 = 1; N < m: all zeros, still integers.
    assert prosac_growth(3).tolist() == [0, 0, 0, 1]
    assert prosac_growth(2).dtype == np.int64
    # The sampler uses that schedule by default, and its own t_n when given one (T'_4 = 31, T'_5 = 91 at 100).
    np.testing.assert_array_equal(ProsacSampler(np.arange(5)).subset_sizes(np.array([60001, 60002])), [4, 5])
    np.testing.assert_array_equal(ProsacSampler(np.arange(5), t_n=100).subset_sizes(np.array([31, 32, 91, 92])),
                                  [4, 5, 5, 5])


def test_prosac_starts_with_the_top_three_and_samples_three_correspondences():
    order = np.array([4, 2, 0, 1, 3])
    for seed in range(12):
        first = ProsacSampler(order, t_n=100).draw(1, np.random.default_rng(seed))
        assert sorted(first[0].tolist()) == [0, 2, 4]
    three = ProsacSampler(np.array([2, 0, 1]))
    assert {tuple(sorted(row)) for row in three.draw(20, np.random.default_rng(0)).tolist()} == {(0, 1, 2)}


def test_prosac_draws_do_not_depend_on_how_they_are_batched():
    order = np.array([4, 2, 0, 1, 3, 6, 5, 7])
    whole = ProsacSampler(order, t_n=60).draw(40, np.random.default_rng(9))
    split = ProsacSampler(order, t_n=60)
    rng = np.random.default_rng(9)
    parts = np.concatenate([split.draw(b, rng) for b in (7, 1, 12, 20)])
    np.testing.assert_array_equal(parts, whole)
    assert split.t == 40


def test_prosac_probability_at_the_edges_of_its_schedule():
    # order (4, 2, 0, 1, 3), t_n 100: T'_3 = 1, T'_4 = 31, T'_5 = 91.
    order = np.array([4, 2, 0, 1, 3])
    s = ProsacSampler(order, t_n=100)
    s.draw(1, np.random.default_rng(0))
    # Draws 2..31 are u_4 = 1 plus two of {4, 2, 0}. Inliers 4, 0, 1 (ranks 0, 2, 3): 1 of the 3 pairs.
    mask = np.zeros(5, bool)
    mask[[4, 0, 1]] = True
    assert s.all_inlier_probability(mask) == pytest.approx(1 / 3, rel=1e-12)
    s.draw(29, np.random.default_rng(1))
    # Draw 31 = T'_4 is still anchored: with u_4 an outlier no draw is all-inlier.
    top = np.zeros(5, bool)
    top[[4, 2, 0]] = True
    assert s.all_inlier_probability(top) == 0.0
    s.draw(61, np.random.default_rng(2))
    # Draw 92 > T'_5: three of all five (u_5 = 3 not required): 4 inliers give (4 3 2)/(5 4 3).
    mask = np.ones(5, bool)
    mask[3] = False
    assert s.all_inlier_probability(mask) == pytest.approx(0.4, rel=1e-12)


# ---------------------------------------------------------------------------- replay


def test_replay_sampler_reports_its_size_and_hands_out_integer_indices():
    samples = np.array([[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [1.0, 3.0, 5.0], [5.0, 4.0, 0.0]])
    r = ReplaySampler(samples, 6)
    assert r.n == 6
    out = r.draw(4, None)
    assert out.dtype == np.int64 and out.tolist() == samples.astype(int).tolist()
    with pytest.raises(ValueError, match=r"^replay exhausted: 4 samples, asked for 5$"):
        r.draw(1, None)
