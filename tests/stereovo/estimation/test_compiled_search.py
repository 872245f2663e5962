"""The compiled search of ``probabilistic`` (stereovo/estimation/compiled_search.py and
kernels/batch_search.py) against the loop's own steps, the reference they replace: the same
estimates, counts, counters and generator state, bit for bit, on fixed seeds (default mix and
hostile preset, eps 0.2 to 0.9, the options the kernel covers, frames that fail), and the searches
it must leave to the loop."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation import estimate_motion
from stereovo.estimation import compiled_search
from stereovo.estimation.kernels import batch_search as kernel
from stereovo.simulation import SimulationConfig, simulate_frame

REPORT_FIELDS = ("score", "status", "n_hypotheses", "n_scored", "n_point_checks", "n_degenerate",
                 "n_local_optimizations", "best_found_at", "n_rejected_samples", "counters")


def _frame(n, eps, seed, outliers="default", **config):
    return simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=eps, outliers=outliers, **config),
                          np.random.default_rng(seed))


def _estimate(monkeypatch, frame, seed, compiled, **kwargs):
    """``estimate_motion`` with the compiled batches on or off; also how many searches the kernel
    took over and the generator's state afterwards."""
    monkeypatch.setattr(compiled_search, "COMPILED_BATCHES", compiled)
    searches = set()
    batches = kernel.batch_search

    def spy(u, state, *args):
        searches.add(id(state))  # one state array a search
        return batches(u, state, *args)

    monkeypatch.setattr(kernel, "batch_search", spy)
    rng = np.random.default_rng(seed)
    est = estimate_motion(frame.prev, frame.curr, frame.camera, rng=rng, noise_sigma=frame.noise_sigma, **kwargs)
    return est, len(searches), rng.bit_generator.state


def _assert_same(monkeypatch, frame, seed, **kwargs):
    compiled, ran, compiled_rng = _estimate(monkeypatch, frame, seed, True, **kwargs)
    loop, ran_loop, loop_rng = _estimate(monkeypatch, frame, seed, False, **kwargs)
    assert ran_loop == 0
    np.testing.assert_array_equal(compiled.rotation, loop.rotation)
    np.testing.assert_array_equal(compiled.translation, loop.translation)
    np.testing.assert_array_equal(compiled.inliers, loop.inliers)
    for name in ("status", "n_hypotheses", "n_scored", "n_point_checks", "score", "counters"):
        assert getattr(compiled, name) == getattr(loop, name), name
    assert (compiled.report is None) == (loop.report is None)
    if compiled.report is not None:
        for name in REPORT_FIELDS:
            assert getattr(compiled.report, name) == getattr(loop.report, name), name
    assert compiled_rng == loop_rng  # the generator ends where the loop leaves it
    return compiled, ran


@pytest.mark.parametrize("outliers,n,eps", [
    ("default", 200, 0.2), ("default", 500, 0.5), ("default", 300, 0.8), ("default", 200, 0.9),
    ("hostile", 500, 0.8), ("hostile", 300, 0.9), ("hostile", 200, 0.9),
])
def test_the_compiled_batches_are_the_loops_steps(monkeypatch, outliers, n, eps):
    taken = 0
    for seed in range(4):
        est, ran = _assert_same(monkeypatch, _frame(n, eps, 10 * seed + n, outliers), seed)
        taken += ran
        assert est.status == "ok"
    assert taken == 4  # every search the kernel covers, short ones included


def test_runner_up_refits_and_their_wins_are_the_loops(monkeypatch):
    """Runner-up refits that lose and that win both run on these frames, and count as the loop counts them."""
    refits = wins = 0
    for seed in range(6):
        est, ran = _assert_same(monkeypatch, _frame(200, 0.9, 700 + seed, "hostile"), seed)
        assert ran == 1
        refits += est.counters["runner_up_refits"]
        wins += est.counters["runner_up_wins"]
    assert refits > wins > 0


@pytest.mark.parametrize("options", [
    dict(rigidity_gate_probability=None),
    dict(runner_up_refit=None),
    dict(local_refit=False, runner_up_refit=None),
    dict(polish_iterations=0),
    dict(batch_size=8, first_batch_size=2),
    dict(confidence=0.999),
    dict(budget=400),
    dict(max_iterations=300),  # the cap before the stop: failures at the cap
    dict(refine=False),
])
def test_each_covered_option_is_the_loops(monkeypatch, options):
    taken = 0
    for seed in range(2):
        _, ran = _assert_same(monkeypatch, _frame(300, 0.9, 900 + seed, "hostile"), seed, **options)
        taken += ran
    assert taken == 2


def test_frames_that_fail_are_the_loops(monkeypatch):
    statuses = set()
    for seed in range(3):
        frame = _frame(300, 0.995, 40 + seed, outlier_mix={"random": 1.0})  # one or two inliers, random outliers
        est, _ = _assert_same(monkeypatch, frame, seed, max_iterations=2000)
        statuses.add(est.status.split(":")[0])
    assert "failed" in statuses


@pytest.mark.parametrize("count,n", [(0, 3), (2, 3), (3, 3), (3, 4), (7, 500), (50, 500), (499, 500), (500, 500),
                                     (3, 1_000_000), (20, 10_000)])
@pytest.mark.parametrize("confidence", [0.5, 0.99, 0.999999, 1 - 1e-15])
def test_the_kernels_bound_is_the_terminations(count, n, confidence):
    """:func:`required_draws` gives what the loop's termination gives, at every scale (no int64 overflow
    where the bound is astronomic) and for a fixed budget."""
    from stereovo.estimation.roles.termination import AdaptiveTermination, FixedBudget

    for max_iterations, min_iterations in ((10_000, 1), (10**9, 1), (10_000, 50), (7, 7)):
        term = AdaptiveTermination(confidence, max_iterations, min_iterations)
        assert kernel.required_draws(float(count), n, confidence, max_iterations, min_iterations, 0) == \
            term.required(count, n)
    assert kernel.required_draws(float(count), n, confidence, 64, 1, 64) == FixedBudget(64).required(count, n)


def test_searches_the_kernel_does_not_cover_stay_with_the_loop(monkeypatch):
    frame = _frame(300, 0.9, 5, "hostile")
    priors = np.where(frame.truth.inlier, 0.8, 0.3)
    order = np.argsort(-frame.scores, kind="stable")
    for kwargs in (dict(priors=priors), dict(order=order), dict(method="probabilistic+sprt"),
                   dict(method="bansac"), dict(method="ransac")):
        _, ran, _ = _estimate(monkeypatch, frame, 0, True, **kwargs)
        assert ran == 0, kwargs
