"""vo_gym.features: the logarithm columns (log-depths, log-variance, prediction residual), computed with
their arguments in one compiled pass and numpy's log over three rows at once, are the column-wise numpy
formulation's, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation import StereoProblem
from stereovo.estimation.roles.reprojection import reprojection_sq
from stereovo.simulation import SimulationConfig, simulate_frame
from vo_gym.features import FEATURE_BOUND, compute_features


def _numpy_log_columns(problem, curr, camera, noise_sigma, motion):
    """Columns 8 to 12 as numpy computed them column by column before they were compiled, clipped."""
    n = problem.points_prev.shape[0]
    out = np.zeros((n, 5), dtype=np.float32)
    with np.errstate(over="ignore", invalid="ignore"):
        out[:, 0] = np.log(problem.points_prev[:, 2] / 10.0)
        out[:, 1] = np.log(problem.points_curr[:, 2] / 10.0)
        out[:, 2] = 0.5 * np.log(np.maximum(problem.cov_prev[:, 2, 2], 1e-300))
        if motion is not None:
            sq = reprojection_sq(camera, motion[0][None], motion[1][None], problem.points_prev, curr)[0]
            out[:, 3] = np.log1p(np.sqrt(sq / 4.0) / noise_sigma)
            out[:, 4] = 1.0
    return np.clip(out, -FEATURE_BOUND, FEATURE_BOUND)


def test_numpys_log_of_stacked_rows_is_its_log_of_each_row():
    rng = np.random.default_rng(0)
    for _ in range(3000):
        n = int(rng.integers(1, 700))
        rows = np.exp(rng.uniform(-30, 30, (3, n)))
        rows[rng.random((3, n)) < 0.01] = rng.choice([0.0, 1.0, 1e-300, np.inf, np.nan])
        with np.errstate(divide="ignore", invalid="ignore"):
            want = np.stack([np.log(row.copy()) for row in rows])
            got = np.log(rows, out=rows)
        assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("outliers", ["default", "hostile"])
def test_log_columns_are_the_column_wise_numpy_formulation(outliers):
    for seed in range(24):
        config = SimulationConfig(n_correspondences=(500, 120, 37)[seed % 3], outlier_ratio=0.3 + 0.1 * (seed % 6),
                                  outliers=outliers)
        frame = simulate_frame(config, rng=seed)
        motion = None if seed % 4 == 0 else (frame.truth.rotation, frame.truth.translation * (1.0 + 0.3 * (seed % 3)))
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, 0.5)
        got = compute_features(frame.prev, frame.curr, frame.scores, frame.camera, 0.5, motion, problem=problem)
        want = _numpy_log_columns(problem, frame.curr, frame.camera, 0.5, motion)
        usable = np.ones(frame.n, bool) if problem.usable is None else problem.usable  # the others are flagged
        assert got[usable, 8:13].tobytes() == want[usable].tobytes()
