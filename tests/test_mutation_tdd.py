"""T(d,d)'s verifier by hand, for the survivors of the mutmut run of ``stereovo/estimation/tdd.py``
(docs/mutation-testing.md): the numpy route (taken for residual models other than the reprojection one,
whose compiled route test_classical_verification checks), point by point.
"""

from __future__ import annotations

import numpy as np
import pytest

import stereovo.estimation.tdd as tdd_module
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.scoring import InlierCount, ReprojectionResidual
from stereovo.estimation.tdd import TddVerification, random_points_excluding
from stereovo.estimation.verification import ScoringContext
from stereovo.geometry import random_rotation
from stereovo.simulation import SimulationConfig, simulate_frame


class _OtherResidual:
    """Stands in for ReprojectionResidual in the tdd module's type test: the numpy route is taken."""


def test_tdd_pretest_on_the_numpy_route_by_hand(monkeypatch):
    # d = 2 and no best model yet (nothing to measure): each hypothesis is checked on d random points outside
    # its sample (random_points_excluding with the verifier's generator), in order, stopping at its first miss;
    # it passes when all d are consistent and is then scored on all N points, its d checks counted once. Two
    # batches: the counters add up.
    monkeypatch.setattr(tdd_module, "ReprojectionResidual", _OtherResidual)
    frame = simulate_frame(SimulationConfig(n_correspondences=150, outlier_ratio=0.3), 4)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    ctx = ScoringContext(problem, ReprojectionResidual(9.0), InlierCount(), 9.0)
    rng = np.random.default_rng(8)
    verifier = TddVerification(d=2, adaptive=False)
    for batch, seed in enumerate((1, 2), start=1):
        R = np.stack([random_rotation(rng, np.radians(0.3)) @ frame.truth.rotation for _ in range(30)])
        t = frame.truth.translation + rng.normal(0, 0.03, (30, 3))
        samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(30)])
        sq = ctx.residuals(R, t)
        idx = random_points_excluding(samples, problem.n, 2, np.random.default_rng(seed))
        consistent = np.take_along_axis(sq, idx, axis=1) < 9.0
        passed = consistent.all(axis=1)
        assert 3 <= passed.sum() <= 27 and (~consistent[:, 0]).any() and (consistent[:, 0] & ~consistent[:, 1]).any()
        first_miss = np.where(~consistent[:, 0], 1, 2)
        scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(seed), samples=samples)
        np.testing.assert_array_equal(np.isinf(scores), ~passed)
        np.testing.assert_array_equal(scores[passed], np.sum(sq[passed] < 9.0, axis=1))
        assert checks == first_miss[~passed].sum() + passed.sum() * problem.n
        # a passed hypothesis' inliers come from the residuals just computed; a failed one's are computed
        for k, fresh in ((np.flatnonzero(passed)[0], False), (np.flatnonzero(~passed)[0], True)):
            mask, computed = ctx.inliers_of(R, t, k)
            np.testing.assert_array_equal(mask, sq[k] < 9.0)
            assert computed is fresh
        c = verifier.counters()
        assert c["tdd_tested"] == 30 * batch
        if batch == 1:
            passed_before = int(passed.sum())
            assert c["tdd_passed"] == passed_before
        else:
            assert c["tdd_passed"] == passed_before + int(passed.sum())


def _two_point_chance(c, m):
    """The chance that 2 distinct points drawn from m, c of them consistent, are both consistent."""
    c, m = np.asarray(c, float), np.asarray(m, float)
    return np.maximum(c, 0) * np.maximum(c - 1, 0) / (np.maximum(m, 1) * np.maximum(m - 1, 1))


def test_tdd_measures_good_hypotheses_pass_chance_on_the_numpy_route_by_hand(monkeypatch):
    # With a best model, hypotheses drawn from its inliers are good: a good one that passed has its exact pass
    # chance from its full support (its own 3 points left out of the N - 3), a good one that failed is measured
    # on measure_points more random points outside its sample (the same generator, after the pre-test's), which
    # the checks count. alpha is the mean of those chances.
    monkeypatch.setattr(tdd_module, "ReprojectionResidual", _OtherResidual)
    frame = simulate_frame(SimulationConfig(n_correspondences=150, outlier_ratio=0.3), 4)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    ctx = ScoringContext(problem, ReprojectionResidual(9.0), InlierCount(), 9.0)
    n, rng = problem.n, np.random.default_rng(9)
    verifier = TddVerification(d=2, measure_points=20, adaptive=False)
    verifier.on_new_best(frame.truth.inlier, None)
    R = np.stack([random_rotation(rng, np.radians(0.1)) @ frame.truth.rotation for _ in range(30)])
    t = frame.truth.translation + rng.normal(0, 0.01, (30, 3))
    samples = np.stack([rng.choice(np.flatnonzero(frame.truth.inlier), 3, replace=False) for _ in range(30)])
    mask = ctx.residuals(R, t) < 9.0
    g = np.random.default_rng(4)
    consistent = np.take_along_axis(mask, random_points_excluding(samples, n, 2, g), axis=1)
    passed = consistent.all(axis=1)
    failed = np.flatnonzero(~passed)
    assert 3 <= passed.sum() <= 27
    measured = np.take_along_axis(mask[failed], random_points_excluding(samples[failed], n, 20, g), axis=1).sum(axis=1)
    own = np.take_along_axis(mask, samples, axis=1).sum(axis=1)
    chances = np.concatenate([_two_point_chance(mask[passed].sum(axis=1) - own[passed], n - 3),
                              _two_point_chance(measured, 20)])
    scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(4), samples=samples)
    first_miss = np.where(~consistent[:, 0], 1, 2)
    assert checks == first_miss[failed].sum() + passed.sum() * n + failed.size * 20
    c = verifier.counters()
    assert c["tdd_good_measured"] == 30 and c["tdd_alpha"] == pytest.approx(np.mean(chances), rel=1e-12)
    assert (c["tdd_measure_checks"], c["tdd_failed"], c["tdd_on"], c["tdd_off"]) == (failed.size * 20, failed.size, 30, 0)
