"""The qualities' and residual models' contracts that the mutmut run of
``stereovo/estimation/roles/scoring.py`` found untested (docs/mutation-testing.md).

RANSAC counts the residuals strictly under the gate (Fischler & Bolles 1981), MSAC sums the
truncated squares normalised by the gate (Torr & Zisserman, "MLESAC: a new robust estimator with
application to estimating image geometry", CVIU 2000); the expected values are arithmetic on the
literals below.
"""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.scoring import (
    InlierCount,
    MahalanobisResidual,
    PixelMahalanobisResidual,
    TruncatedQuadratic,
)
from stereovo.simulation import SimulationConfig, simulate_frame


def test_inlier_count_is_strictly_under_the_gate_and_a_float_score():
    residual_sq = np.array([[8.99, 9.0, 9.01, 0.0], [9.0, 9.0, 9.0, 9.0]])
    score = InlierCount().score(residual_sq, 9.0)
    # A residual capped at the gate comes back as exactly T^2 (ResidualModel.squared): not an inlier.
    assert score.tolist() == [2.0, 0.0]
    assert score.dtype == np.float64


def test_truncated_quadratic_is_normalised_by_the_gate():
    # -(1 + 4 + 9) / 9 for (1, 4, 100) at T^2 = 9: each residual counts at most the gate.
    score = TruncatedQuadratic().score(np.array([[1.0, 4.0, 100.0], [0.0, 0.0, 0.0]]), 9.0)
    np.testing.assert_allclose(score, [-14.0 / 9.0, 0.0], rtol=1e-15)


@pytest.mark.parametrize("model", [MahalanobisResidual(), PixelMahalanobisResidual()], ids=lambda m: m.name)
def test_residual_models_compute_in_double_precision_whatever_the_motions_dtype(model):
    frame = simulate_frame(SimulationConfig(n_correspondences=40, outlier_ratio=0.3), 4)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    R32 = frame.truth.rotation[None].astype(np.float32)
    t32 = frame.truth.translation[None].astype(np.float32)
    # Single-precision motions are the same motions read exactly in float64.
    expected = model.squared(problem, R32.astype(np.float64), t32.astype(np.float64))
    np.testing.assert_array_equal(model.squared(problem, R32, t32), expected)
