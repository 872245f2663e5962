"""Prior-aware adaptive stopping (issue 14 item 4): q is the chance that one draw *of the sampler in
use* is all-inlier given the best model's inliers; and priors of any scale (issue 16)."""

from __future__ import annotations

import functools
import itertools

import numpy as np
import pytest
from scipy.stats import binom

from stereovo import estimate_motion
from stereovo.estimation.estimator_options import EstimatorOptions
from stereovo.estimation.registry import method_spec
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.samplers import (
    ProsacSampler,
    UniformSampler,
    WeightedSampler,
    normalised_weights,
)
from stereovo.estimation.methods.sprt import SprtTermination, SprtVerification
from stereovo.estimation.methods.tdd import TddTermination, TddVerification
from stereovo.estimation.roles.termination import (
    AdaptiveTermination,
    all_inlier_probability,
    iterations_for,
    required_iterations,
)
from stereovo.geometry import rotation_error
from stereovo.simulation import SimulationConfig, simulate_frame


def brute_force_q(w: np.ndarray, inliers: np.ndarray) -> float:
    """The defining sum over ordered distinct triples in I, O(|I|^3)."""
    w = w / w.sum()
    q = 0.0
    for a, b, c in itertools.permutations(np.flatnonzero(inliers), 3):
        q += w[a] * w[b] / (1 - w[a]) * w[c] / (1 - w[a] - w[b])
    return q


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
    assert 0.0 <= q <= 1.0
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method="ransac", priors=priors, rng=0,
                          noise_sigma=frame.noise_sigma)
    assert est.status == "ok" or est.status.startswith("failed")


def test_complex_priors_are_refused_naming_priors():
    frame = simulate_frame(SimulationConfig(n_correspondences=30, outlier_ratio=0.3), 3)
    with pytest.raises(ValueError, match="priors"):
        estimate_motion(frame.prev, frame.curr, frame.camera, method="ransac", priors=np.ones(30) + 1j, rng=0)
    with pytest.raises(ValueError, match="priors"):
        WeightedSampler(np.ones(30, dtype=complex))


CALIBRATION_CONFIDENCE = 0.9  # misses allowed in one run of ten: frequent enough to count in 1000 runs


@functools.cache
def calibration_frames(frames: int = 1000) -> tuple:
    """1000 seeded frames at eps 0.8 (N 40, 8 inliers) with their problems, simulated once."""
    config = SimulationConfig(n_correspondences=40, outlier_ratio=0.8)
    out = []
    for seed in range(frames):
        frame = simulate_frame(config, 5000 + seed)
        out.append((frame, StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)))
    return tuple(out)


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


def test_evaluate_runs_agents_adaptively_beside_the_classical_adaptive_rows():
    from agents.evaluation.run import run_evaluation
    from agents.evaluation.setup import KIND_AGENT_ADAPTIVE, EvalConfig, resolve_agents

    config = EvalConfig(episodes=1, frames_per_episode=3, epsilons=(0.7,), budgets=(16,), budget=16,
                        sweep_epsilon=0.7, n=200, methods=("prosac",), max_iterations=500, adaptive_agents=True)
    result = run_evaluation(config, resolve_agents(["match-score"]), workers=1, progress=False)
    adaptive = [r for r in result.rows if r["method"] == "match-score (adaptive)"]
    fixed = [r for r in result.rows if r["method"] == "match-score"]
    assert len(adaptive) == len(fixed) == 3 * 1  # the fixed-budget setting only (sweep eps = eps)
    assert all(r["kind"] == KIND_AGENT_ADAPTIVE and r["budget"] == 16 for r in adaptive)
    assert all(r["n_hypotheses"] == 16 for r in fixed)
    assert all(1 <= r["n_hypotheses"] <= 500 for r in adaptive) and any(r["n_hypotheses"] != 16 for r in adaptive)
    table = result.summary["budget_sweep"]["adaptive"]
    assert {"prosac (adaptive)", "match-score (adaptive)"} <= set(table)
    with pytest.raises(ValueError, match="adaptive_agents"):
        EvalConfig(adaptive_agents=1)
