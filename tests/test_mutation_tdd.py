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
