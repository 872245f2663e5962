"""PROSAC (Chum & Matas, "Matching with PROSAC", CVPR 2005): its termination (non-randomness,
maximality, n* and the guards) and the stop of a PROSAC ordering by its schedule."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import binom

from stereovo import estimate_motion
from stereovo.estimation.loop import run_ransac
from stereovo.estimation.estimator_options import EstimatorOptions
from stereovo.estimation.registry import method_spec
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.methods.prosac import ProsacTermination, non_random_minimum, prefix_draws
from stereovo.estimation.roles.samplers import ProsacSampler
from stereovo.estimation.methods.sprt import SprtTermination, SprtVerification
from stereovo.estimation.methods.tdd import TddTermination, TddVerification
from stereovo.estimation.roles.termination import AdaptiveTermination
from stereovo.geometry import rotation_error
from stereovo.simulation import SimulationConfig, simulate_frame
from tests.support.stopping import CALIBRATION_CONFIDENCE, calibration_frames


def perfect_order_frame(n=300, epsilon=0.5, seed=7):
    frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=epsilon), seed)
    order = np.argsort(~frame.truth.inlier, kind="stable")  # every inlier first
    return frame, order


def random_ordering_rule(epsilon: float, orderings: int = 400, n: int = 500) -> tuple[float, float, float]:
    """PROSAC's rule told the true consensus on random orderings: ``(mean k_n* / k_N, mean share at n*, share)``."""
    n_inliers = int(round(n * (1 - epsilon)))
    k_n = float(prefix_draws(n_inliers, n, 0.01))  # RANSAC's bound on the same consensus
    ratios, shares = [], []
    for seed in range(orderings):
        g = np.random.default_rng(seed)
        inliers = np.zeros(n, dtype=bool)
        inliers[g.choice(n, n_inliers, replace=False)] = True
        order = g.permutation(n)
        stop = ProsacTermination(ProsacSampler(order), confidence=0.99)
        stop.on_new_best(inliers, None)
        ratios.append(stop.k_stop / k_n)
        shares.append(inliers[order[: stop.n_star]].mean())
    return float(np.mean(ratios)), float(np.mean(shares)), n_inliers / n


def binomial_cdf(x: int, trials: int, beta: float) -> float:
    return sum(math.comb(trials, i) * beta**i * (1 - beta) ** (trials - i) for i in range(x + 1))


def schedule_by_hand(sampler: ProsacSampler, inliers: np.ndarray, confidence: float, draws: int = 60_000) -> float:
    """The first T with ``prod_{t<=T} (1 - q_t) <= 1 - confidence``, each draw's q_t read off the
    sampler's own schedule (``subset_sizes``, anchored while ``t <= T'_n``) one draw at a time."""
    t = np.arange(1, draws + 1)
    n = sampler.subset_sizes(t)
    ranked = inliers[sampler.order]
    count = np.r_[0, np.cumsum(ranked)]
    q = np.empty(draws)
    for k in range(draws):
        m = int(n[k])
        if t[k] <= sampler.growth[m] and m > 3:  # u_m plus two of the m - 1 above it
            q[k] = ranked[m - 1] * count[m - 1] * (count[m - 1] - 1) / ((m - 1) * (m - 2))
        else:  # three of U_m (m = 3: the top three themselves)
            q[k] = count[m] * (count[m] - 1) * (count[m] - 2) / (m * (m - 1) * (m - 2))
    with np.errstate(divide="ignore"):
        missed = np.cumsum(np.log1p(-q))
    reached = np.flatnonzero(missed <= np.log1p(-confidence))
    return float(reached[0] + 1) if reached.size else np.inf


def test_non_random_minimum_is_the_binomial_definition_and_its_normal_approximation():
    # The paper: I_min = min{j : P(m + Binomial(n - m, beta) >= j) < psi}.
    for n in (20, 50, 100, 200, 500):
        j = int(non_random_minimum(n, 0.05, 0.05))
        assert binom.sf(j - 3 - 1, n - 3, 0.05) < 0.05  # P(at least j - 3 chance agreements) < psi
        assert binom.sf(j - 1 - 3 - 1, n - 3, 0.05) >= 0.05  # and j is the smallest such
    # The normal approximation: m + (n - m) beta + 1.645 sqrt((n - m) beta (1 - beta)); n = 100: 11.38.
    approx = non_random_minimum(100, 0.05, 0.05, exact=False)
    assert approx == pytest.approx(3 + 97 * 0.05 + 1.6449 * np.sqrt(97 * 0.0475), abs=1e-3)


def test_prefix_draws_edge_cases():
    k = prefix_draws(np.array([2, 20, 10, 50]), np.array([20, 20, 100, 500]), 0.05)
    assert k[0] == np.inf  # fewer than 3 inliers: never certain
    assert k[1] == 1  # all inliers: one draw
    q = 10 * 9 * 8 / (100 * 99 * 98)
    assert k[2] == pytest.approx(np.log(0.05) / np.log1p(-q))


def test_termination_lowers_the_sampler_to_n_star():
    frame, order = perfect_order_frame(epsilon=0.7)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    options = EstimatorOptions(
        noise_sigma=frame.noise_sigma, batch_size=1, first_batch_size=1, refine=False, polish_iterations=2, local_refit=True
    )
    components = method_spec("prosac").build(problem, options, None, order, {})
    report = run_ransac(problem, components, np.random.default_rng(0))
    stop = components.termination
    assert isinstance(stop, ProsacTermination)
    n_inliers = int(frame.truth.inlier.sum())
    assert stop.n_star is not None and components.sampler.n_max == stop.n_star
    # n* stays inside the top-ranked inliers (plus at most a few gate-passing outliers), far below N.
    assert 20 <= stop.n_star <= n_inliers + 5
    assert report.n_hypotheses == stop.stop_at == int(np.ceil(stop.k_stop)) <= 5  # every draw in U_n*


def test_no_inlier_fraction_guard_a_small_perfect_top_stops_at_once():
    sampler = ProsacSampler(np.arange(500))
    stop = ProsacTermination(sampler, min_n=20)
    inliers = np.zeros(500, dtype=bool)
    inliers[:2] = True  # two "inliers" cannot make a non-random consensus: no prefix is admissible
    stop.on_new_best(inliers, None)
    assert stop.n_star is None and sampler.n_max == 500 and stop.required(2, 500) == stop.max_iterations
    inliers[:10] = True  # 2 % inliers, all on top: 10 of the top 20 is far from chance (no 0.2 N guard)
    stop.on_new_best(inliers, None)
    assert stop.n_star == 20 and stop.required(10, 500) == int(np.ceil(prefix_draws(10, 20, 0.01)))
    inliers[:50] = True  # 10 % inliers, all on top (eps 0.9): n* = 50, one draw suffices
    stop.on_new_best(inliers, None)
    assert stop.n_star == 50 and stop.required(50, 500) == 1 and sampler.n_max == 50
    inliers = np.zeros(500, dtype=bool)
    inliers[::6] = True  # 84 inliers spread evenly: ties and near-ties go to the largest prefix
    stop.on_new_best(inliers, None)
    support = np.cumsum(inliers)
    n = np.arange(1, 501)
    k = np.where((n >= 20) & (support >= non_random_minimum(n, 0.05, 0.05)), prefix_draws(support, n, 0.01), np.inf)
    assert stop.n_star == int(n[np.flatnonzero(k == k.min())[-1]])
    assert stop.counters()["prosac_n_star"] == stop.n_star


@pytest.mark.parametrize("epsilon", [0.5, 0.8, 0.9])
def test_perfect_ordering_needs_a_handful_of_hypotheses_at_any_contamination(epsilon):
    """Inliers first (shuffled among themselves), N = 500: median <= 5 hypotheses, every frame right.

    With the sample polish and local refit: a raw closed-form 3-point fit on triangulated points
    explains only a few per cent of the inliers under the reprojection gate, so the support that
    PROSAC's maximality reads would be a small fraction of the true one."""
    draws, right = [], []
    for seed in range(6):
        frame = simulate_frame(SimulationConfig(n_correspondences=500, outlier_ratio=epsilon), seed)
        g = np.random.default_rng(seed)
        order = np.r_[g.permutation(np.flatnonzero(frame.truth.inlier)), g.permutation(np.flatnonzero(~frame.truth.inlier))]
        est = estimate_motion(
            frame.prev, frame.curr, frame.camera, method="prosac", order=order, rng=seed, noise_sigma=frame.noise_sigma,
            batch_size=1, first_batch_size=1, polish_iterations=2, local_refit=True,
        )
        draws.append(est.n_hypotheses)
        right.append(est.ok and np.degrees(rotation_error(est.rotation, frame.truth.rotation)) < 1.0)
    assert np.median(draws) <= 5, draws
    assert all(right)


@pytest.mark.parametrize("epsilon", [0.5, 0.8])
def test_on_a_random_ordering_the_rule_picks_a_prefix_richer_than_the_whole(epsilon):
    """Why a random ordering does not make PROSAC's stop RANSAC's: n* minimises k_n over every
    non-random prefix (Chum & Matas 2005), and on a random ordering some prefix holds a larger share
    of inliers than the whole set by chance. Told the true consensus (400 orderings, N 500), the rule
    picks prefixes whose inlier share is 0.58 (eps 0.5) and 0.26 (eps 0.8) on average and asks for
    0.70 and 0.59 of RANSAC's draws."""
    ratio, share_at_n_star, share = random_ordering_rule(epsilon)
    print(f"eps {epsilon}: k_n*/k_N {ratio:.3f}, inlier share at n* {share_at_n_star:.3f} (overall {share:.2f})")
    assert share_at_n_star > share + 0.05
    assert 0.5 < ratio < 0.8, ratio


def test_random_ordering_succeeds_as_ransac_does_and_misses_at_most_one_minus_confidence():
    """Random orderings, eps 0.5, N 500, random mismatches only (one structure), 200 frames, the
    enhancements the perfect-ordering test uses. PROSAC is right on every frame RANSAC is right on;
    the runs that stop without ever drawing an all-inlier sample are within 1 - confidence (one-sided
    binomial test at the 0.1 % level); the mean hypotheses (0.80 of RANSAC's) are below RANSAC's + 10 %
    and not below the rule's own prediction on the true consensus (0.70, the test above) less 0.05."""
    config = SimulationConfig(n_correspondences=500, outlier_ratio=0.5, outlier_mix=(1, 0, 0))
    draws = {"ransac": [], "prosac": []}
    right = {"ransac": [], "prosac": []}
    misses = 0
    for seed in range(200):
        frame = simulate_frame(config, 10_000 + seed)
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
        options = EstimatorOptions(noise_sigma=frame.noise_sigma, polish_iterations=2, local_refit=True)
        order = np.random.default_rng(seed).permutation(500)
        for name in draws:
            components = method_spec(name).build(problem, options, None, order if name == "prosac" else None, {})
            sampler, hit = components.sampler, [False]
            draw = sampler.draw

            def recording(batch, rng, draw=draw, hit=hit):
                samples = draw(batch, rng)
                hit[0] = hit[0] or bool(np.any(np.all(frame.truth.inlier[samples], axis=1)))
                return samples

            sampler.draw = recording
            report = run_ransac(problem, components, np.random.default_rng(seed))
            draws[name].append(report.n_hypotheses)
            error = np.degrees(rotation_error(report.rotation, frame.truth.rotation))
            right[name].append(report.status == "ok" and error < 1)
            misses += name == "prosac" and not hit[0]
    assert all(r for r, s in zip(right["prosac"], right["ransac"]) if s) and np.mean(right["ransac"]) > 0.99
    assert binom.sf(misses - 1, 200, 0.01) > 1e-3, misses
    ratio = np.mean(draws["prosac"]) / np.mean(draws["ransac"])
    print(f"random ordering: PROSAC/RANSAC mean hypotheses {ratio:.3f}, {misses} of 200 PROSAC runs missed")
    predicted = random_ordering_rule(0.5)[0]
    assert predicted - 0.05 <= ratio <= 1.1, (ratio, predicted)


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


def test_prosac_schedule_stop_is_the_product_over_its_draws():
    """A PROSAC sampler's stop is the first T at which the chance that none of draws 1..T was
    all-inlier falls to 1 - p, over its schedule (random, perfect and reversed orderings, a lowered
    n_max); AdaptiveTermination stops there, and its q is the per-draw chance needing as many."""
    g = np.random.default_rng(4)
    for trial in range(24):
        n = int(g.integers(6, 200))
        inliers = g.random(n) > g.uniform(0.1, 0.9)
        inliers[g.choice(n, 3, replace=False)] = True
        kind = trial % 3
        order = g.permutation(n)
        if kind:  # inliers first (perfect) or last (adversarial)
            first = np.flatnonzero(inliers if kind == 1 else ~inliers)
            order = np.r_[g.permutation(first), g.permutation(np.setdiff1d(np.arange(n), first))]
        sampler = ProsacSampler(order, t_n=float(g.choice([20, 2_000, 200_000])))  # 20: the stop past T'_N
        if trial % 4 == 3:
            sampler.n_max = int(g.integers(3, n + 1))
        confidence = float(g.choice([0.5, 0.9, 0.99]))
        expected = schedule_by_hand(sampler, inliers, confidence)
        got = sampler.required_draws(inliers, confidence)
        assert got == expected or (expected == np.inf and got > 60_000), (trial, got, expected)
        stop = AdaptiveTermination(confidence, 10_000, sampler=sampler)
        assert stop.required(int(inliers.sum()), n) == 10_000  # no best yet: keep drawing
        stop.on_new_best(inliers, None)
        assert stop.required(int(inliers.sum()), n) == min(got, 10_000) and stop.probability.updates == 1
        if got < np.inf:
            assert (1 - stop.probability.q) ** got == pytest.approx(1 - confidence, rel=1e-9)
    for rule in (SprtTermination(SprtVerification(sampler.n), 0.9, sampler=sampler),
                 TddTermination(0.9, verifier=TddVerification(), sampler=sampler)):
        rule.on_new_best(inliers, None)  # the early-rejection stops take the schedule's per-draw q too
        assert rule.probability.scheduled and rule.probability.draws == sampler.required_draws(inliers, 0.9)
    # reached at the first draw of a segment whose q is below 1: u_5 an inlier after one outlier on top
    first_draw = ProsacSampler(np.arange(12), t_n=12)
    mask = np.arange(12) > 0
    assert first_draw.required_draws(mask, 0.5) == schedule_by_hand(first_draw, mask, 0.5)
    # reached one draw past T'_N: draws 1-4 (anchored, T'_n = 1, 2, 3, 4) miss with 1, 2/3, 1/2 and
    # 2/5, 0.133 > 0.1; draw 5, three of U_6 (q = 1/2), brings it to 0.067
    past_schedule = ProsacSampler(np.arange(6), t_n=1)
    mask = np.array([True, True, False, True, True, True])
    assert list(past_schedule.growth[3:]) == [1, 2, 3, 4]
    assert past_schedule.required_draws(mask, 0.9) == 5.0 == schedule_by_hand(past_schedule, mask, 0.9, draws=10)
    perfect = ProsacSampler(np.arange(50))
    assert perfect.required_draws(np.arange(50) < 10, 0.99) == 1.0  # the first draw is the top three
    hopeless = AdaptiveTermination(0.99, 500, sampler=ProsacSampler(np.arange(50)))
    for _ in range(2):
        hopeless.on_new_best(np.arange(50) < 2, None)  # no all-inlier triple exists
    assert hopeless.probability.draws == np.inf and hopeless.probability.q == 0.0 and hopeless.probability.updates == 2
    assert hopeless.required(2, 50) == 500


@pytest.mark.slow
def test_prosac_order_stop_is_calibrated_for_any_ordering():
    """The calibration test for a PROSAC ordering with the adaptive stop (``ransac`` given order=):
    told the true consensus, its draws miss every all-inlier sample in at most 1 - confidence of the
    runs (and about that often: the bound is tight), whether the ordering is random, by match score
    or adversarial (outliers first); a stationary bound on the next draw's q would stop at once or never."""
    allowed = 1.0 - CALIBRATION_CONFIDENCE
    options = EstimatorOptions(confidence=CALIBRATION_CONFIDENCE, max_iterations=1_000_000)
    for kind in ("random", "score", "adversarial"):
        misses = 0
        frames = calibration_frames()
        for seed, (frame, problem) in enumerate(frames):
            truth = frame.truth.inlier
            order = {"random": np.random.default_rng(seed).permutation(40), "score": np.argsort(-frame.scores),
                     "adversarial": np.argsort(truth, kind="stable")}[kind]
            components = method_spec("ransac").build(problem, options, None, order, {})
            stop = components.termination
            stop.on_new_best(truth, None)
            k = stop.required(int(truth.sum()), 40)
            assert k < options.max_iterations
            samples = components.sampler.draw(k, np.random.default_rng(seed))
            misses += not bool(np.any(np.all(truth[samples], axis=1)))
        assert binom.sf(misses - 1, len(frames), allowed) > 1e-3, (kind, misses)
        assert binom.cdf(misses, len(frames), allowed) > 1e-3, (kind, misses)


def test_ransac_with_a_prosac_order_stops_by_its_schedule_not_at_the_cap():
    """N 500: a perfect ordering stops after a median of one or two hypotheses, every frame right; a
    random one at eps 0.8 stops near RANSAC's count (median within 1.5x) and never at the cap (the
    next draw's q, 0 whenever its u_n is an outlier, kept such runs going to max_iterations)."""
    config = SimulationConfig(n_correspondences=500, outlier_ratio=0.8, outlier_mix=(1.0, 0.0, 0.0))
    perfect, random_order, uniform = [], [], []
    for seed in range(10):
        frame = simulate_frame(config, 900 + seed)
        g = np.random.default_rng(seed)
        inl = frame.truth.inlier
        orders = {"perfect": np.r_[g.permutation(np.flatnonzero(inl)), g.permutation(np.flatnonzero(~inl))],
                  "random": g.permutation(500), "uniform": None}
        for kind, rows in (("perfect", perfect), ("random", random_order), ("uniform", uniform)):
            est = estimate_motion(frame.prev, frame.curr, frame.camera, method="ransac", order=orders[kind], rng=seed,
                                  noise_sigma=frame.noise_sigma, polish_iterations=2, local_refit=True,
                                  batch_size=1 if kind == "perfect" else 32, first_batch_size=1 if kind == "perfect" else 8)
            right = est.ok and np.degrees(rotation_error(est.rotation, frame.truth.rotation)) < 1.0
            rows.append((est.n_hypotheses, right))
    assert np.median([h for h, _ in perfect]) <= 2 and all(r for _, r in perfect), perfect
    assert max(h for h, _ in random_order) < 10_000, random_order
    assert np.median([h for h, _ in random_order]) <= 1.5 * np.median([h for h, _ in uniform]), (random_order, uniform)
    assert sum(r for _, r in random_order) >= sum(r for _, r in uniform) - 1


def test_prosac_method_options_reach_its_sampler_and_its_stop_and_order_is_required():
    from stereovo.estimation.registry import validate_options
    from stereovo.estimation.roles.samplers import prosac_growth

    frame, order = perfect_order_frame(epsilon=0.5)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    given = {"prosac_t_n": 5000.0, "prosac_beta": 0.07, "prosac_psi": 0.02, "prosac_min_n": 31}
    options, extra = validate_options("prosac", {"noise_sigma": frame.noise_sigma, "max_iterations": 777, **given})
    components = method_spec("prosac").build(problem, options, None, order, extra)
    stop, sampler = components.termination, components.sampler
    assert isinstance(stop, ProsacTermination) and stop.sampler is sampler
    np.testing.assert_array_equal(sampler.growth, prosac_growth(problem.n, 3, 5000.0))
    assert (stop.beta, stop.psi, stop.min_n, stop.max_iterations) == (0.07, 0.02, 31, 777)
    assert stop.confidence == options.confidence
    # under a fixed budget the stop still listens (it lowers n_max to n*), and the budget ends the search
    options, extra = validate_options("prosac", {"noise_sigma": frame.noise_sigma, "budget": 12})
    budgeted = method_spec("prosac").build(problem, options, None, order, extra)
    assert not isinstance(budgeted.termination, ProsacTermination)
    assert [type(x) for x in budgeted.listeners if isinstance(x, ProsacTermination)] == [ProsacTermination]
    with pytest.raises(ValueError, match="method 'prosac' needs order="):
        method_spec("prosac").build(problem, options, None, None, extra)
