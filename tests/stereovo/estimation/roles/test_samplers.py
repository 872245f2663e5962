"""The samplers (stereovo/estimation/roles/samplers.py): uniform, weighted, replay and PROSAC draws, their
probabilities and q, and the checks of priors and orders."""

from __future__ import annotations

import itertools
import math
import warnings
from fractions import Fraction

import numpy as np
import pytest
from scipy.stats import binom

from stereovo import estimate_motion
from stereovo.estimation.roles.samplers import (
    ProsacSampler,
    WeightedSampler,
    distinct_uniform_triplets,
    prosac_growth,
    shared_prosac_growth,
    ReplaySampler,
    UniformSampler,
    normalised_weights,
    validate_order,
    validate_priors,
)
from stereovo.metrics import frame_metrics
from stereovo.simulation import SimulationConfig, simulate_frame


def brute_force_q(w: np.ndarray, inliers: np.ndarray) -> float:
    """The defining sum over ordered distinct triples in I, O(|I|^3)."""
    w = w / w.sum()
    q = 0.0
    for a, b, c in itertools.permutations(np.flatnonzero(inliers), 3):
        q += w[a] * w[b] / (1 - w[a]) * w[c] / (1 - w[a] - w[b])
    return q


def test_uniform_triplets_distinct_and_uniform():
    rng = np.random.default_rng(0)
    s = distinct_uniform_triplets(np.full(60_000, 5), rng)
    assert np.all((s[:, 0] != s[:, 1]) & (s[:, 0] != s[:, 2]) & (s[:, 1] != s[:, 2]))
    counts = np.bincount(s.ravel(), minlength=5) / s.size
    np.testing.assert_allclose(counts, 0.2, atol=0.005)
    sets = {tuple(sorted(r)) for r in s[:2000]}
    assert len(sets) == 10  # every 3-subset of 5 appears


def test_weighted_sampler_follows_priors_and_log_probability_is_exact():
    priors = np.array([4.0, 3.0, 2.0, 1.0, 0.0])
    sampler = WeightedSampler(priors)
    rng = np.random.default_rng(0)
    draws = sampler.draw(100_000, rng)
    assert not np.any(draws == 4)  # zero prior is never drawn
    # Empirical frequency of each ordered triplet matches its exact log-probability.
    triplets = list(itertools.permutations(range(4), 3))
    probs = np.exp(sampler.log_probability(np.array(triplets)))
    assert probs.sum() == pytest.approx(1.0)
    keys = draws @ np.array([16, 4, 1])
    freq = np.array([np.mean(keys == a * 16 + b * 4 + c) for a, b, c in triplets])
    np.testing.assert_allclose(freq, probs, atol=0.006)


def test_prosac_growth_matches_reference_values():
    T = prosac_growth(500)
    assert [int(T[n]) for n in (4, 5, 10, 20, 50, 100, 200)] == [2, 3, 8, 23, 216, 1613, 12783]


def test_prosac_samples_respect_growth():
    order = np.random.default_rng(1).permutation(200)
    sampler = ProsacSampler(order)
    rank = np.empty(200, dtype=int)
    rank[order] = np.arange(200)
    draws = rank[sampler.draw(3000, np.random.default_rng(2))]
    t = np.arange(1, 3001)
    n = sampler.subset_sizes(t)
    anchored = t <= sampler.growth[n]
    assert np.all(draws.max(axis=1) < n)
    assert np.all(draws[anchored].max(axis=1) == n[anchored] - 1)
    assert set(draws[0]) == {0, 1, 2}


@pytest.mark.parametrize(
    "priors",
    [np.array([0.0, 0.0, 1e-300, 1.0, 1.0, 0.0]), np.array([1e12, 1.0, 1e-12, 0.0, 3.0]), np.array([0.0, 1.0, 1.0, 1.0])],
)
def test_weighted_sampler_draws_three_distinct_positive_weight_indices_under_extreme_priors(priors):
    draws = WeightedSampler(priors).draw(5000, np.random.default_rng(1))
    assert draws.shape == (5000, 3)
    assert np.all(priors[draws] > 0)
    assert np.all((draws[:, 0] != draws[:, 1]) & (draws[:, 0] != draws[:, 2]) & (draws[:, 1] != draws[:, 2]))


def test_weighted_sampler_fix_up_path_draws_distinct_positive_indices():
    # The vectorised draw hands rows that rounding pushed past the last interval to this exact path.
    sampler = WeightedSampler(np.array([0.0, 2.0, 1.0, 1.0, 0.0]))
    top = 1.0 - 2.0**-53  # the largest value Generator.random() returns
    for u in (np.array([top, top, top]), np.array([0.0, 0.0, 0.0]), np.array([0.5, top, 0.0])):
        picked = sampler._draw_exactly(u)
        assert len(set(picked.tolist())) == 3 and set(picked.tolist()) <= {1, 2, 3}
    assert sampler._draw_exactly(np.array([0.0, 0.0, 0.0])).tolist() == [1, 2, 3]


def test_prosac_samples_respect_n_max():
    sampler = ProsacSampler(np.arange(300))
    sampler.draw(50, np.random.default_rng(0))
    sampler.n_max = 40
    later = sampler.draw(5000, np.random.default_rng(1))
    assert later.max() < 40


def test_the_samplers_prosac_growth_is_computed_once_per_length_and_shared_read_only():
    first, again = shared_prosac_growth(300, 3, 200_000), shared_prosac_growth(300, 3, 200_000)
    assert first is again and not first.flags.writeable
    np.testing.assert_array_equal(first, prosac_growth(300))
    with pytest.raises(ValueError, match="read-only"):
        first[5] = 0
    assert shared_prosac_growth(2).tolist() == [0, 0, 0]
    assert ProsacSampler(np.arange(300)).growth is first


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


def test_weighted_q_is_the_exact_sequential_draw_probability():
    rng = np.random.default_rng(0)
    for trial in range(20):
        n = int(rng.integers(5, 25))
        w = rng.random(n) ** 3 if trial % 2 else np.exp(4 * rng.normal(size=n))
        w[rng.random(n) < 0.2] = 0.0
        w[:3] += 0.5
        inliers = rng.random(n) < 0.6
        assert WeightedSampler(w).all_inlier_probability(inliers) == pytest.approx(brute_force_q(w, inliers), rel=1e-12)
    # and it is what the sampler's own draws do
    w = np.r_[np.full(10, 4.0), np.ones(30)]
    inliers = np.r_[np.ones(8, bool), np.zeros(24, bool), np.ones(8, bool)]
    sampler = WeightedSampler(w)
    draws = sampler.draw(200_000, np.random.default_rng(1))
    hits = int(np.count_nonzero(np.all(inliers[draws], axis=1)))
    q = sampler.all_inlier_probability(inliers)
    lo, hi = binom.interval(0.999, 200_000, q)
    assert lo <= hits <= hi


def exact_q(w: np.ndarray, inliers: np.ndarray) -> Fraction:
    """The defining sum over ordered distinct triples in I, in exact rational arithmetic on the
    sampler's own (normalised) weights."""
    w = [Fraction(float(x)) for x in w]
    total = sum(w)
    q = Fraction(0)
    for a, b, c in itertools.permutations(np.flatnonzero(inliers), 3):
        q += w[a] / total * w[b] / (total - w[a]) * w[c] / (total - w[a] - w[b])
    return q


@pytest.mark.parametrize("priors, inliers", [
    # one weight holds nearly all the mass: the first draw is that point, the rest uniform
    (np.r_[1e300, 1e-300, np.ones(10)], np.r_[True, False, np.ones(7, bool), np.zeros(3, bool)]),
    (np.r_[1e17, 1e-17, np.ones(10)], np.r_[True, True, np.ones(7, bool), np.zeros(3, bool)]),
    # two of them, both inliers, or the heavier one an outlier
    (np.r_[1e200, 1e200, np.ones(9)], np.r_[True, True, np.ones(5, bool), np.zeros(4, bool)]),
    (np.r_[1e200, 1e199, np.ones(9)], np.r_[True, True, np.ones(5, bool), np.zeros(4, bool)]),
    (np.r_[1e200, 1e199, np.ones(9)], np.r_[False, True, np.ones(5, bool), np.zeros(4, bool)]),
    # three: the first draw is all of them
    (np.r_[1e250, 1e240, 1e230, np.ones(8)], np.r_[True, True, True, np.zeros(8, bool)]),
])
def test_weighted_q_holds_when_a_few_weights_hold_almost_all_the_mass(priors, inliers):
    # W - w_a cancels to 0 in floating point for the heavy point: the masses left are summed again
    sampler = WeightedSampler(priors)
    q = sampler.all_inlier_probability(inliers)
    assert q == pytest.approx(float(exact_q(sampler.weights, inliers)), rel=1e-9, abs=1e-300)
    # the draws: the cumulative sums cannot resolve the mass left, so such rows are drawn exactly
    draws = sampler.draw(20_000, np.random.default_rng(2))
    assert np.all(np.diff(np.sort(draws, axis=1), axis=1) > 0)
    hits = int(np.count_nonzero(np.all(inliers[draws], axis=1)))
    lo, hi = binom.interval(0.999, 20_000, q)
    assert lo <= hits <= hi


def test_prosac_sampler_q_is_that_of_its_next_draw():
    sampler = ProsacSampler(np.arange(100), t_n=1000)
    inliers = np.zeros(100, bool)
    inliers[:10] = True
    assert sampler.all_inlier_probability(inliers) == 1.0  # the first draw is the top three
    sampler.draw(20, np.random.default_rng(0))
    n = int(sampler.subset_sizes(np.array([sampler.t + 1]))[0])
    assert sampler.t + 1 <= sampler.growth[n] and n > 10  # anchored on u_n, an outlier
    assert sampler.all_inlier_probability(inliers) == 0.0
    sampler.draw(5000, np.random.default_rng(0))  # past T'_N: three of all N
    assert sampler.all_inlier_probability(inliers) == pytest.approx(10 * 9 * 8 / (100 * 99 * 98))


@pytest.mark.parametrize(
    "priors",
    [np.full(60, 1e307), np.exp(np.linspace(700.0, 709.7, 60)), np.r_[np.full(30, 1e-320), np.ones(30)],
     np.r_[1e300, 1e-300, np.ones(58)]],
)
def test_priors_of_any_scale_work(priors):
    frame = simulate_frame(SimulationConfig(n_correspondences=60, outlier_ratio=0.3), 3)
    w = normalised_weights(priors)
    assert np.all(np.isfinite(w)) and w.sum() == pytest.approx(1.0) and np.all((w > 0) == (priors > 0))
    sampler = WeightedSampler(priors)
    draws = sampler.draw(2000, np.random.default_rng(0))
    assert np.all(np.isfinite(sampler.log_probability(draws)))
    q = sampler.all_inlier_probability(frame.truth.inlier)
    drawn = np.mean(np.all(frame.truth.inlier[draws], axis=1))  # what the sampler's own draws do
    assert q == pytest.approx(drawn, abs=0.04)
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method="ransac+polish", priors=priors, rng=0,
                          noise_sigma=frame.noise_sigma)
    assert est.ok and frame_metrics(est, frame.truth).rot_err_deg < 1.0, est.status
    # Textbook ransac's consensus may leave out the point that the priors put in every draw (1e300):
    # then no draw can be all-inlier for it, its stop is never met and it fails at the cap; an "ok"
    # must be right.
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method="ransac", priors=priors, rng=0,
                          noise_sigma=frame.noise_sigma)
    assert (est.ok and frame_metrics(est, frame.truth).rot_err_deg < 1.0) or est.status.startswith(
        "failed: no confident consensus"), est.status


def test_complex_priors_are_refused_naming_priors():
    frame = simulate_frame(SimulationConfig(n_correspondences=30, outlier_ratio=0.3), 3)
    with pytest.raises(ValueError, match="priors"):
        estimate_motion(frame.prev, frame.curr, frame.camera, method="ransac", priors=np.ones(30) + 1j, rng=0)
    with pytest.raises(ValueError, match="priors"):
        WeightedSampler(np.ones(30, dtype=complex))


# --- Exact draws and probabilities of the uniform, weighted and PROSAC samplers ---


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
    assert draws.tolist() == [_weighted_reference(row, s.weights) for row in u]


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


def test_the_weighted_samplers_tables_are_the_float64_quotient_and_its_running_sums_bit_for_bit():
    rng = np.random.default_rng(0)
    for p in (rng.random(50), rng.random(50).astype(np.float32), rng.integers(1, 100, 50),
              np.exp(3.0 * rng.normal(size=50))):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            s = WeightedSampler(p)
        q = np.asarray(p, dtype=float)
        w = q / q.sum()  # numpy's pairwise sum of the float64 values, then the quotient
        np.testing.assert_array_equal(s.weights, w)
        np.testing.assert_array_equal(s._cdf, np.cumsum(w))
        np.testing.assert_array_equal(s._before, np.r_[0.0, np.cumsum(w)[:-1]])
        with pytest.raises(ValueError, match="read-only"):  # the draws' tables are built from them
            s.weights[0] = 1.0


def test_log_probability_stays_a_finite_log_probability_when_the_mass_left_rounds_to_zero():
    # w = (0.5, 0.5, 5e-18): before the third pick 0.5 + 0.5 == 1.0, so the mass left rounds to 0.
    s = WeightedSampler(np.array([1.0, 1.0, 1e-17]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # log1p(-1) in the branch np.where discards must not warn
        log_p = s.log_probability(np.array([[0, 1, 2], [2, 0, 1]]))
    assert np.all(np.isfinite(log_p)) and np.all(log_p <= 0.0)
    assert log_p[0] == pytest.approx(math.log(0.5), rel=1e-12)  # the third pick is all the mass left
    assert log_p[1] == pytest.approx(math.log(5e-18) + math.log(0.5) + 0.0, rel=1e-12)


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


def test_replay_sampler_reports_its_size_and_hands_out_integer_indices():
    samples = np.array([[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [1.0, 3.0, 5.0], [5.0, 4.0, 0.0]])
    r = ReplaySampler(samples, 6)
    assert r.n == 6
    out = r.draw(4, None)
    assert out.dtype == np.int64 and out.tolist() == samples.astype(int).tolist()
    with pytest.raises(ValueError, match=r"^replay exhausted: 4 samples, asked for 5$"):
        r.draw(1, None)


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
