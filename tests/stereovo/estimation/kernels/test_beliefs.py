"""The compiled BANSAC and ARS samplers against their numpy formulation (tests/support/belief_samplers.py):
the same draws, beliefs and estimates, bit for bit, on fixed seeds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tests.support.belief_samplers import ReferenceArsSampler, ReferenceBansacSampler, reference_logistic

from stereovo.estimation.methods import ars, bansac
from stereovo.estimation import estimate_motion
from stereovo.estimation.methods.ars import ArsSampler, baysac_failure_update
from stereovo.estimation.methods.bansac import BansacSampler, log_odds_update
from stereovo.estimation.kernels import beliefs as belief_kernels
from stereovo.estimation.loop import LoopState
from stereovo.simulation import SimulationConfig, simulate_frame


def test_compiled_logaddexp_update_and_logistic_equal_numpys_bit_for_bit():
    rng = np.random.default_rng(3)
    log_odds = np.concatenate([rng.normal(0, 5, 2000), [0.0, -800.0, 800.0, 1e-300]])
    verdicts = rng.random(log_odds.size) < 0.4
    for r in (0.0, 0.1, 0.5, 0.7143, 0.95, 1.0):
        expected = log_odds_update(log_odds, verdicts, r)
        got = log_odds.copy()
        c = min(bansac.classification_parameter(r), bansac.C_MAX)
        log_c, log_1mc = math.log(c), math.log1p(-c)
        gated = belief_kernels.bansac_log_odds_update(
            got, verdicts, log_c, bansac.LOG_GATED_IN + log_1mc, bansac.LOG_GATED_OUT + log_1mc, log_1mc - log_c)
        assert gated == np.count_nonzero(verdicts)
        np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(belief_kernels.logistic_beliefs(log_odds), reference_logistic(log_odds))


def test_compiled_baysac_draw_equals_the_numpy_update():
    p = np.random.default_rng(0).uniform(0.05, 0.95, 40)
    compiled, reference = ArsSampler(40, p), ReferenceArsSampler(40, p)
    a, b = np.random.default_rng(1), np.random.default_rng(1)
    for batch in (1, 5, 60, 200):  # 200 > the 56 candidate triples: the fallback to the best tried one
        np.testing.assert_array_equal(compiled.draw(batch, a), reference.draw(batch, b))
        np.testing.assert_array_equal(compiled.beliefs, reference.beliefs)
    assert compiled.counters() == reference.counters()
    single = np.array([0.3, 0.9, 0.6, 0.5])
    table = np.full(16, belief_kernels.EMPTY, dtype=np.int64)
    got = single.copy()
    samples, codes, before, added = belief_kernels.ars_draw(got, np.arange(4), ars.CANDIDATE_TRIPLES, table, 4, 1,
                                                            bansac.BELIEF_FLOOR)
    assert added == 1 and samples[0].tolist() == [1, 2, 3]  # the three most probable, best first
    np.testing.assert_array_equal(got, baysac_failure_update(single, samples[0]))
    np.testing.assert_array_equal(before[0], single[[1, 2, 3]])
    # 0.9 * 0.6 * 0.5 = 0.27 fails: each of the three falls, the fourth point keeps 0.3
    assert got[0] == 0.3 and np.all(got[1:] < single[1:])


def test_ars_tried_table_grows_and_keeps_every_code():
    sampler, reference = ArsSampler(30), ReferenceArsSampler(30)
    a, b = np.random.default_rng(5), np.random.default_rng(5)
    for _ in range(12):  # 12 x 200 draws: the table of 1024 slots doubles twice
        np.testing.assert_array_equal(sampler.draw(200, a), reference.draw(200, b))
        state = LoopState(0, 0.0, samples=np.zeros((0, 3), dtype=np.int64))
        sampler.on_hypotheses(None, None, np.zeros((0, 30), dtype=bool), None, state)
        reference.on_hypotheses(None, None, np.zeros((0, 30), dtype=bool), None, state)
    assert sampler.counters() == reference.counters()
    assert sampler.counters()["ars_tried"] > 512


def _frames():
    out = []
    for n, eps, seed in ((60, 0.5, 0), (200, 0.7, 1), (500, 0.5, 2), (120, 0.3, 3)):
        config = SimulationConfig(n_correspondences=n, outlier_ratio=eps, noise_sigma=0.5)
        out.append(simulate_frame(config, np.random.default_rng(seed)))
    return out


def _estimate(frame, method, priors, seed, **extra):
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, priors=priors, rng=seed,
                          noise_sigma=frame.noise_sigma, **extra)
    return est.rotation, est.translation, est.inliers, est.n_hypotheses, est.status, dict(est.counters)


CASES = [
    ("bansac", {}), ("p-bansac", {}), ("bansac", {"bansac_weights": "belief"}), ("bansac", {"bansac_batch": 16}),
    ("ars", {}),
]


@pytest.mark.parametrize("method, extra", CASES)
def test_compiled_samplers_give_todays_estimates_on_fixed_seeds(monkeypatch, method, extra):
    frames = _frames()
    runs = []
    for i, frame in enumerate(frames):
        priors = None if i % 2 else np.where(frame.truth.inlier, 0.8, 0.3)
        runs.append(_estimate(frame, method, priors, 10 + i, **extra))
    monkeypatch.setattr(bansac, "BansacSampler", ReferenceBansacSampler)
    monkeypatch.setattr(ars, "ArsSampler", ReferenceArsSampler)
    for i, (frame, compiled) in enumerate(zip(frames, runs)):
        priors = None if i % 2 else np.where(frame.truth.inlier, 0.8, 0.3)
        reference = _estimate(frame, method, priors, 10 + i, **extra)
        for got, want in zip(compiled[:3], reference[:3]):
            np.testing.assert_array_equal(got, want)
        assert compiled[3:] == reference[3:]
        assert compiled[3] > 1  # the search ran: many draws, each one updating the beliefs


def test_bansac_sampler_caches_its_weights_until_the_next_update():
    sampler = BansacSampler(10, np.linspace(0.1, 0.9, 10))
    w = sampler.sampling_weights
    assert sampler.sampling_weights is w
    np.testing.assert_array_equal(w, np.maximum(np.ceil(100 * sampler.beliefs), 1.0))
    sampler.apply(np.arange(10) > 4)
    assert sampler.sampling_weights is not w
    assert np.all(sampler.sampling_weights[5:] > w[5:]) and np.all(sampler.sampling_weights[:5] <= w[:5])


def test_discretised_weights_take_the_exact_ceiling_at_every_rounding_edge():
    k = np.arange(1, 100) / 100
    edges = np.log(k) - np.log1p(-k)  # the log-odds whose belief is k / 100: the ceiling's edges
    log_odds = np.concatenate([edges, np.nextafter(edges, -np.inf), np.nextafter(edges, np.inf),
                               np.linspace(-60, 60, 5001), [-40.0, 40.0, -36.8, 36.8]])
    beliefs = reference_logistic(log_odds)
    for discretised, expected in ((True, np.maximum(np.ceil(100 * beliefs), 1.0)), (False, np.maximum(beliefs, 1e-12))):
        weights, w, cdf, before = belief_kernels.bansac_draw_arrays(log_odds, discretised, 100.0, 1e-12)
        np.testing.assert_array_equal(weights, expected)
        np.testing.assert_array_equal(w, expected / np.sum(expected))
        np.testing.assert_array_equal(cdf, np.cumsum(w))
        np.testing.assert_array_equal(before, np.concatenate([[0.0], cdf[:-1]]))


def test_numpy_sum_is_numpys_pairwise_sum():
    rng = np.random.default_rng(2)
    for n in (0, 1, 7, 8, 9, 127, 128, 129, 500, 1000, 4099):
        a = rng.random(n) * 10.0 ** rng.integers(-8, 8, n)
        assert belief_kernels.numpy_sum(a) == np.sum(a)
