"""MLESAC and Guided-MLESAC (docs/algorithms.md, `mlesac` and `guided-mlesac`): EM, units, priors,
and the mixture's densities."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from stereovo.camera import StereoCamera
from stereovo.estimation.estimator_options import EstimatorOptions
from stereovo.estimation.registry import method_spec
from stereovo.estimation.methods.mlesac import (
    GuidedMlesacQuality,
    MlesacQuality,
    mixture_log_likelihood,
    mlesac_em,
    inlier_log_normaliser,
    outlier_log_density,
    COVARIANCE_FLOOR,
)
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.scoring import MahalanobisResidual
from stereovo.geometry import so3_exp
from stereovo.simulation import SimulationConfig, simulate_frame


def simulated_mixture(rng, gamma=0.6, n=2000, sigma=1.0, side=40.0):
    """3-D residuals: Gaussian inliers (std sigma) with probability gamma, else uniform in a cube."""
    inlier = rng.random(n) < gamma
    e = np.where(inlier[:, None], rng.normal(0, sigma, (n, 3)), rng.uniform(-side / 2, side / 2, (n, 3)))
    sq = np.sum(e**2, axis=1)
    log_p_in = -1.5 * np.log(2 * np.pi * sigma**2) - sq / (2 * sigma**2)
    return log_p_in[None], -3 * np.log(side), inlier


def frame_problem(seed=3, epsilon=0.5, n=300):
    frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=epsilon), seed)
    return frame, StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)


def draws_to_first_all_inlier(sampler, inlier, rng, trials=200):
    """Mean draws until the first all-inlier triplet, over independent runs (batches of 64)."""
    counts = []
    for _ in range(trials):
        drawn = 0
        while True:
            s = sampler.draw(64, rng)
            hit = np.flatnonzero(np.all(inlier[s], axis=1))
            if hit.size:
                counts.append(drawn + hit[0] + 1)
                break
            drawn += 64
    return float(np.mean(counts))


FAR_ROW = np.array([[1e8, 1e8, 1e8 - 50, 1e8]])  # usable (50 px disparity) but absurdly far off the image


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


def det3(m: np.ndarray) -> float:
    """A 3x3 determinant by cofactor expansion along the first row."""
    return (
        m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
        - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
        + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0])
    )


@pytest.mark.parametrize("seed", range(5))
def test_em_recovers_the_mixing_weight_and_is_monotone(seed):
    rng = np.random.default_rng(seed)
    log_p_in, log_p_out, _ = simulated_mixture(rng)
    gamma, L, history = mlesac_em(log_p_in, log_p_out, return_history=True)
    assert abs(gamma[0] - 0.6) < 0.03
    values = np.array([h[1][0] for h in history])
    assert np.all(np.diff(values) >= -1e-9), values  # -L never increases
    assert L[0] == pytest.approx(values[-1])
    # L at the EM gamma beats any other gamma on a grid, up to the grid step.
    grid = np.linspace(0.01, 0.99, 99)
    grid_L = mixture_log_likelihood(grid, np.repeat(log_p_in, 99, axis=0), log_p_out)
    assert L[0] >= grid_L.max() - 1e-6


def test_em_is_monotone_from_a_poor_start_and_vectorised_over_hypotheses():
    rng = np.random.default_rng(9)
    rows = [simulated_mixture(rng, gamma=g)[0] for g in (0.1, 0.5, 0.9)]
    log_p_in = np.concatenate(rows)
    gamma, _, history = mlesac_em(log_p_in, -3 * np.log(40.0), iterations=30, gamma0=0.99, return_history=True)
    values = np.stack([h[1] for h in history])
    assert np.all(np.diff(values, axis=0) >= -1e-9)
    np.testing.assert_allclose(gamma, [0.1, 0.5, 0.9], atol=0.03)


def test_mlesac_prefers_the_true_motion_and_its_gamma_is_the_inlier_fraction():
    frame, problem = frame_problem()
    quality = MlesacQuality.for_problem(problem)
    R0, t0 = frame.truth.rotation, frame.truth.translation
    # Perturbed models: 0.2 degrees of yaw, 5 cm of translation.
    Rs = np.stack([R0, so3_exp(np.array([0, np.radians(0.2), 0])) @ R0, R0])
    ts = np.stack([t0, t0, t0 + [0.05, 0, 0]])
    sq = MahalanobisResidual().squared(problem, Rs, ts)
    L = quality.score(sq, 7.81)
    assert L[0] > L[1] and L[0] > L[2]
    gamma = quality.gamma(sq[:1])[0]
    assert abs(gamma - frame.truth.inlier.mean()) < 0.06
    # The densities are in the same units (m^-3): a far and a near inlier weigh alike against
    # the outlier density, so the log-ratio at zero residual varies little with depth.
    log_ratio = quality.log_normaliser - quality.log_p_out
    depth = problem.points_curr[:, 2]
    assert np.ptp(log_ratio[frame.truth.inlier]) < 4.0, np.ptp(log_ratio)
    assert abs(np.corrcoef(log_ratio, np.log(depth))[0, 1]) < 0.9


def test_guided_quality_with_constant_gamma_equals_mlesac_likelihood():
    frame, problem = frame_problem()
    sq = MahalanobisResidual().squared(problem, frame.truth.rotation[None], frame.truth.translation[None])
    mlesac = MlesacQuality.for_problem(problem)
    gamma = mlesac.gamma(sq)[0]
    guided = GuidedMlesacQuality.for_problem(problem, np.full(problem.n, gamma))
    assert guided.score(sq, 7.81)[0] == pytest.approx(mlesac.score(sq, 7.81)[0], rel=1e-9)


def test_informative_priors_reduce_draws_to_the_first_all_inlier_triplet():
    frame, problem = frame_problem(seed=4, epsilon=0.7)
    frame_scores = simulate_frame(
        SimulationConfig(n_correspondences=300, outlier_ratio=0.7, score_auc=0.9), 4
    ).scores  # same geometry, more informative scores (common random numbers)
    options = EstimatorOptions(noise_sigma=frame.noise_sigma)
    spec = method_spec("guided-mlesac")
    inlier = frame.truth.inlier
    rng = np.random.default_rng(0)
    guided = spec.build(problem, options, frame_scores, None, {}).sampler
    flat = spec.build(problem, options, np.full(problem.n, 0.5), None, {}).sampler
    I, N = inlier.sum(), problem.n
    uniform_mean = N * (N - 1) * (N - 2) / (I * (I - 1) * (I - 2))  # 1 / q
    flat_mean = draws_to_first_all_inlier(flat, inlier, rng)
    guided_mean = draws_to_first_all_inlier(guided, inlier, rng)
    assert abs(flat_mean - uniform_mean) < 0.25 * uniform_mean  # constant gamma_i is uniform sampling
    assert guided_mean < 0.5 * uniform_mean


@pytest.mark.filterwarnings("error")  # a NaN/overflow in logaddexp or exp would raise here
@pytest.mark.parametrize("method", ["mlesac", "guided-mlesac"])
@pytest.mark.parametrize("seed", [5, 11])
def test_one_far_off_row_changes_nothing(method, seed):
    # Issue: one such row on an eps-0.5 frame gave "no consensus" after 10,000 hypotheses, with
    # logaddexp warnings. Its densities stay finite, so it is one more outlier.
    from stereovo import estimate_motion
    from stereovo.geometry import rotation_error

    frame, problem = frame_problem(seed=seed, epsilon=0.5)
    far = StereoProblem.build(np.vstack([frame.prev, FAR_ROW]), np.vstack([frame.curr, FAR_ROW]),
                              frame.camera, frame.noise_sigma)
    quality = MlesacQuality.for_problem(far)
    assert np.all(np.isfinite(quality.log_normaliser)) and np.all(np.isfinite(quality.log_p_out))
    assert quality.log_p_out[:-1] == pytest.approx(MlesacQuality.for_problem(problem).log_p_out)  # box unchanged

    def run(prev, curr, priors, **options):
        kw = {"priors": priors} if method == "guided-mlesac" else {}
        return estimate_motion(prev, curr, frame.camera, method=method, rng=1, noise_sigma=frame.noise_sigma,
                               **kw, **options)

    scores = np.append(frame.scores, 0.5)
    # The paper's recipe: still ok, still right, the far row an outlier, no longer a search.
    plain = run(frame.prev, frame.curr, frame.scores)
    extra = run(far.prev, far.curr, scores)
    assert plain.ok and extra.ok, extra.status
    assert not extra.inliers[-1]
    assert np.degrees(rotation_error(extra.rotation, frame.truth.rotation)) < 1.0
    assert extra.n_hypotheses < 4 * plain.n_hypotheses + 64
    # With the refinement both land on the same optimum: the row changes nothing.
    plain = run(frame.prev, frame.curr, frame.scores, polish_iterations=2, refine=True)
    extra = run(far.prev, far.curr, scores, polish_iterations=2, refine=True)
    assert extra.ok and not extra.inliers[-1]
    assert np.count_nonzero(extra.inliers[:-1] != plain.inliers) <= 0.02 * problem.n  # gate-boundary points
    assert np.degrees(rotation_error(extra.rotation, plain.rotation)) < 0.02
    assert np.linalg.norm(extra.translation - plain.translation) < 0.01


@pytest.mark.filterwarnings("error")
def test_densities_stay_finite_for_numerically_singular_covariances_and_absurd_disparities():
    frame, problem = frame_problem(seed=3, epsilon=0.5, n=40)
    # Row 0: a summed covariance of rank 1 (what rounding leaves of an enormous lateral position);
    # row 1: its determinant negative by rounding. Other rows keep slogdet's value exactly.
    u = np.array([0.6, 0.8, 0.0])
    cov_prev = problem.cov_prev.copy()
    cov_prev[0] = 1e9 * np.outer(u, u)
    cov_prev[1] = 1e9 * np.outer(u, u) - 1e-9 * np.eye(3)
    cov_curr = problem.cov_curr.copy()
    cov_curr[:2] = 0.0
    singular = StereoProblem(**{**{k: getattr(problem, k) for k in problem.__dataclass_fields__},
                                "cov_prev": cov_prev, "cov_curr": cov_curr})
    normaliser = MlesacQuality.for_problem(singular).log_normaliser
    assert np.all(np.isfinite(normaliser))
    assert normaliser[0] < 0  # floored at 1e-12 x 1e9 = 1e-3 m^2 per lost direction: a flat, wide density
    np.testing.assert_array_equal(normaliser[2:], MlesacQuality.for_problem(problem).log_normaliser[2:])
    # Squared distances a singular solve returns as NaN or negative are an outlier and a perfect fit.
    quality = MlesacQuality.for_problem(problem)
    sq = np.full((1, problem.n), 1.0)
    sq[0, :2] = [np.nan, -5.0]
    score = quality.score(sq, 7.81)
    assert np.isfinite(score[0]) and np.isfinite(quality.gamma(sq)[0])
    guided = GuidedMlesacQuality.for_problem(problem, np.full(problem.n, 0.5))
    assert np.isfinite(guided.score(sq, 7.81)[0])
    # A row with a disparity beyond the image width: the box grows at most to the width, its density stays in range.
    row = frame.curr[:1].copy()
    row[0, 2] = row[0, 0] - 5 * frame.camera.width
    wide = StereoProblem.build(np.vstack([frame.prev, frame.prev[:1]]), np.vstack([frame.curr, row]),
                               frame.camera, frame.noise_sigma)
    log_p_out = MlesacQuality.for_problem(wide).log_p_out
    assert np.all(np.isfinite(log_p_out))
    cam = frame.camera
    box = np.log(cam.width) + np.log(cam.height) + np.log(cam.width)
    nearest = 4 * np.log(cam.fx * cam.baseline / cam.width) - 2 * np.log(cam.fx) - np.log(cam.fy) - np.log(cam.baseline)
    assert log_p_out[-1] == pytest.approx(-box - nearest)


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


# --- The mixture's densities on ill-conditioned rows and on rows without depth ---


def test_inlier_normaliser_keeps_slogdet_and_floors_only_ill_conditioned_rows():
    A = np.random.default_rng(3).normal(size=(20, 3, 3))
    spd = A @ np.swapaxes(A, 1, 2) + 0.5 * np.eye(3)
    rows = np.concatenate([np.stack([np.diag([1e-20, 1.0, 1.0]), np.diag([2e-12, 1.0, 4.0])]), spd])
    problem = SimpleNamespace(cov_prev=rows / 2, cov_curr=rows / 2)
    got = inlier_log_normaliser(problem)
    base = -1.5 * math.log(2 * math.pi)
    np.testing.assert_array_equal(got[2:], base - 0.5 * np.linalg.slogdet(spd)[1])  # bit for bit
    # eig 1e-20 < 1e-12 x 1: floored to 1e-12; eig 2e-12 < 1e-12 x 4: floored to 4e-12.
    assert abs(got[0] - (base - 0.5 * math.log(COVARIANCE_FLOOR * 1.0))) < 1e-12
    assert abs(got[1] - (base - 0.5 * (math.log(4e-12) + math.log(1.0) + math.log(4.0)))) < 1e-12


def test_densities_are_finite_on_rows_without_depth_and_unchanged_on_the_others():
    """The in-frame environment judges whole frames: rows without depth (NaN points and covariances)
    get finite densities, and every other row the value it has in the usable part alone."""
    frame = simulate_frame(SimulationConfig(n_correspondences=150, outlier_ratio=0.8, outliers="hostile"), 3)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    usable = problem.usable_mask
    assert not usable.all()
    sub = problem.select(np.flatnonzero(usable))
    for density in (inlier_log_normaliser, outlier_log_density):
        whole = density(problem)
        assert np.isfinite(whole).all()
        np.testing.assert_array_equal(whole[usable], density(sub))
    # as documented: a unit determinant, and the outlier density at the farthest depth allowed
    np.testing.assert_array_equal(inlier_log_normaliser(problem)[~usable], -1.5 * np.log(2 * np.pi))
    cam = problem.camera
    largest = min(max(float(np.max(cam.disparity(problem.curr))), 1.0), float(cam.width))
    farthest = cam.fx * cam.baseline / cam.min_disparity
    expected = -(np.log(cam.width) + np.log(cam.height) + np.log(largest)) - (
        4 * np.log(farthest) - 2 * np.log(cam.fx) - np.log(cam.fy) - np.log(cam.baseline))
    np.testing.assert_allclose(outlier_log_density(problem)[~usable], expected, rtol=1e-12)
    quality = MlesacQuality.for_problem(problem)
    R, t = frame.truth.rotation[None], frame.truth.translation[None]
    assert np.isfinite(quality.score(MahalanobisResidual().squared(problem, R, t), 7.81)).all()


def test_outlier_density_of_a_frame_without_a_finite_disparity_takes_a_one_pixel_box_side():
    cam = StereoCamera()
    nothing = SimpleNamespace(camera=cam, curr=np.full((3, 4), np.nan), points_curr=np.full((3, 3), np.nan))
    farthest = cam.fx * cam.baseline / cam.min_disparity
    expected = -(np.log(cam.width) + np.log(cam.height) + np.log(1.0)) - (
        4 * np.log(farthest) - 2 * np.log(cam.fx) - np.log(cam.fy) - np.log(cam.baseline))
    np.testing.assert_allclose(outlier_log_density(nothing), expected, rtol=1e-12)
