"""BANSAC's compiled search (stereovo/estimation/kernels/bansac_runner.py) against the shared loop's
steps, the reference it replaces: the same estimates, counters, beliefs
and generator state, bit for bit, on fixed seeds (with and without priors, eps 0.2 / 0.5 / 0.8, the
hostile preset, frames that fail, the cap reached, the options it covers), and its pieces
against the functions they reproduce."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stereovo.estimation import StereoProblem, estimate_motion, method_spec
from stereovo.estimation.kernels import bansac_runner
from stereovo.estimation.kernels import beliefs as belief_kernels
from stereovo.estimation.methods import bansac
from stereovo.estimation.registry import split_options
from stereovo.simulation import SimulationConfig, simulate_frame
from tests.support.estimates import assert_same_estimate


def _priors(frame, seed):
    noise = np.random.default_rng(100 + seed).normal(0, 0.3, frame.n)
    return np.where(frame.truth.inlier, 0.8, 0.3) * np.exp(noise)


SEARCHES = {"bansac": (bansac, "compiled_bansac_search"), "p-bansac": (bansac, "compiled_bansac_search")}


def _estimate(monkeypatch, frame, method, priors, seed, compiled, **options):
    """``estimate_motion`` by the method's compiled search or the loop; also whether the search ran
    compiled, and the generator and the sampler's beliefs afterwards."""
    module, name = SEARCHES[method]
    monkeypatch.setattr(module, "COMPILED_SEARCH", compiled)
    ran, samplers = [], []
    search, judged = getattr(module, name), module.judged_components

    def spy(s):
        ran.append(module.compiled_search_applies(s.components))
        search(s)

    def built(problem, options, priors, order, sampler):
        samplers.append(sampler)
        return judged(problem, options, priors, order, sampler)

    monkeypatch.setattr(module, name, spy)
    monkeypatch.setattr(module, "judged_components", built)
    rng = np.random.default_rng(seed)
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, priors=priors, rng=rng,
                          noise_sigma=frame.noise_sigma, **options)
    beliefs = None
    if samplers:
        beliefs = getattr(samplers[0], "log_odds", None)
        beliefs = getattr(samplers[0], "beliefs", None) if beliefs is None else beliefs
    return est, any(ran), rng.bit_generator.state, beliefs


def _assert_same(monkeypatch, frame, method, priors, seed, **options):
    compiled, ran, compiled_rng, compiled_beliefs = _estimate(monkeypatch, frame, method, priors, seed, True, **options)
    loop, ran_loop, loop_rng, loop_beliefs = _estimate(monkeypatch, frame, method, priors, seed, False, **options)
    assert not ran_loop
    assert_same_estimate(compiled, loop)
    assert compiled_rng == loop_rng  # the generator ends where the loop leaves it
    if compiled_beliefs is not None:
        np.testing.assert_array_equal(compiled_beliefs, loop_beliefs)
    return compiled, ran


@pytest.mark.parametrize("method", ["bansac", "p-bansac"])
@pytest.mark.parametrize("eps", [0.2, 0.5, 0.8])
def test_compiled_search_gives_the_loops_estimates_on_fixed_seeds(monkeypatch, method, eps):
    config = SimulationConfig(n_correspondences=300, outlier_ratio=eps)
    for seed in range(6):
        frame = simulate_frame(config, rng=seed)
        priors = _priors(frame, seed) if seed % 2 == 0 else None
        est, ran = _assert_same(monkeypatch, frame, method, priors, seed)
        assert ran and est.n_hypotheses > 0


@pytest.mark.parametrize("method", ["bansac", "p-bansac"])
def test_compiled_search_gives_the_loops_estimates_on_the_hostile_preset(monkeypatch, method):
    config = SimulationConfig(n_correspondences=400, outliers="hostile")
    for seed in range(5):
        frame = simulate_frame(config, rng=seed)
        _, ran = _assert_same(monkeypatch, frame, method, _priors(frame, seed) if seed % 2 else None, seed)
        assert ran


@pytest.mark.parametrize("options", [
    {"rigidity_gate_probability": 0.999},  # samples rejected before the fit
    {"polish_iterations": 2},
    {"runner_up_refit": 0.5, "local_refit": True},  # the runner-up refit: steps handed back that are not new bests
    {"bansac_weights": "belief"},
    {"initial_probability": 0.3, "prior_ceiling": 0.9},
    {"refine": True},  # (local_refit=False is refused: the method refits every new best anyway)
    {"confidence": 0.999, "bansac_threshold": 0.05},
])
def test_compiled_search_covers_the_options_of_the_papers_update(monkeypatch, options):
    config = SimulationConfig(n_correspondences=300, outlier_ratio=0.5)
    estimates = []
    for seed in range(4):
        frame = simulate_frame(config, rng=seed)
        est, ran = _assert_same(monkeypatch, frame, "bansac", _priors(frame, seed) if seed % 2 else None, seed,
                                **options)
        assert ran
        estimates.append(est)
    if "runner_up_refit" in options:  # the path was taken
        assert sum(est.counters["runner_up_refits"] for est in estimates) > 0
    if "rigidity_gate_probability" in options:
        assert sum(est.report.n_rejected_samples for est in estimates) > 0


@pytest.mark.parametrize("method", ["bansac"])
def test_compiled_search_reaches_the_cap_as_the_loop_does(monkeypatch, method):
    frame = simulate_frame(SimulationConfig(n_correspondences=300, outlier_ratio=0.8), rng=3)
    for cap in (1, 2, 7, 40):
        est, ran = _assert_same(monkeypatch, frame, method, None, 3, max_iterations=cap)
        assert ran and est.n_hypotheses == cap
    assert est.status.startswith("failed: no confident consensus")


@pytest.mark.parametrize("method", ["bansac"])
def test_compiled_search_fails_as_the_loop_does(monkeypatch, method):
    frame = simulate_frame(SimulationConfig(n_correspondences=120, outlier_ratio=0.3), rng=1)
    # every row an outlier: each row's k match taken from another row
    scrambled = frame.__class__(**{**vars(frame), "curr": np.roll(frame.curr, 7, axis=0)})
    for seed in range(3):
        est, ran = _assert_same(monkeypatch, scrambled, method, None, seed)
        assert ran
    # few usable rows: the others have no disparity (no depth)
    curr = frame.curr.copy()
    curr[10:, 2] = curr[10:, 0]
    few = frame.__class__(**{**vars(frame), "curr": curr})
    est, ran = _assert_same(monkeypatch, few, method, None, 0)
    assert ran and est.unusable.sum() == frame.n - 10
    curr[4:, 2] = curr[4:, 0]
    too_few = frame.__class__(**{**vars(frame), "curr": curr})
    est, ran = _assert_same(monkeypatch, too_few, method, None, 0)
    assert not ran and est.status.startswith("failed: too few usable")


@pytest.mark.parametrize("options", [{"bansac_batch": 16}, {"bansac_update": "verdict-likelihood"}, {"budget": 50}])
def test_other_variants_keep_the_loop(monkeypatch, options):
    frame = simulate_frame(SimulationConfig(n_correspondences=200, outlier_ratio=0.5), rng=0)
    _, ran, _, _ = _estimate(monkeypatch, frame, "bansac", None, 0, True, **options)
    assert not ran


def test_compiled_search_declines_components_it_does_not_reproduce():
    frame = simulate_frame(SimulationConfig(n_correspondences=100, outlier_ratio=0.5), rng=0)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    spec = method_spec("bansac")
    shared, extra = split_options(spec, {"noise_sigma": frame.noise_sigma})
    components = spec.build(problem, shared, None, None, extra)
    assert components.search_runner is bansac.compiled_bansac_search
    assert bansac.compiled_search_applies(components)
    components.listeners = [object()]
    assert not bansac.compiled_search_applies(components)
    components = spec.build(problem, shared, None, None, extra)
    components.sampler = bansac.BansacSampler(problem.n)  # not the termination's sampler
    assert not bansac.compiled_search_applies(components)


def test_update_scalars_round_as_python_does():
    for n in (3, 7, 100, 333, 500, 2048):
        for k in range(n + 1):
            c = min(bansac.classification_parameter(k / n), bansac.C_MAX)
            log_c, log_1mc = math.log(c), math.log1p(-c)
            expected = (log_c, bansac.LOG_GATED_IN + log_1mc, bansac.LOG_GATED_OUT + log_1mc, log_1mc - log_c)
            got = bansac_runner.update_scalars(k, n, bansac.TABLE_KNEE, bansac.C_MAX, bansac.LOG_GATED_IN,
                                               bansac.LOG_GATED_OUT)
            assert got == expected, (n, k)


def test_weights_found_from_the_previous_level_are_the_draw_arrays_weights():
    rng = np.random.default_rng(4)
    levels = float(bansac.WEIGHT_LEVELS)
    edges = bansac_runner.level_edges(levels)
    # log-odds spread over every level, and some on (and a rounding step either side of) each edge
    on_edges = edges[1:-1]
    log_odds = np.concatenate([rng.normal(0, 3, 3000), on_edges, np.nextafter(on_edges, np.inf),
                               np.nextafter(on_edges, -np.inf), [-50.0, 50.0, 0.0]])
    level = np.ones(log_odds.size, dtype=np.int64)
    lower, upper = np.full(log_odds.size, np.inf), np.full(log_odds.size, -np.inf)
    shifted = log_odds
    for step in range(12):
        # small moves (most points keep their weight's interval) and large ones
        shifted = np.ascontiguousarray(shifted + rng.normal(0, (0.01, 0.5)[step % 2] if step else 0.0, log_odds.size))
        if step == 7:
            shifted[-len(on_edges):] = on_edges  # back onto the edges, from inside a known interval
        expected = belief_kernels.bansac_draw_arrays(shifted, True, levels, bansac.WEIGHT_FLOOR)
        got = bansac_runner.discretised_draw_arrays(shifted, level, lower, upper, edges, levels)
        for a, b in zip(got, expected):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(level, expected[0].astype(np.int64))


def test_compiled_exact_redraw_is_the_samplers_fix_up():
    rng = np.random.default_rng(9)
    for _ in range(300):
        n = int(rng.integers(3, 40))
        weights = rng.integers(0, 4, n).astype(float)
        weights[rng.choice(n, 3, replace=False)] += 1.0  # at least three drawable points
        w = weights / weights.sum()
        u = rng.random(3)
        u[rng.random(3) < 0.2] = 0.999999999999  # the top edge
        out = np.empty(3, dtype=np.int64)
        bansac_runner.exact_weighted_redraw(w, u, out)
        np.testing.assert_array_equal(out, bansac.exact_weighted_draw(w, u))


