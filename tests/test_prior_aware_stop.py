"""Prior-aware adaptive stopping (issue 14 item 4): q is the chance that one draw *of the sampler in
use* is all-inlier given the best model's inliers; and priors of any scale (issue 16)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.stats import binom

from stereovo import estimate_motion
from stereovo.estimation.loop import run_ransac
from stereovo.estimation.methods import EstimatorOptions, method_spec
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.samplers import ProsacSampler, UniformSampler, WeightedSampler, normalised_weights
from stereovo.estimation.termination import AdaptiveTermination, all_inlier_probability, required_iterations
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


class RecordingSampler:
    """A weighted sampler that remembers whether it ever drew an all-inlier sample (truth known)."""

    def __init__(self, priors: np.ndarray, truth: np.ndarray) -> None:
        self.inner = WeightedSampler(priors)
        self.n = self.inner.n
        self.truth = truth
        self.hit = False

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        samples = self.inner.draw(batch, rng)
        self.hit = self.hit or bool(np.any(np.all(self.truth[samples], axis=1)))
        return samples

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        return self.inner.all_inlier_probability(inliers)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["informative", "uninformative", "adversarial"])
def test_calibration_stops_without_an_all_inlier_sample_at_most_one_in_a_hundred(kind):
    """1000 seeded frames at eps 0.8 (N 40, 8 inliers), the real loop: a run that stops by the bound
    without ever having drawn an all-inlier sample happens at most 1 - confidence of the time.

    Low pixel noise and a 1 px gate, so that the minimal fit of an all-inlier sample explains the
    inliers (the bound is about drawing such a sample). Batches of up to 64 draws: the last one may
    run past the bound by a few per cent of the draws, which the loop really does."""
    weights = {"informative": (3.0, 1.0), "uninformative": (1.0, 1.0), "adversarial": (1.0, 1.5)}[kind]
    config = SimulationConfig(n_correspondences=40, outlier_ratio=0.8, noise_sigma=0.02, outlier_mix=(1, 0, 0))
    options = EstimatorOptions(noise_sigma=0.02, threshold_px=1.0, max_iterations=1_000_000, batch_size=64,
                               least_squares_refit=False)
    misses = stops = 0
    for seed in range(1000):
        frame = simulate_frame(config, 5000 + seed)
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, 0.02)
        priors = np.where(frame.truth.inlier, *weights)
        components = method_spec("ransac").build(problem, options, priors, None, {})
        sampler = RecordingSampler(priors, frame.truth.inlier)
        components.sampler = sampler
        components.termination.probability.sampler = sampler  # record the very draws the bound is about
        report = run_ransac(problem, components, np.random.default_rng(seed))
        stops += 1
        misses += not sampler.hit
        assert report.n_hypotheses < options.max_iterations
    # P(misses >= observed | p = 0.01) must not be tiny: one-sided binomial test at the 0.1 % level
    assert binom.sf(misses - 1, stops, 0.01) > 1e-3, (kind, misses)
    print(f"{kind}: {misses} of {stops} runs stopped without an all-inlier sample")


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
    from agents.evaluation import KIND_AGENT_ADAPTIVE, EvalConfig, resolve_agents, run_evaluation

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
