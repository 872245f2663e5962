"""MLESAC's densities in absolute units, on a non-default camera, against the formulas of stereovo.estimation.methods.mlesac.

Outliers are uniform in the stereo measurement box ``width x height x (largest disparity)`` px^3, carried
to metres at the point by ``|det J| = Z^4 / (fx^2 fy b)``; inliers are Gaussian with covariance
``S_X + S_Y``. The expected values are worked out by hand below.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stereovo.camera import StereoCamera
from stereovo.estimation.methods.mlesac import (
    GuidedMlesacQuality,
    MlesacQuality,
    inlier_log_normaliser,
    mixture_log_likelihood,
    mlesac_em,
    outlier_log_density,
)
from stereovo.estimation.problem import StereoProblem

# fx != fy, a short baseline and a VGA image: every camera constant enters the density differently.
CAMERA = StereoCamera(fx=500.0, fy=400.0, cx=320.0, cy=240.0, baseline=0.25, width=640, height=480)


def problem_at_depths(depths_curr=(5.0, 10.0, 25.0)) -> StereoProblem:
    """Points on and off the optical axis at known depths at k (disparity fx b / Z = 125 / Z px);
    every row kept (min_disparity_sigmas 0), so that very far rows reach the density's floor."""
    depths = np.asarray(depths_curr)
    curr_points = np.stack([np.linspace(-1.0, 1.0, depths.size), np.linspace(0.5, -0.5, depths.size), depths], 1)
    prev_points = curr_points + [0.0, 0.0, 1.0]
    return StereoProblem.build(CAMERA.project(prev_points), CAMERA.project(curr_points), CAMERA, 0.5,
                               min_disparity_sigmas=0.0)


def test_outlier_density_in_measurement_space_mapped_to_metres():
    problem = problem_at_depths()
    # Disparities 125/5 = 25, 125/10 = 12.5, 125/25 = 5 px: the box is 640 x 480 x 25 = 7.68e6 px^3.
    # |det J| = Z^4 / (500^2 * 400 * 0.25) = Z^4 / 2.5e7 m^3/px^3: 2.5e-5 (Z = 5), 4e-4 (10), 0.015625 (25).
    # p_out = 1 / (7.68e6 |det J|): 1/192, 1/3072, 1/120000 per m^3.
    expected = np.log([1 / 192, 1 / 3072, 1 / 120_000])
    np.testing.assert_allclose(outlier_log_density(problem), expected, rtol=0, atol=1e-9)
    # A far point is spread over more metric volume: its density is lower (the sign of the Jacobian term).
    assert outlier_log_density(problem)[0] > outlier_log_density(problem)[2]


def test_outlier_density_box_uses_the_largest_disparity_of_the_frame():
    # Depths 10 and 25 m only: the largest disparity is 12.5 px, the box 640 x 480 x 12.5 = 3.84e6 px^3.
    problem = problem_at_depths((10.0, 25.0))
    expected = np.log([1 / (3.84e6 * 4e-4), 1 / (3.84e6 * 0.015625)])  # 1/1536 and 1/60000
    np.testing.assert_allclose(outlier_log_density(problem), expected, rtol=0, atol=1e-9)
    # Very far points (largest disparity 1.25 px < 1): the disparity side of the box is floored at 1 px.
    far = problem_at_depths((100.0, 125.0))  # disparities 1.25 and 1.0 px
    box = 640 * 480 * 1.25
    np.testing.assert_allclose(
        outlier_log_density(far), np.log([1 / (box * 100.0**4 / 2.5e7), 1 / (box * 125.0**4 / 2.5e7)]), atol=1e-9
    )


def det3(m: np.ndarray) -> float:
    """A 3x3 determinant by cofactor expansion along the first row."""
    return (
        m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
        - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
        + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0])
    )


def test_inlier_normaliser_is_the_gaussian_constant_of_the_summed_covariance():
    problem = problem_at_depths()
    got = inlier_log_normaliser(problem)
    for i in range(problem.n):
        S = problem.cov_prev[i] + problem.cov_curr[i]
        # log((2 pi)^(-3/2) |S|^(-1/2))
        assert got[i] == pytest.approx(-1.5 * math.log(2 * math.pi) - 0.5 * math.log(det3(S)), abs=1e-9)
    # A nearer point is measured more precisely: a larger Gaussian peak.
    assert got[0] > got[1] > got[2]


def test_inlier_normaliser_on_explicit_covariances():
    # S_X + S_Y = diag(0.04, 0.1, 1.0) m^2 (det 0.004) and [[2, 1, 0], [1, 2, 0], [0, 0, 1]] (det 3).
    problem = problem_at_depths((5.0, 10.0))
    cov_prev = np.array([np.diag([0.01, 0.04, 0.25]), [[1.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 0.5]]])
    cov_curr = np.array([np.diag([0.03, 0.06, 0.75]), [[1.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 0.5]]])
    explicit = StereoProblem(**{**{k: getattr(problem, k) for k in problem.__dataclass_fields__},
                                "cov_prev": cov_prev, "cov_curr": cov_curr})
    expected = [-1.5 * math.log(2 * math.pi) - 0.5 * math.log(0.004), -1.5 * math.log(2 * math.pi) - 0.5 * math.log(3)]
    np.testing.assert_allclose(inlier_log_normaliser(explicit), expected, rtol=0, atol=1e-12)
    assert expected[0] == pytest.approx(-2.7568156 + 2.7607305, abs=1e-6)  # = 0.0039149


def test_mlesac_quality_uses_both_densities():
    problem = problem_at_depths()
    quality = MlesacQuality.for_problem(problem)
    np.testing.assert_allclose(quality.log_p_out, np.log([1 / 192, 1 / 3072, 1 / 120_000]), atol=1e-9)
    # The inlier density at squared Mahalanobis distance d^2 is the normaliser times exp(-d^2 / 2).
    d2 = np.array([[0.0, 2.0, 8.0]])
    np.testing.assert_allclose(quality.log_p_in(d2), (inlier_log_normaliser(problem) - np.array([0.0, 1.0, 4.0]))[None])


def test_em_tolerance_and_iterations_reach_the_quality():
    # Unit densities: p_in = exp(-d^2 / 2), p_out = 0.5. Two residuals at 0 and two at d^2 = 20.
    # One EM step from gamma 0.5: z = (0.5 * 1) / (0.5 * 1 + 0.5 * 0.5) = 2/3 for the small ones and
    # 0.5 e^-10 / (0.5 e^-10 + 0.25) = 9.08e-5 for the others: gamma_1 = (2 * 2/3 + 2 * 9.08e-5) / 4 = 0.33338.
    # The change 0.1666 is below a tolerance of 0.5: EM stops there, 50 iterations allowed or not.
    z_far = 0.5 * math.exp(-10) / (0.5 * math.exp(-10) + 0.25)
    gamma_1 = (2 * (2 / 3) + 2 * z_far) / 4
    d2 = np.array([[0.0, 0.0, 20.0, 20.0]])
    coarse = MlesacQuality(np.zeros(4), np.full(4, math.log(0.5)), em_iterations=50, em_tolerance=0.5)
    assert coarse.gamma(d2)[0] == pytest.approx(gamma_1, rel=1e-12)
    # L at gamma_1: sum_i log(gamma_1 p_in,i + (1 - gamma_1) 0.5).
    L = 2 * math.log(gamma_1 + (1 - gamma_1) * 0.5) + 2 * math.log(gamma_1 * math.exp(-10) + (1 - gamma_1) * 0.5)
    assert coarse.score(d2, 9.0)[0] == pytest.approx(L, rel=1e-12)
    # A tight tolerance runs on to the fixed point gamma ~ 1/2 - ..., far from one step.
    fine = MlesacQuality(np.zeros(4), np.full(4, math.log(0.5)), em_iterations=50, em_tolerance=1e-9)
    assert abs(fine.gamma(d2)[0] - gamma_1) > 0.05


def test_guided_mlesac_clips_the_priors_away_from_0_and_1():
    problem = problem_at_depths()
    quality = GuidedMlesacQuality.for_problem(problem, np.array([0.0, 1.0, 0.25]))
    np.testing.assert_array_equal(quality.gamma, [1e-6, 1 - 1e-6, 0.25])
    scores = quality.score(np.zeros((1, 3)), 9.0)
    assert np.all(np.isfinite(scores))
    # Residuals 0: each term log(g p_in + (1 - g) p_out) with p_in the normaliser's density.
    p_in, p_out = np.exp(inlier_log_normaliser(problem)), np.exp(outlier_log_density(problem))
    g = np.array([1e-6, 1 - 1e-6, 0.25])
    assert scores[0] == pytest.approx(float(np.sum(np.log(g * p_in + (1 - g) * p_out))), rel=1e-9)


def test_em_defaults_and_the_gamma_clip():
    # p_in = 1 for two residuals, ~0 for two, p_out = 0.5: the EM map is g -> g / (1 + g) (up to e^-10 terms),
    # so from 0.5 it runs 1/3, 1/4, ... and after the default five iterations gamma = 1/7 (changes > 1e-4).
    log_p_in = np.array([[0.0, 0.0, -10.0, -10.0]])
    result = mlesac_em(log_p_in, math.log(0.5))
    assert len(result) == 2  # (gamma, L) unless return_history
    assert result[0][0] == pytest.approx(1 / 7, abs=2e-4)
    assert mlesac_em(log_p_in, math.log(0.5), iterations=0)[0][0] == 0.5  # gamma0 is 0.5
    # A model claiming every point (gamma = 1) is clipped to 1 - 1e-6: L = log((1 - 1e-6) e^0 + 1e-6 * 1e6) = log 2 - ...
    L = mixture_log_likelihood(np.array([1.0]), np.array([[0.0]]), math.log(1e6))
    assert L[0] == pytest.approx(math.log((1 - 1e-6) + 1e-6 * 1e6), rel=1e-9)  # unclipped: log 1 = 0
    # EM from gamma0 = 1 is not stuck there: z = (1 - 1e-6) e^-50 / ((1 - 1e-6) e^-50 + 1e-6) ~ 2e-16.
    gamma = mlesac_em(np.array([[-50.0, -50.0]]), 0.0, iterations=1, gamma0=1.0)[0]
    assert gamma[0] == pytest.approx(math.exp(-50) / 1e-6, rel=1e-5)


def test_mlesac_quality_settings_and_unusable_distances():
    problem = problem_at_depths()
    default = MlesacQuality.for_problem(problem)
    assert (default.em_iterations, default.em_tolerance) == (5, 1e-4)
    custom = MlesacQuality.for_problem(problem, em_iterations=9, em_tolerance=0.5)
    assert (custom.em_iterations, custom.em_tolerance) == (9, 0.5)
    # A NaN squared distance (a singular covariance's solve) counts as an outlier, like inf; a negative one as 0.
    nan, inf, zero = (default.score(np.array([[x, 0.0, 0.0]]), 9.0)[0] for x in (np.nan, np.inf, 0.0))
    assert nan == inf and nan < zero
    assert default.score(np.array([[-1e-9, 0.0, 0.0]]), 9.0)[0] == zero
