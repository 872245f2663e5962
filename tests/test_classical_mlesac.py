"""MLESAC and Guided-MLESAC (docs/algorithms.md, `mlesac` and `guided-mlesac`): EM, units, priors."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation.estimator_options import EstimatorOptions
from stereovo.estimation.registry import method_spec
from stereovo.estimation.methods.mlesac import (
    GuidedMlesacQuality,
    MlesacQuality,
    mixture_log_likelihood,
    mlesac_em,
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


def frame_problem(seed=3, epsilon=0.5, n=300):
    frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=epsilon), seed)
    return frame, StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)


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


FAR_ROW = np.array([[1e8, 1e8, 1e8 - 50, 1e8]])  # usable (50 px disparity) but absurdly far off the image


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
