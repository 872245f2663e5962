"""The consensus refit (stereovo/estimation/roles/local_optimization.py)."""

import numpy as np

from stereovo.estimation.problem import StereoProblem
from stereovo.geometry import se3_exp


def test_local_refit_scores_its_result_as_a_fresh_scoring_would():
    from stereovo.estimation.roles.local_optimization import ConsensusRefit
    from stereovo.estimation.roles.scoring import ReprojectionResidual, TruncatedQuadratic
    from stereovo.estimation.roles.verification import ScoringContext
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=300, outlier_ratio=0.4), np.random.default_rng(6))
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    ctx = ScoringContext(problem, ReprojectionResidual(), TruncatedQuadratic(), 9.0)
    R0, t0 = frame.truth.rotation @ se3_exp(np.full(6, 3e-4))[0], frame.truth.translation + 0.002
    score0, inliers0 = ctx.score_and_inliers(R0[None], t0[None])
    R, t, inliers, score, checks = ConsensusRefit().improve(ctx, R0, t0, inliers0[0], float(score0[0]), None)
    fresh_score, fresh_inliers = ctx.score_and_inliers(R[None], t[None])
    assert score == float(fresh_score[0]) and score > score0[0]
    np.testing.assert_array_equal(inliers, fresh_inliers[0])
    assert checks == problem.n * ConsensusRefit().refiner.rounds
