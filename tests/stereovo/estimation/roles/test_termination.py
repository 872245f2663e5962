"""Stopping rules (stereovo/estimation/roles/termination.py) against numbers worked out by hand, and the
prior-aware stop of a guided sampler calibrated on simulated frames.

Every expected value is a literal, or arithmetic on literals written here from the papers' formulas
(Schoenberger, Larsson & Pollefeys 2025 for drawing without replacement)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import binom

from stereovo import estimate_motion
from stereovo.estimation.estimator_options import EstimatorOptions
from stereovo.estimation.registry import method_spec
from stereovo.estimation.roles.samplers import UniformSampler, WeightedSampler
from stereovo.estimation.methods.sprt import SprtTermination, SprtVerification
from stereovo.estimation.methods.tdd import TddTermination
from stereovo.estimation.roles.termination import (
    AdaptiveTermination,
    FixedBudget,
    all_inlier_probability,
    iterations_for,
    required_iterations,
)
from stereovo.geometry import rotation_error
from stereovo.simulation import SimulationConfig, simulate_frame
from tests.support.stopping import CALIBRATION_CONFIDENCE, calibration_frames


def calibration_misses(kind: str, wrong_q: str | None = None) -> tuple[int, int, float]:
    """Runs that stop without ever having drawn an all-inlier sample: ``(misses, runs, mean draws)``.

    Over :func:`calibration_frames`; the priors are the match scores (informative), constant
    (uninformative) or one minus half the scores (adversarial: outliers favoured, every weight in
    [0.5, 1]). Each run builds the library's components (``method_spec("ransac")``: the guided
    sampler and the prior-aware stop), tells the stop that the best consensus is the true inlier set
    and draws exactly the bound's number of samples with that sampler. That is the bound's claim:
    given the consensus I, k(q_I) draws of *this* sampler miss every all-inlier sample at most
    1 - confidence of the time. In the loop itself a run can stop only once its best consensus is
    large, which (without a local refit) takes an all-inlier sample first, so the loop's miss count
    is 0 whatever q is: a count that cannot fail.

    ``wrong_q``: a deliberately wrong stop, to show that the count catches one: ``"uniform"`` (the
    count formula, blind to the priors) or ``"doubled"`` (the sampler's q times 2).
    """
    options = EstimatorOptions(confidence=CALIBRATION_CONFIDENCE, max_iterations=1_000_000)
    frames = calibration_frames()
    misses = draws = 0
    for seed, (frame, problem) in enumerate(frames):
        priors = {"informative": frame.scores, "uninformative": np.ones(40), "adversarial": 1.0 - 0.5 * frame.scores}
        components = method_spec("ransac").build(problem, options, priors[kind], None, {})
        stop, truth = components.termination, frame.truth.inlier
        stop.on_new_best(truth, None)
        count = int(truth.sum())
        k = stop.required(count, 40)
        if wrong_q == "uniform":
            k = required_iterations(count, 40, CALIBRATION_CONFIDENCE, options.max_iterations)
        elif wrong_q == "doubled":
            k = iterations_for(min(2 * stop.probability.q, 1.0), CALIBRATION_CONFIDENCE, options.max_iterations)
        assert k < options.max_iterations  # the bound, not the cap, ends the run
        samples = components.sampler.draw(k, np.random.default_rng(seed))
        misses += not bool(np.any(np.all(truth[samples], axis=1)))
        draws += k
    return misses, len(frames), draws / len(frames)


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


def test_uniform_weights_give_the_uniform_bound_exactly():
    inliers = np.zeros(200, bool)
    inliers[::3] = True
    I = int(inliers.sum())
    exact = float(all_inlier_probability(I, 200))
    assert UniformSampler(200).all_inlier_probability(inliers) == exact
    assert WeightedSampler(np.full(200, 0.37)).all_inlier_probability(inliers) == exact
    # zero weights are never drawn: the uniform formula over the positive-weight rows
    w = np.r_[np.zeros(20), np.ones(180)]
    assert WeightedSampler(w).all_inlier_probability(inliers) == float(
        all_inlier_probability(int(inliers[20:].sum()), 180)
    )
    # the termination with a uniform sampler is today's bound, call for call
    stop = AdaptiveTermination(sampler=UniformSampler(200))
    stop.on_new_best(inliers, None)
    for count in (0, 3, 10, 67, 150, 200):
        assert stop.required(count, 200) == required_iterations(count, 200)


def test_guided_termination_follows_the_samplers_q():
    inliers = np.r_[np.ones(20, bool), np.zeros(80, bool)]
    for w_in, w_out in ((5.0, 1.0), (1.0, 2.0)):
        sampler = WeightedSampler(np.r_[np.full(20, w_in), np.full(80, w_out)])
        stop = AdaptiveTermination(sampler=sampler)
        assert stop.required(20, 100) == stop.max_iterations  # no best yet: keep drawing
        stop.on_new_best(inliers, None)
        q = sampler.all_inlier_probability(inliers)
        assert stop.required(20, 100) == min(int(np.ceil(np.log(0.01) / np.log1p(-q))), stop.max_iterations)
        uniform = required_iterations(20, 100)
        assert (stop.required(20, 100) < uniform) == (w_in > w_out)
        assert stop.counters() == {"stop_guided": 1, "stop_q": q}


@pytest.mark.slow
def test_calibration_stops_without_an_all_inlier_sample_at_most_one_minus_confidence():
    """Informative, uninformative and adversarial priors: the fraction of runs that stop without an
    all-inlier sample is at most 1 - confidence (one-sided binomial test at the 0.1 % level), and it is
    seen (the bound is tight: about 1 - confidence of the runs do miss). A wrong q fails the same test:
    the uniform count formula under adversarial priors, or the sampler's q doubled."""
    allowed = 1.0 - CALIBRATION_CONFIDENCE
    for kind in ("informative", "uninformative", "adversarial"):
        misses, runs, mean_draws = calibration_misses(kind)
        assert binom.sf(misses - 1, runs, allowed) > 1e-3, (kind, misses, runs)  # not above 1 - confidence
        assert binom.cdf(misses, runs, allowed) > 1e-3, (kind, misses, runs)  # nor far below it: the bound is tight
        print(f"{kind}: {misses} of {runs} runs stopped without an all-inlier sample ({mean_draws:.0f} draws each)")
    for kind, wrong_q in (("adversarial", "uniform"), ("informative", "doubled")):
        misses, runs, _ = calibration_misses(kind, wrong_q)
        assert binom.sf(misses - 1, runs, allowed) < 1e-3, (kind, wrong_q, misses, runs)
        print(f"{kind} with the {wrong_q} q: {misses} of {runs} runs missed")


def test_guided_ransac_draws_fewer_hypotheses_with_informative_priors():
    """eps 0.8, match scores of AUC 0.9 as priors: the prior-aware stop needs at most half the uniform
    draws, at equal success (with the enhancements the baseline grid runs)."""
    config = SimulationConfig(n_correspondences=500, outlier_ratio=0.8, score_auc=0.9)
    enhanced = {"polish_iterations": 2, "local_refit": True, "refine": True}
    draws = {"uniform": [], "guided": []}
    right = {"uniform": 0, "guided": 0}
    for seed in range(8):
        frame = simulate_frame(config, 700 + seed)
        for name, priors in (("uniform", None), ("guided", frame.scores)):
            est = estimate_motion(frame.prev, frame.curr, frame.camera, method="ransac", priors=priors, rng=seed,
                                  noise_sigma=frame.noise_sigma, **enhanced)
            draws[name].append(est.n_hypotheses)
            right[name] += est.ok and np.degrees(rotation_error(est.rotation, frame.truth.rotation)) < 1.0
    assert np.mean(draws["guided"]) <= 0.5 * np.mean(draws["uniform"]), draws
    assert right["guided"] >= right["uniform"] - 1, right


def test_required_iterations_without_replacement():
    # docs/algorithms.md, `ransac`: N = 20, I = 6, p = 0.99 gives 261 (the w^3 bound would give 169).
    assert required_iterations(6, 20, 0.99) == 261
    assert required_iterations(2, 20, 0.99, max_iterations=10_000) == 10_000
    assert required_iterations(20, 20, 0.99) == 1
    # arrays of counts give the bounds elementwise
    np.testing.assert_array_equal(required_iterations(np.array([[6, 2], [20, 6]]), 20, 0.99), [[261, 10_000], [1, 261]])


def test_the_compiled_bound_is_the_formula_at_every_scale():
    """``required_iterations`` runs the compiled bound (shared with the compiled search); against the
    formula in Python's floats and exact integer ``ceil``, with numpy's ``q`` of draws without
    replacement: equal for counts, sizes, sample sizes, confidences and caps from the edges to where
    the bound no longer fits an int64 (``1 - 1e-15`` at N 1e6)."""
    rng = np.random.default_rng(4)
    cases = [(0, 3), (2, 3), (3, 3), (3, 4), (7, 500), (50, 500), (499, 500), (500, 500), (3, 1_000_000),
             (20, 10_000)] + [(int(c), int(n)) for n in rng.integers(3, 5000, 60) for c in rng.integers(0, n + 1, 2)]
    for count, n in cases:
        for sample_size in (1, 3, 4):
            for confidence in (0.5, 0.99, 0.999999, 1 - 1e-15):
                for cap in (7, 10_000, 10**9, 2**62):
                    q = float(all_inlier_probability(count, n, sample_size))
                    want = cap if q <= 0 else 1 if q >= 1 else min(max(math.ceil(math.log1p(-confidence) /
                                                                                 math.log1p(-q)), 1), cap)
                    assert required_iterations(count, n, confidence, cap, sample_size) == want, (count, n, cap)
