"""PROSAC's termination (ALGORITHMS.md section 3): non-randomness, maximality, n* and the guards."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from stereovo import estimate_motion
from stereovo.estimation.loop import run_ransac
from stereovo.estimation.methods import EstimatorOptions, method_spec
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.prosac import ProsacTermination, non_random_minimum, prefix_draws
from stereovo.estimation.samplers import ProsacSampler
from stereovo.geometry import rotation_error
from stereovo.simulation import SimulationConfig, simulate_frame


def test_non_random_minimum_is_the_normal_approximation_of_the_binomial_tail():
    # I_min = m + (n - m) beta + 1.645 sqrt((n - m) beta (1 - beta)); n = 100, beta = 0.05: 11.38.
    assert non_random_minimum(100, 0.05, 0.05) == pytest.approx(3 + 97 * 0.05 + 1.6449 * np.sqrt(97 * 0.0475), abs=1e-3)
    # The binomial tail beyond it is close to psi for moderate n.
    for n in (50, 200, 500):
        j = int(np.ceil(non_random_minimum(n, 0.05, 0.05)))
        tail = binom.sf(j - 3 - 1, n - 3, 0.05)  # P(at least j - 3 chance agreements)
        assert tail < 0.1


def test_prefix_draws_edge_cases():
    k = prefix_draws(np.array([2, 20, 10, 50]), np.array([20, 20, 100, 500]), 0.05)
    assert k[0] == np.inf  # fewer than 3 inliers: never certain
    assert k[1] == 1  # all inliers: one draw
    q = 10 * 9 * 8 / (100 * 99 * 98)
    assert k[2] == pytest.approx(np.log(0.05) / np.log1p(-q))


def perfect_order_frame(n=300, epsilon=0.5, seed=7):
    frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=epsilon), seed)
    order = np.argsort(~frame.truth.inlier, kind="stable")  # every inlier first
    return frame, order


def test_perfect_ordering_succeeds_within_a_handful_of_hypotheses():
    frame, order = perfect_order_frame(epsilon=0.7)
    est = estimate_motion(
        frame.prev, frame.curr, frame.camera, method="prosac", order=order, batch_size=1, rng=0,
        noise_sigma=frame.noise_sigma,
    )
    assert est.ok
    assert np.degrees(rotation_error(est.rotation, frame.truth.rotation)) < 1.0
    assert est.n_hypotheses <= 5, est.n_hypotheses
    # The same frame with a random order needs RANSAC's many draws.
    shuffled = estimate_motion(
        frame.prev, frame.curr, frame.camera, method="prosac", order=np.random.default_rng(1).permutation(300),
        batch_size=1, rng=0, noise_sigma=frame.noise_sigma,
    )
    assert shuffled.n_hypotheses > 20 * est.n_hypotheses


def test_termination_lowers_the_sampler_to_n_star():
    frame, order = perfect_order_frame(epsilon=0.7)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    options = EstimatorOptions(noise_sigma=frame.noise_sigma, batch_size=1, refine=False)
    components = method_spec("prosac").build(problem, options, None, order, {})
    report = run_ransac(problem, components, np.random.default_rng(0))
    stop = components.termination
    assert isinstance(stop, ProsacTermination)
    n_inliers = int(frame.truth.inlier.sum())
    assert stop.n_star is not None and components.sampler.n_max == stop.n_star
    # n* stays inside the top-ranked inliers (plus at most a few gate-passing outliers), far below N.
    assert 20 <= stop.n_star <= n_inliers + 5
    assert report.n_hypotheses == int(np.ceil(stop.k_stop)) <= 5


def test_guards_no_stop_before_min_n_and_full_set_exempt_from_fraction_guard():
    sampler = ProsacSampler(np.arange(200))
    stop = ProsacTermination(sampler, min_n=20, min_inlier_fraction=0.2)
    inliers = np.zeros(200, dtype=bool)
    inliers[:10] = True  # a perfect but tiny top: n < 20 and 10 < 0.2 N are both refused
    stop.on_new_best(inliers, None)
    assert stop.n_star is None and sampler.n_max == 200 and stop.required(10, 200) == stop.max_iterations
    inliers = np.zeros(200, dtype=bool)
    inliers[::6] = True  # 34 inliers spread evenly: only U_N passes, with RANSAC's own bound
    stop.on_new_best(inliers, None)
    assert stop.n_star == 200
    assert stop.required(34, 200) == int(np.ceil(prefix_draws(34, 200, 0.01)))


def test_prosac_samples_respect_n_max():
    sampler = ProsacSampler(np.arange(300))
    sampler.draw(50, np.random.default_rng(0))
    sampler.n_max = 40
    later = sampler.draw(5000, np.random.default_rng(1))
    assert later.max() < 40
