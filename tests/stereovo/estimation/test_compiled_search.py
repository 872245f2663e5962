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
from tests.support.estimates import assert_same_estimate


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
    assert_same_estimate(compiled, loop)
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


def _components(problem, **changes):
    """``probabilistic``'s components for ``problem`` with some roles changed."""
    import dataclasses

    from stereovo.estimation import method_spec
    from stereovo.estimation.registry import split_options

    spec = method_spec("probabilistic")
    options, extra = split_options(spec, {"noise_sigma": problem.noise_sigma})
    return dataclasses.replace(spec.build(problem, options, None, None, extra), **changes)


def _search_state(search):
    return (search.best_R.tolist(), search.best_t.tolist(), search.best_inliers.tolist(), search.best_inliers.dtype,
            search.best_score, search.found_at, search.drawn, search.scored, search.checks, search.degenerate,
            search.rejected, search.local_runs, search.runner_up_runs, search.runner_up_wins, search.next_size,
            search.required, search.done)


def _run_both(monkeypatch, problem, components_of, seed, steps_first=0):
    """The search's state and report after the compiled search and after the loop's steps (each on
    fresh components from ``components_of()``), optionally after ``steps_first`` loop steps."""
    from stereovo.estimation.loop import RansacSearch

    out = []
    for compiled in (True, False):
        monkeypatch.setattr(compiled_search, "COMPILED_BATCHES", compiled)
        rng = np.random.default_rng(seed)
        search = RansacSearch(problem, components_of(), rng)
        for _ in range(steps_first):
            search.step()
        compiled_search.compiled_batch_search(search)
        while not search.done:
            search.step()
        report = search.finish()
        out.append((_search_state(search), report.counters, report.status, rng.bit_generator.state))
    return out


def _problem(n, eps, seed, outliers="hostile"):
    from stereovo.estimation import StereoProblem

    frame = _frame(n, eps, seed, outliers)
    return StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)


def test_a_search_stepped_by_the_loop_first_continues_as_the_loop(monkeypatch):
    """The runner takes a search wherever it stands: its counts, best model and the refit's counters
    carry on from the loop's."""
    for seed in range(3):
        problem = _problem(300, 0.9, 60 + seed)
        compiled, loop = _run_both(monkeypatch, problem, lambda: _components(problem), seed, steps_first=3)
        assert compiled == loop
        assert compiled[0][3] == np.bool_  # the best model's inliers stay a mask


@pytest.mark.parametrize("change", ["huber", "min_iterations", "no runner-up", "budget"])
def test_roles_set_otherwise_than_the_recipe_are_the_loops(monkeypatch, change):
    from stereovo.estimation.roles.local_optimization import ConsensusRefit
    from stereovo.estimation.roles.refinement import ReprojectionRefiner
    from stereovo.estimation.roles.termination import AdaptiveTermination, FixedBudget

    # min_iterations above the bound of eps 0.5; no runner-up where many hypotheses tie with the best
    n, eps, outliers = {"min_iterations": (200, 0.5, "default"), "no runner-up": (40, 0.0, "default")}.get(
        change, (300, 0.9, "hostile"))
    for seed in range(3):
        problem = _problem(n, eps, 80 + seed, outliers)

        def components_of():
            if change == "huber":
                refit = ConsensusRefit(refiner=ReprojectionRefiner(iterations=3, rounds=2, huber_px=1.0))
                return _components(problem, local_optimizer=refit)
            if change == "min_iterations":
                return _components(problem, termination=AdaptiveTermination(0.99, 10_000, min_iterations=700))
            if change == "budget":
                return _components(problem, termination=FixedBudget(300), first_batch_size=None)
            # a refit that cannot raise the count (no LM step), so that hypotheses tie with the best
            still = ConsensusRefit(refiner=ReprojectionRefiner(iterations=0, rounds=1))
            return _components(problem, runner_up_fraction=None, termination=FixedBudget(200), first_batch_size=None,
                               batch_size=8, local_optimizer=still)

        compiled, loop = _run_both(monkeypatch, problem, components_of, seed)
        assert compiled == loop
        if change == "min_iterations":
            assert compiled[0][6] == 700  # the bound of the best's support is below 700
        if change == "no runner-up":
            # no runner-up refit: every refit is a new best's
            assert compiled[0][12] == 0 and compiled[1]["refit_runs"] == compiled[0][11]
            monkeypatch.setattr(compiled_search, "COMPILED_BATCHES", False)
            ties = _components(problem, runner_up_fraction=1.0, termination=FixedBudget(200), first_batch_size=None,
                               batch_size=8, local_optimizer=ConsensusRefit(refiner=ReprojectionRefiner(iterations=0,
                                                                                                        rounds=1)))
            from stereovo.estimation.loop import run_ransac

            assert run_ransac(problem, ties, np.random.default_rng(seed)).counters["runner_up_refits"] > 0


def test_the_kernel_covers_exactly_the_recipes_roles():
    """``batch_search_applies`` takes the recipe and declines each role it does not reproduce."""
    from stereovo.estimation.roles.local_optimization import ConsensusRefit
    from stereovo.estimation.roles.refinement import ReprojectionRefiner
    from stereovo.estimation.roles.samplers import WeightedSampler
    from stereovo.estimation.roles.scoring import PixelMahalanobisResidual, ReprojectionResidual, TruncatedQuadratic
    from stereovo.estimation.roles.termination import AdaptiveTermination

    problem = _problem(200, 0.5, 3)
    applies = compiled_search.batch_search_applies
    assert applies(_components(problem))
    assert applies(_components(problem, threshold_sq=0.5, local_optimizer=None, runner_up_fraction=None,
                               sample_check=None))
    gated = ConsensusRefit(refiner=ReprojectionRefiner(iterations=3, rounds=2, gate=(PixelMahalanobisResidual(), 11.3)))
    declined = [
        dict(sampler=WeightedSampler(np.ones(problem.n))),
        dict(sample_check=object()),
        dict(verifier=object()),
        dict(residual_model=ReprojectionResidual(9.0)),
        dict(quality=TruncatedQuadratic()),
        dict(threshold_sq=0.0),
        dict(local_optimizer=gated),
        dict(local_optimizer=object()),
        dict(termination=AdaptiveTermination(0.99, 10_000, sampler=WeightedSampler(np.ones(problem.n)))),
        dict(termination=object()),
        dict(listeners=[object()]),
    ]
    for change in declined:
        assert not applies(_components(problem, **change)), change
