"""The shared estimator core: solvers, samplers, termination, scoring and the estimate_motion contract."""

import itertools

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from stereovo import StereoCamera, available_methods, estimate_motion
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.samplers import (
    ProsacSampler,
    WeightedSampler,
    distinct_uniform_triplets,
    prosac_growth,
)
from stereovo.estimation.roles.scoring import MahalanobisResidual, PixelMahalanobisResidual
from stereovo.estimation.roles.solvers import degenerate_triplets, kabsch_batch
from stereovo.estimation.roles.termination import required_iterations
from stereovo.geometry import random_rotation, rotation_error, se3_exp

CAMERA = StereoCamera()
CORE_METHODS = ["ransac", "msac", "probabilistic"]


def noise_free_pair(rng, R, t, n=80):
    """Points visible in both frames under the motion x_k = R x_{k-1} + t, measured exactly."""
    X = np.c_[rng.uniform(-20, 20, 40 * n), rng.uniform(-3, 3, 40 * n), rng.uniform(3, 50, 40 * n)]
    Y = X @ R.T + t
    ok = CAMERA.is_visible(X, z_min=3) & CAMERA.is_visible(Y, z_min=1)
    X, Y = X[ok][:n], Y[ok][:n]
    return CAMERA.project(X), CAMERA.project(Y)


motions = st.tuples(
    st.floats(-0.15, 0.15), st.floats(-0.15, 0.15), st.floats(-0.15, 0.15),
    st.floats(-1.0, 1.0), st.floats(-0.5, 0.5), st.floats(-2.0, 0.5), st.integers(0, 2**31),
)


@given(motions)
def test_noise_free_motion_recovered_to_1e9(m):
    wx, wy, wz, tx, ty, tz, seed = m
    R, _ = se3_exp(np.array([0, 0, 0, wx, wy, wz]))
    t = np.array([tx, ty, tz])
    prev, curr = noise_free_pair(np.random.default_rng(seed), R, t)
    for method in CORE_METHODS:
        est = estimate_motion(prev, curr, CAMERA, method=method, rng=seed)
        assert est.ok, est.status
        assert rotation_error(est.rotation, R) < 1e-9
        assert np.linalg.norm(est.translation - t) < 1e-9
        assert est.inliers.all()


def test_kabsch_batch_exact_and_proper_rotation():
    rng = np.random.default_rng(0)
    R = np.stack([random_rotation(rng) for _ in range(16)])
    t = rng.normal(size=(16, 3))
    X = rng.normal(size=(16, 3, 3)) * 5
    Y = np.einsum("hij,hmj->hmi", R, X) + t[:, None]
    R_fit, t_fit = kabsch_batch(X, Y)
    np.testing.assert_allclose(R_fit, R, atol=1e-10)
    np.testing.assert_allclose(t_fit, t, atol=1e-9)
    # A mirrored point set must still give det +1.
    R_m, _ = kabsch_batch(X[:1], -X[:1])
    assert np.linalg.det(R_m[0]) == pytest.approx(1.0)


def _svd_kabsch(X: np.ndarray, Y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference weighted Kabsch/Umeyama: SVD of the cross-covariance with the det(R) = +1 fix."""
    w = w / w.sum()
    mx, my = w @ X, w @ Y
    U, _, Vt = np.linalg.svd(((Y - my) * w[:, None]).T @ (X - mx))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return R, my - R @ mx


def test_closed_form_fit_is_the_svd_kabsch_minimiser():
    """Horn's quaternion fit equals the SVD solution on noisy, weighted and pure-outlier sets."""
    rng = np.random.default_rng(3)
    H, M = 200, 5
    R_true = np.stack([random_rotation(rng) for _ in range(H)])
    X = rng.normal(size=(H, M, 3)) * 4 + [0.0, 0.0, 15.0]
    Y = np.einsum("hij,hmj->hmi", R_true, X) + rng.normal(size=(H, 1, 3))
    Y[: H // 2] += rng.normal(0, 0.05, size=(H // 2, M, 3))  # noisy inliers
    Y[H // 2 :] = rng.normal(size=(H - H // 2, M, 3)) * 4  # unrelated points: any rotation may win
    w = rng.uniform(0.1, 1.0, size=(H, M))
    R_fit, t_fit = kabsch_batch(X, Y, w)
    for h in range(H):
        R_ref, t_ref = _svd_kabsch(X[h], Y[h], w[h])
        np.testing.assert_allclose(R_fit[h], R_ref, atol=1e-9)
        np.testing.assert_allclose(t_fit[h], t_ref, atol=1e-8)
    np.testing.assert_allclose(np.linalg.det(R_fit), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("hij,hkj->hik", R_fit, R_fit), np.broadcast_to(np.eye(3), (H, 3, 3)), atol=1e-12)
    # Minimal samples: three points, a rank-2 cross-covariance.
    R3, t3 = kabsch_batch(X[:, :3], Y[:, :3])
    for h in range(H):
        R_ref, t_ref = _svd_kabsch(X[h, :3], Y[h, :3], np.ones(3))
        np.testing.assert_allclose(R3[h], R_ref, atol=1e-9)


def test_closed_form_fit_of_collinear_points_still_aligns_them():
    """Collinear points leave the rotation about their line free (a repeated top eigenvalue of
    Horn's 4x4, where the eigenvector is not unique): the fit must still map them exactly."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        R, t = random_rotation(rng), rng.normal(size=3)
        direction = rng.normal(size=3)
        X = rng.normal(size=(4, 1)) * direction + rng.normal(size=3)
        Y = X @ R.T + t
        R_fit, t_fit = kabsch_batch(X[None], Y[None])
        np.testing.assert_allclose(X @ R_fit[0].T + t_fit[0], Y, atol=1e-9)
        assert np.linalg.det(R_fit[0]) == pytest.approx(1.0)


def test_degenerate_triplets_detected():
    line = np.array([[[0, 0, 5.0], [1, 0, 5.0], [2, 0, 5.0]]])
    coincident = np.array([[[1, 1, 5.0], [1, 1, 5.0], [1, 1, 5.0]]])
    good = np.array([[[0, 0, 5.0], [1, 0, 5.0], [0, 1, 6.0]]])
    X = np.concatenate([line, coincident, good])
    np.testing.assert_array_equal(degenerate_triplets(X, X), [True, True, False])


def test_minimal_hypotheses_compose_degeneracy_fit_and_polish():
    from stereovo.estimation.roles.reprojection import gauss_newton_steps
    from stereovo.estimation.roles.solvers import minimal_hypotheses

    rng = np.random.default_rng(6)
    prev, curr = noise_free_pair(rng, random_rotation(rng, 0.05), np.array([0.2, 0.0, -1.0]), 40)
    curr = curr + rng.normal(0, 0.5, curr.shape)
    problem = StereoProblem.build(prev, curr, CAMERA, 0.5)
    samples = np.stack([rng.choice(40, 3, replace=False) for _ in range(50)])
    samples[0] = [0, 0, 1]  # coincident points: degenerate
    X, Y = problem.points_prev[samples], problem.points_curr[samples]
    R, t, valid = minimal_hypotheses(problem, samples, polish_iterations=2)
    np.testing.assert_array_equal(valid, ~degenerate_triplets(X, Y))
    R0, t0 = kabsch_batch(X, Y)
    R_ref, t_ref, _ = gauss_newton_steps(
        CAMERA, R0, t0, X, Y, problem.prev[samples], problem.curr[samples],
        iterations=2, damping=1e-9, tolerance=0.0, step_control=False,
    )
    np.testing.assert_allclose(R[valid], R_ref[valid], atol=1e-12)
    np.testing.assert_allclose(t[valid], t_ref[valid], atol=1e-12)
    np.testing.assert_array_equal(R[0], np.eye(3))


def test_uniform_triplets_distinct_and_uniform():
    rng = np.random.default_rng(0)
    s = distinct_uniform_triplets(np.full(60_000, 5), rng)
    assert np.all((s[:, 0] != s[:, 1]) & (s[:, 0] != s[:, 2]) & (s[:, 1] != s[:, 2]))
    counts = np.bincount(s.ravel(), minlength=5) / s.size
    np.testing.assert_allclose(counts, 0.2, atol=0.005)
    sets = {tuple(sorted(r)) for r in s[:2000]}
    assert len(sets) == 10  # every 3-subset of 5 appears


def test_weighted_sampler_follows_priors_and_log_probability_is_exact():
    priors = np.array([4.0, 3.0, 2.0, 1.0, 0.0])
    sampler = WeightedSampler(priors)
    rng = np.random.default_rng(0)
    draws = sampler.draw(100_000, rng)
    assert not np.any(draws == 4)  # zero prior is never drawn
    # Empirical frequency of each ordered triplet matches its exact log-probability.
    triplets = list(itertools.permutations(range(4), 3))
    probs = np.exp(sampler.log_probability(np.array(triplets)))
    assert probs.sum() == pytest.approx(1.0)
    keys = draws @ np.array([16, 4, 1])
    freq = np.array([np.mean(keys == a * 16 + b * 4 + c) for a, b, c in triplets])
    np.testing.assert_allclose(freq, probs, atol=0.006)


def test_prosac_growth_matches_reference_values():
    T = prosac_growth(500)
    assert [int(T[n]) for n in (4, 5, 10, 20, 50, 100, 200)] == [2, 3, 8, 23, 216, 1613, 12783]


def test_prosac_samples_respect_growth():
    order = np.random.default_rng(1).permutation(200)
    sampler = ProsacSampler(order)
    rank = np.empty(200, dtype=int)
    rank[order] = np.arange(200)
    draws = rank[sampler.draw(3000, np.random.default_rng(2))]
    t = np.arange(1, 3001)
    n = sampler.subset_sizes(t)
    anchored = t <= sampler.growth[n]
    assert np.all(draws.max(axis=1) < n)
    assert np.all(draws[anchored].max(axis=1) == n[anchored] - 1)
    assert set(draws[0]) == {0, 1, 2}


def test_required_iterations_without_replacement():
    # docs/algorithms.md, `ransac`: N = 20, I = 6, p = 0.99 gives 261 (the w^3 bound would give 169).
    assert required_iterations(6, 20, 0.99) == 261
    assert required_iterations(2, 20, 0.99, max_iterations=10_000) == 10_000
    assert required_iterations(20, 20, 0.99) == 1
    # arrays of counts give the bounds elementwise
    np.testing.assert_array_equal(required_iterations(np.array([[6, 2], [20, 6]]), 20, 0.99), [[261, 10_000], [1, 261]])


def test_reprojection_residual_matches_projection_and_is_inf_behind_the_camera():
    from stereovo.estimation.kernels.base import MIN_DEPTH
    from stereovo.estimation.roles.reprojection import reprojection_sq

    rng = np.random.default_rng(4)
    X = np.column_stack([rng.uniform(-8, 8, 300), rng.uniform(-2, 2, 300), rng.uniform(2, 60, 300)])
    meas = rng.uniform(0, 500, (300, 4))
    Rs = np.stack([random_rotation(rng, 0.1) for _ in range(5)])
    ts = rng.normal(0, 0.5, (5, 3))
    ts[4] = [0.0, 0.0, -30.0]  # moves the nearer half of the points behind the camera
    got = reprojection_sq(CAMERA, Rs, ts, X, meas)
    for h in range(5):
        moved = X @ Rs[h].T + ts[h]
        behind = moved[:, 2] <= MIN_DEPTH
        expected = np.sum((CAMERA.project(np.where(behind[:, None], 1.0, moved)) - meas) ** 2, axis=1)
        np.testing.assert_allclose(got[h][~behind], expected[~behind], rtol=1e-12)
        assert np.all(np.isinf(got[h][behind]))
        assert behind.any() == (h == 4)


def test_mahalanobis_matches_explicit_inverse():
    rng = np.random.default_rng(0)
    R, t = random_rotation(rng, 0.1), rng.normal(size=3)
    prev, curr = noise_free_pair(rng, R, t, 30)
    curr = curr + rng.normal(0, 0.5, curr.shape)
    curr[:, 3] = curr[:, 1]
    problem = StereoProblem.build(prev, curr, CAMERA, 0.5)
    Rs = np.stack([R, random_rotation(rng, 0.1)])
    ts = np.stack([t, t + 0.1])
    got = MahalanobisResidual().squared(problem, Rs, ts)
    for h in range(2):
        P = problem.points_prev @ Rs[h].T + ts[h]
        Y = problem.points_curr
        r = Y - P
        # covariances at the fused points: in each frame, the disparity the mean of the two
        # observations carried there (Y carried back to k-1 is W = R^T (Y - t))
        ip, iy = 1 / P[:, 2], 1 / Y[:, 2]
        Q = (P * ip[:, None] + Y * iy[:, None]) / (ip + iy)[:, None]
        X, W = problem.points_prev, (Y - ts[h]) @ Rs[h]
        ix, iw = 1 / X[:, 2], 1 / W[:, 2]
        X_star = (X * ix[:, None] + W * iw[:, None]) / (ix + iw)[:, None]
        np.testing.assert_allclose(CAMERA.disparity(CAMERA.project(X_star)), 0.5 * (CAMERA.disparity(CAMERA.project(X))
                                   + CAMERA.disparity(CAMERA.project(W))), rtol=1e-12)
        np.testing.assert_allclose(CAMERA.disparity(CAMERA.project(Q)), 0.5 * (CAMERA.disparity(CAMERA.project(P))
                                   + CAMERA.disparity(CAMERA.project(Y))), rtol=1e-12)
        cov_at = lambda X: CAMERA.triangulation_covariance(CAMERA.project(X), 0.5)  # noqa: E731
        C = Rs[h] @ cov_at(X_star) @ Rs[h].T + cov_at(Q)
        expected = np.einsum("ni,ni->n", r, np.linalg.solve(C, r[..., None])[..., 0])
        np.testing.assert_allclose(got[h], expected, rtol=1e-8)


def test_capped_mahalanobis_is_exact_below_the_cap_and_at_least_the_cap_above():
    rng = np.random.default_rng(2)
    R, t = random_rotation(rng, 0.1), rng.normal(size=3)
    prev, curr = noise_free_pair(rng, R, t, 200)
    curr = curr + rng.normal(0, 0.5, curr.shape)
    curr[:80] = curr[80:160][::-1]  # mismatches
    problem = StereoProblem.build(prev, curr, CAMERA, 0.5)
    Rs = np.stack([R, random_rotation(rng, 0.1), R])
    ts = np.stack([t, t + 0.3, t + 0.02])
    exact = MahalanobisResidual().squared(problem, Rs, ts)
    cap = MahalanobisResidual().threshold_sq
    capped = MahalanobisResidual().squared(problem, Rs, ts, cap=cap)
    below = exact < cap
    np.testing.assert_array_equal(capped[below], exact[below])
    assert np.all(capped[~below] >= cap) and np.all(capped[~below] <= exact[~below] * (1 + 1e-12))
    assert np.any(capped[~below] < exact[~below])  # the bound did skip some solves


@pytest.mark.parametrize("v_measurement", ["shared", "independent"])
def test_pixel_mahalanobis_matches_explicit_propagated_covariance(v_measurement):
    rng = np.random.default_rng(1)
    R, t = random_rotation(rng, 0.1), rng.normal(size=3)
    prev, curr = noise_free_pair(rng, R, t, 30)
    curr = curr + rng.normal(0, 0.5, curr.shape)
    camera = StereoCamera(v_measurement=v_measurement)
    problem = StereoProblem.build(prev, curr, camera, 0.5)
    Rs = np.stack([R, random_rotation(rng, 0.1)])
    ts = np.stack([t, t + 0.1])
    got = PixelMahalanobisResidual().squared(problem, Rs, ts)
    fx, fy, b = CAMERA.fx, CAMERA.fy, CAMERA.baseline
    for h in range(2):
        Y = problem.points_prev @ Rs[h].T + ts[h]
        x, y, z = Y.T
        J = np.zeros((len(z), 4, 3))
        J[:, 0] = np.stack([fx / z, 0 * z, -fx * x / z**2], -1)
        J[:, 1] = np.stack([0 * z, fy / z, -fy * y / z**2], -1)
        J[:, 2] = np.stack([fx / z, 0 * z, -fx * (x - b) / z**2], -1)
        J[:, 3] = J[:, 1]
        r = CAMERA.project(Y) - curr
        if v_measurement == "shared":  # one v measured: residual (uL, uR, mean v), 3 dof
            J, r = J[:, [0, 2, 1]], np.stack([r[:, 0], r[:, 2], 0.5 * (r[:, 1] + r[:, 3])], -1)
        C = J @ (Rs[h] @ problem.cov_prev @ Rs[h].T) @ np.swapaxes(J, 1, 2) + 0.25 * np.eye(J.shape[1])
        expected = np.einsum("ni,ni->n", r, np.linalg.solve(C, r[..., None])[..., 0])
        np.testing.assert_allclose(got[h], expected, rtol=1e-8)


def test_pixel_gate_keeps_the_inliers_it_promises_where_the_3d_gate_misses_far_points():
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=1000, outlier_ratio=0.3), np.random.default_rng(3))
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    truth = frame.truth.inlier
    R, t = frame.truth.rotation[None], frame.truth.translation[None]
    pixel = PixelMahalanobisResidual().squared(problem, R, t)[0] < PixelMahalanobisResidual().threshold_sq
    metric = MahalanobisResidual().squared(problem, R, t)[0] < MahalanobisResidual().threshold_sq
    assert np.mean(pixel[truth]) > 0.97  # a 99 % gate
    assert np.mean(pixel[truth]) > np.mean(metric[truth]) + 0.03
    assert np.mean(pixel[~truth]) < 0.05


def test_probabilistic_final_inliers_recall_the_true_inliers():
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=500, outlier_ratio=0.5), np.random.default_rng(4))
    est = estimate_motion(frame.prev, frame.curr, frame.camera, rng=0)
    truth = frame.truth.inlier
    assert est.ok
    assert np.mean(est.inliers[truth]) > 0.95
    assert np.mean(est.inliers[~truth]) < 0.02
    with pytest.raises(ValueError, match="refine_gate_probability"):
        estimate_motion(frame.prev, frame.curr, frame.camera, refine_gate_probability=1.0)


# ----------------------------------------------------------------------------- the public contract


def test_available_methods_lists_core_methods_with_descriptions():
    methods = available_methods()
    for name in CORE_METHODS:
        assert name in methods and len(methods[name]) > 10


@pytest.mark.parametrize(
    "prev,curr,message",
    [
        (np.zeros((5, 3)), np.zeros((5, 3)), r"shape \(N, 4\)"),
        (np.tile([600.0, 100, 590, 100], (5, 1)), np.tile([600.0, 100, 590, 100], (4, 1)), "same number of rows"),
        (np.tile([600.0, 100, 590, 100], (5, 1)) + 1j, np.tile([600.0, 100, 590, 100], (5, 1)), "prev must be real"),
        (np.tile([600.0, 100, 590, 100], (5, 1)), np.tile([600.0, 100, 590, 100], (5, 1)).astype(complex),
         "curr must be real"),
        (np.full((5, 4), "a"), np.ones((5, 4)), "prev must be a numeric"),
    ],
)
def test_malformed_input_raises_clear_value_error(prev, curr, message):
    with pytest.raises(ValueError, match=message):
        estimate_motion(prev, curr, CAMERA)


def test_rows_without_depth_are_not_malformed_input():
    """A frame whose rows all lack depth is a failed estimate, not a ValueError (DESIGN section 3)."""
    est = estimate_motion(np.tile([600.0, 100, 600, 100], (8, 1)), np.tile([600.0, 100, 590, 100], (8, 1)), CAMERA)
    assert not est.ok and est.n_unusable == 8 and "0 of 8 usable" in est.status and est.covariance is None


def test_bad_method_option_priors_and_order_raise():
    prev, curr = noise_free_pair(np.random.default_rng(0), np.eye(3), np.array([0, 0, -1.0]), 30)
    with pytest.raises(ValueError, match="unknown method"):
        estimate_motion(prev, curr, CAMERA, method="nope")
    with pytest.raises(ValueError, match="unknown option"):
        estimate_motion(prev, curr, CAMERA, threshhold=3)
    with pytest.raises(ValueError, match="confidence"):
        estimate_motion(prev, curr, CAMERA, confidence=1.5)
    with pytest.raises(ValueError, match="refine_rounds"):
        estimate_motion(prev, curr, CAMERA, refine_rounds=0)
    with pytest.raises(ValueError, match="first_batch_size"):
        estimate_motion(prev, curr, CAMERA, first_batch_size=0)
    with pytest.raises(ValueError, match="rigidity_gate_probability"):
        estimate_motion(prev, curr, CAMERA, rigidity_gate_probability=1.0)
    with pytest.raises(ValueError, match="priors must have shape"):
        estimate_motion(prev, curr, CAMERA, priors=np.ones(3))
    with pytest.raises(ValueError, match=r"non-negative, got minimum -2.5"):
        estimate_motion(prev, curr, CAMERA, priors=np.r_[np.ones(29), -2.5])
    with pytest.raises(ValueError, match="NaN or inf"):
        estimate_motion(prev, curr, CAMERA, priors=np.r_[np.ones(29), np.inf])
    with pytest.raises(ValueError, match="at least 3 positive"):
        estimate_motion(prev, curr, CAMERA, priors=np.r_[np.ones(2), np.zeros(28)])
    with pytest.raises(ValueError, match="permutation"):
        estimate_motion(prev, curr, CAMERA, order=np.zeros(30, dtype=int))
    with pytest.raises(ValueError, match="not both"):
        estimate_motion(prev, curr, CAMERA, priors=np.ones(30), order=np.arange(30))


def test_estimate_problem_equals_estimate_motion_on_the_same_frame():
    from stereovo.estimation import estimate_problem

    rng = np.random.default_rng(5)
    prev, curr = noise_free_pair(rng, random_rotation(rng, 0.05), np.array([0.1, 0.0, -1.0]), 60)
    curr = curr + rng.normal(0, 0.5, curr.shape)
    curr[:10] = curr[10:20]  # mismatches
    problem = StereoProblem.build(prev, curr, CAMERA, 0.5)
    for method in ("probabilistic", "msac"):
        a = estimate_motion(prev, curr, CAMERA, method=method, rng=3, noise_sigma=0.5)
        b = estimate_problem(problem, method=method, rng=3)
        np.testing.assert_array_equal(a.rotation, b.rotation)
        np.testing.assert_array_equal(a.inliers, b.inliers)
    with pytest.raises(ValueError, match="differs from the problem"):
        estimate_problem(problem, noise_sigma=1.0)


def test_hopeless_frames_fail_without_raising():
    prev, curr = noise_free_pair(np.random.default_rng(0), np.eye(3), np.array([0, 0, -1.0]), 30)
    few = estimate_motion(prev[:2], curr[:2], CAMERA)
    assert not few.ok and "too few" in few.status
    assert np.array_equal(few.rotation, np.eye(3)) and few.inliers.shape == (2,)

    line = np.array([[x, 0.0, 10.0] for x in np.linspace(-3, 3, 12)])
    collinear = estimate_motion(CAMERA.project(line), CAMERA.project(line + [0, 0, -1]), CAMERA, budget=64)
    assert not collinear.ok and "degenerate" in collinear.status

    rng = np.random.default_rng(5)
    shuffled = curr[rng.permutation(30)]
    none = estimate_motion(prev, shuffled, CAMERA, method="ransac", rng=1, max_iterations=300)
    assert not none.ok and "no consensus" in none.status
    np.testing.assert_array_equal(none.translation, np.zeros(3))


def test_same_seed_same_result_different_seed_differs():
    rng = np.random.default_rng(3)
    R, t = random_rotation(rng, 0.05), np.array([0.1, 0.0, -1.0])
    prev, curr = noise_free_pair(rng, R, t, 200)
    curr = curr + rng.normal(0, 0.5, curr.shape)
    curr[:, 3] = curr[:, 1]
    curr[:100] = curr[rng.permutation(100)]  # half of them mismatched
    a = estimate_motion(prev, curr, CAMERA, rng=7)
    b = estimate_motion(prev, curr, CAMERA, rng=np.random.default_rng(7))
    c = estimate_motion(prev, curr, CAMERA, rng=8)
    np.testing.assert_array_equal(a.rotation, b.rotation)
    np.testing.assert_array_equal(a.inliers, b.inliers)
    assert a.n_hypotheses == b.n_hypotheses
    assert not np.array_equal(a.translation, c.translation)


def test_fixed_budget_draws_exactly_budget():
    rng = np.random.default_rng(4)
    prev, curr = noise_free_pair(rng, np.eye(3), np.array([0, 0, -1.0]), 100)
    est = estimate_motion(prev, curr, CAMERA, budget=17, batch_size=5)
    assert est.n_hypotheses == 17 and est.ok


def test_small_first_batch_and_refit_skipped_only_in_the_batch_that_ends_the_search():
    """A low-contamination frame ends after its first batch: the light refit of that batch's
    best is left to the final refinement, but Lo-RANSAC's inner RANSAC (a search) still runs,
    and so does the refit when later batches follow."""
    rng = np.random.default_rng(5)
    R_true = random_rotation(rng, 0.05)
    prev, curr = noise_free_pair(rng, R_true, np.array([0.1, 0.0, -1.0]), 200)
    curr = curr + rng.normal(0, 0.5, curr.shape)
    curr[:, 3] = curr[:, 1]
    curr[:20] = curr[rng.permutation(20)]  # 10 % mismatched: the bound falls below one batch at once
    refitting = dict(polish_iterations=2, local_refit=True, refine=True)  # msac's paper recipe has no local refit
    ends_at_once = estimate_motion(prev, curr, CAMERA, method="msac", rng=0, **refitting)
    # one first batch of first_batch_size (16) hypotheses, not batch_size (128): the bound is met
    assert ends_at_once.n_hypotheses == 16 and ends_at_once.report.n_local_optimizations == 0
    assert estimate_motion(prev, curr, CAMERA, method="msac", rng=0, **refitting, first_batch_size=32).n_hypotheses == 32
    assert estimate_motion(prev, curr, CAMERA, method="msac", rng=0, **refitting, budget=40).n_hypotheses == 40
    assert np.degrees(rotation_error(ends_at_once.rotation, R_true)) < 0.1  # the refinement did its work
    searching = estimate_motion(prev, curr, CAMERA, method="msac", rng=0, **refitting, batch_size=1)
    assert searching.report.n_local_optimizations >= 1  # new bests before the last batch are refit
    lo = estimate_motion(prev, curr, CAMERA, method="lo-ransac", rng=0)
    assert lo.report.n_local_optimizations >= 1
    assert ends_at_once.ok and searching.ok and lo.ok

def test_adaptive_batches_double_from_the_first_up_to_batch_size():
    from stereovo.estimation.loop import run_ransac
    from stereovo.estimation.estimator_options import EstimatorOptions
    from stereovo.estimation.registry import method_spec

    class BatchRecorder:
        def __init__(self):
            self.drawn = []

        def on_new_best(self, inliers, state):
            pass

        def on_batch(self, state):
            self.drawn.append(state.n_hypotheses)

    rng = np.random.default_rng(2)
    prev, _ = noise_free_pair(rng, np.eye(3), np.zeros(3), 60)
    curr, _ = noise_free_pair(rng, np.eye(3), np.zeros(3), 60)  # unrelated points: no consensus ends the search
    problem = StereoProblem.build(prev, curr, CAMERA)
    drawn = {}
    for batch_size, budget in ((128, None), (128, 300), (8, None)):
        options = EstimatorOptions(max_iterations=300, batch_size=batch_size, budget=budget)
        components = method_spec("msac").build(problem, options, None, None, {})
        recorder = BatchRecorder()
        components.listeners.append(recorder)
        run_ransac(problem, components, np.random.default_rng(0))
        drawn[batch_size, budget] = recorder.drawn
    assert drawn[128, None] == [16, 48, 112, 240, 300]  # 16, 32, 64, 128, then what the cap leaves
    assert drawn[128, 300] == [128, 256, 300]  # a fixed budget keeps batch_size throughout
    assert drawn[8, None] == list(range(8, 301, 8)) + [300]  # batch_size caps the first batch too


def test_new_best_inliers_come_from_the_batch_scores_exactly():
    """Scoring caps residuals at the gate; the inlier mask read from the capped batch residuals
    must equal the one from the hypothesis' own residuals."""
    from stereovo.estimation.roles.scoring import InlierCount, MahalanobisResidual
    from stereovo.estimation.roles.solvers import minimal_hypotheses
    from stereovo.estimation.roles.verification import ScoringContext
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=300, outlier_ratio=0.5), np.random.default_rng(3))
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    samples = np.stack([np.random.default_rng(i).choice(problem.n, 3, replace=False) for i in range(40)])
    R, t, valid = minimal_hypotheses(problem, samples)
    R, t = R[valid], t[valid]
    ctx = ScoringContext(problem, MahalanobisResidual(7.81), InlierCount(), 7.81)
    scores = ctx.score(R, t)
    for i in range(len(R)):
        reused, computed = ctx.inliers_of(R, t, i)
        assert not computed
        np.testing.assert_array_equal(reused, ctx.residuals(R[i : i + 1], t[i : i + 1])[0] < 7.81)
        assert reused.sum() == scores[i]
    fresh, computed = ctx.inliers_of(R.copy(), t, 0)  # another batch: computed afresh
    assert computed and fresh.sum() == scores[0]


def _pairwise_rigidity_reference(problem, samples):
    """Largest squared standardised change of a sample's three pairwise distances (numpy)."""
    worst = np.zeros(len(samples))
    for a, b in ((0, 1), (0, 2), (1, 2)):
        dX = problem.points_prev[samples[:, a]] - problem.points_prev[samples[:, b]]
        dY = problem.points_curr[samples[:, a]] - problem.points_curr[samples[:, b]]
        lX, lY = np.linalg.norm(dX, axis=1), np.linalg.norm(dY, axis=1)
        uX, uY = dX / lX[:, None], dY / lY[:, None]
        var = np.einsum("hi,hij,hj->h", uX, problem.cov_prev[samples[:, a]] + problem.cov_prev[samples[:, b]], uX)
        var += np.einsum("hi,hij,hj->h", uY, problem.cov_curr[samples[:, a]] + problem.cov_curr[samples[:, b]], uY)
        worst = np.maximum(worst, (lY - lX) ** 2 / var)
    return worst


def test_rigidity_check_keeps_inlier_triplets_and_drops_most_with_an_outlier():
    from scipy.stats import chi2

    from stereovo.estimation.roles.sample_check import RigidityCheck
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=400, outlier_ratio=0.6), np.random.default_rng(2))
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    rng = np.random.default_rng(0)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(6000)])
    check = RigidityCheck(chi2.ppf(0.999, 1))
    keep = check.accept(problem, samples)
    np.testing.assert_array_equal(keep, _pairwise_rigidity_reference(problem, samples) <= check.threshold_sq)
    all_inlier = frame.truth.inlier[samples].all(axis=1)
    assert all_inlier.sum() > 300
    assert keep[all_inlier].mean() > 0.99  # three tests at 0.999 each
    assert keep[~all_inlier].mean() < 0.3  # an outlier breaks two of the three distances


def test_probabilistic_fits_only_rigid_samples_and_still_finds_the_motion():
    from stereovo.simulation import SimulationConfig, simulate_frame

    # random mismatches only: a moving object's rigid cluster may win at eps 0.8 with or without the check
    config = SimulationConfig(n_correspondences=300, outlier_ratio=0.8, outlier_mix=(1.0, 0.0, 0.0))
    frame = simulate_frame(config, np.random.default_rng(4))
    kwargs = dict(rng=0, noise_sigma=frame.noise_sigma)
    checked = estimate_motion(frame.prev, frame.curr, frame.camera, **kwargs)
    unchecked = estimate_motion(frame.prev, frame.curr, frame.camera, rigidity_gate_probability=None, **kwargs)
    for est in (checked, unchecked):
        assert est.ok
        assert np.degrees(rotation_error(est.rotation, frame.truth.rotation)) < 0.2
        assert np.linalg.norm(est.translation - frame.truth.translation) < 0.05
    report = checked.report
    assert report.n_rejected_samples > 0.6 * checked.n_hypotheses
    assert report.n_scored + report.n_degenerate + report.n_rejected_samples == checked.n_hypotheses
    assert unchecked.report.n_rejected_samples == 0
    assert unchecked.report.n_scored + unchecked.report.n_degenerate == unchecked.n_hypotheses
    # Frames where no triplet is rigid fail with a reason, without raising.
    rng = np.random.default_rng(1)
    shuffled = frame.curr[rng.permutation(frame.n)]
    est = estimate_motion(frame.prev, shuffled, frame.camera, budget=20, **kwargs)
    assert not est.ok and est.status.startswith("failed: ")


def test_priors_and_order_reach_the_sampler():
    # Only the first 20 correspondences are correct; priors or an order naming them
    # finds the motion within the first batch, uniform sampling at 90 % outliers rarely does.
    rng = np.random.default_rng(6)
    t = np.array([0.0, 0.0, -1.0])
    prev, curr = noise_free_pair(rng, np.eye(3), t, 200)
    curr[20:] = curr[20:][rng.permutation(180)]
    priors = np.r_[np.ones(20), np.zeros(180)]
    guided = estimate_motion(prev, curr, CAMERA, priors=priors, budget=8, batch_size=8, rng=0)
    prosac = estimate_motion(prev, curr, CAMERA, order=np.arange(200), budget=1, batch_size=1, rng=0)
    assert guided.ok and np.linalg.norm(guided.translation - t) < 1e-6
    assert prosac.ok and np.linalg.norm(prosac.translation - t) < 1e-6
    assert guided.inliers[:20].all()


def test_symmetric_reprojection_jacobian_matches_finite_differences():
    from stereovo.estimation.roles.reprojection import residuals_and_jacobians

    rng = np.random.default_rng(3)
    R_true, t_true = se3_exp(np.array([0.1, -0.05, 0.8, 0.02, -0.03, 0.01]))
    prev, curr = noise_free_pair(rng, R_true, t_true, n=20)
    problem = StereoProblem.build(prev, curr, CAMERA)
    R0, t0 = se3_exp(rng.normal(scale=0.02, size=6))
    R0, t0 = R0 @ R_true, R0 @ t_true + t0
    args = (problem.points_prev, problem.points_curr, problem.prev, problem.curr)
    res, jac = residuals_and_jacobians(CAMERA, R0[None], t0[None], *args)
    assert res.shape == (1, 20, 8) and jac.shape == (1, 20, 8, 6)
    numeric = np.empty_like(jac)
    h = 1e-6
    for k in range(6):
        step = np.zeros(6)
        step[k] = h
        dR_p, dt_p = se3_exp(step)
        dR_m, dt_m = se3_exp(-step)
        plus, _ = residuals_and_jacobians(CAMERA, (dR_p @ R0)[None], (dR_p @ t0 + dt_p)[None], *args, with_jacobian=False)
        minus, _ = residuals_and_jacobians(CAMERA, (dR_m @ R0)[None], (dR_m @ t0 + dt_m)[None], *args, with_jacobian=False)
        numeric[..., k] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(jac, numeric, rtol=1e-4, atol=1e-3)



@pytest.mark.parametrize("huber", [None, 2.0])
def test_gauss_newton_step_solves_the_normal_equations_of_the_jacobian_rows(huber):
    # The LM kernel sums J^T W J from each side's 3x3 terms rather than the 8 x 6 rows: one
    # plain Gauss-Newton step must equal the step computed here from the rows themselves.
    from stereovo.estimation.roles.reprojection import gauss_newton_steps, residuals_and_jacobians

    rng = np.random.default_rng(8)
    R_true, t_true = se3_exp(np.array([0.3, -0.1, 1.2, 0.03, -0.02, 0.05]))
    prev, curr = noise_free_pair(rng, R_true, t_true, n=60)
    curr = curr + rng.normal(0, 1.0, curr.shape)
    problem = StereoProblem.build(prev, curr, CAMERA)
    dR, dt = se3_exp(rng.normal(scale=0.01, size=6))
    R0, t0 = dR @ R_true, dR @ t_true + dt
    weights = rng.uniform(0.2, 1.0, 60) * (rng.random(60) > 0.3)
    args = (problem.points_prev, problem.points_curr, problem.prev, problem.curr)
    res, jac = residuals_and_jacobians(CAMERA, R0[None], t0[None], *args)
    res, jac = res[0], jac[0]
    w = weights.copy()
    if huber is not None:
        norm = np.linalg.norm(res, axis=1)
        w[norm > huber] *= huber / norm[norm > huber]
    A = np.einsum("m,mri,mrj->ij", w, jac, jac)
    g = np.einsum("m,mri,mr->i", w, jac, res)
    delta = -np.linalg.solve(A + 1e-9 * np.diag(np.diag(A)), g)
    dR_ref, dt_ref = se3_exp(delta)
    R, t, _ = gauss_newton_steps(
        CAMERA, R0[None], t0[None], *args, weights=weights, iterations=1, damping=1e-9, huber=huber, step_control=False
    )
    np.testing.assert_allclose(R[0], dR_ref @ R0, atol=1e-12)
    np.testing.assert_allclose(t[0], dR_ref @ t0 + dt_ref, atol=1e-10)

def test_gauss_newton_refinement_reaches_the_noise_free_motion():
    from stereovo.estimation.roles.reprojection import gauss_newton_steps

    rng = np.random.default_rng(4)
    R_true, t_true = se3_exp(np.array([-0.2, 0.05, 1.1, 0.01, 0.04, -0.02]))
    prev, curr = noise_free_pair(rng, R_true, t_true, n=60)
    problem = StereoProblem.build(prev, curr, CAMERA)
    dR, dt = se3_exp(np.array([0.05, -0.05, 0.1, 0.01, -0.01, 0.02]))
    R, t, cost = gauss_newton_steps(
        CAMERA, (dR @ R_true)[None], (dR @ t_true + dt)[None],
        problem.points_prev, problem.points_curr, problem.prev, problem.curr, iterations=20,
    )
    assert rotation_error(R[0], R_true) < 1e-9
    assert np.linalg.norm(t[0] - t_true) < 1e-9
    assert cost[0] < 1e-12


@pytest.mark.parametrize(
    "priors",
    [np.array([0.0, 0.0, 1e-300, 1.0, 1.0, 0.0]), np.array([1e12, 1.0, 1e-12, 0.0, 3.0]), np.array([0.0, 1.0, 1.0, 1.0])],
)
def test_weighted_sampler_draws_three_distinct_positive_weight_indices_under_extreme_priors(priors):
    draws = WeightedSampler(priors).draw(5000, np.random.default_rng(1))
    assert draws.shape == (5000, 3)
    assert np.all(priors[draws] > 0)
    assert np.all((draws[:, 0] != draws[:, 1]) & (draws[:, 0] != draws[:, 2]) & (draws[:, 1] != draws[:, 2]))


def test_weighted_sampler_fix_up_path_draws_distinct_positive_indices():
    # The vectorised draw hands rows that rounding pushed past the last interval to this exact path.
    sampler = WeightedSampler(np.array([0.0, 2.0, 1.0, 1.0, 0.0]))
    top = 1.0 - 2.0**-53  # the largest value Generator.random() returns
    for u in (np.array([top, top, top]), np.array([0.0, 0.0, 0.0]), np.array([0.5, top, 0.0])):
        picked = sampler._draw_exactly(u)
        assert len(set(picked.tolist())) == 3 and set(picked.tolist()) <= {1, 2, 3}
    assert sampler._draw_exactly(np.array([0.0, 0.0, 0.0])).tolist() == [1, 2, 3]


def test_compiled_weighted_draw_inverts_the_cut_cumulative_weights_like_searchsorted():
    """The compiled draw against the same inversion written with numpy's searchsorted."""
    from stereovo.estimation.kernels.sampling import weighted_triplets

    rng = np.random.default_rng(2)
    for trial in range(60):
        n = int(rng.integers(3, 400))
        priors = rng.random(n) if trial % 3 else np.exp(8.0 * rng.normal(size=n))
        priors[rng.random(n) < 0.3 * (trial % 2)] = 0.0
        priors[:3] += 1.0
        w = priors / priors.sum()
        cdf = np.cumsum(w)
        before = np.concatenate([[0.0], cdf[:-1]])
        total = cdf[-1]
        u = rng.random((256, 3))

        def invert(mass):
            return np.minimum(np.searchsorted(cdf, mass, side="right"), n - 1)

        a = invert(u[:, 0] * total)
        x = u[:, 1] * (total - w[a])
        b = invert(np.where(x < before[a], x, x + w[a]))
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        x = u[:, 2] * (total - w[a] - w[b])
        x = np.where(x < before[lo], x, x + w[lo])
        c = invert(np.where(x < before[hi], x, x + w[hi]))
        samples, suspect = weighted_triplets(u, w, cdf, before)
        np.testing.assert_array_equal(samples, np.stack([a, b, c], axis=1))
        expected = (b == a) | (c == a) | (c == b) | (w[a] == 0) | (w[b] == 0) | (w[c] == 0)
        np.testing.assert_array_equal(suspect, expected)


@pytest.mark.parametrize("gate", [None, "pixel"])
def test_refinement_returns_the_residuals_that_selected_its_inliers(gate):
    from stereovo.estimation.roles.refinement import ReprojectionRefiner
    from stereovo.estimation.roles.scoring import PixelMahalanobisResidual, ReprojectionResidual
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=300, outlier_ratio=0.4), np.random.default_rng(5))
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    model, threshold = ReprojectionResidual(), 9.0
    refiner = ReprojectionRefiner(iterations=3, rounds=2)
    if gate == "pixel":
        refiner = ReprojectionRefiner(iterations=3, rounds=2, gate=(PixelMahalanobisResidual(), 13.28))
        model_used, threshold_used = refiner.gate
    else:
        model_used, threshold_used = model, threshold
    R0, t0 = frame.truth.rotation @ se3_exp(np.full(6, 3e-4))[0], frame.truth.translation + 0.002
    start = model.squared(problem, R0[None], t0[None])[0] < threshold
    R, t, inliers, residual_sq = refiner.refine_with_residuals(problem, R0, t0, start, model, threshold)
    np.testing.assert_array_equal(inliers, model_used.squared(problem, R[None], t[None])[0] < threshold_used)
    if gate is None:  # the caller's own model: residuals come back for it to score with
        np.testing.assert_array_equal(residual_sq, model.squared(problem, R[None], t[None])[0])
    else:  # inliers chosen by the refiner's own gate: the caller's model was never evaluated
        assert residual_sq is None
    assert rotation_error(R, frame.truth.rotation) < rotation_error(R0, frame.truth.rotation)
    plain = refiner.refine(problem, R0, t0, start, model, threshold)
    for a, b in zip(plain, (R, t, inliers)):
        np.testing.assert_array_equal(a, b)
    # Too few inliers to refit: the motion comes back as given, with no residuals of it.
    few = np.zeros(problem.n, dtype=bool)
    few[:2] = True
    R2, t2, _, none = ReprojectionRefiner(rounds=2).refine_with_residuals(problem, R0, t0, few, model, threshold)
    assert none is None and np.array_equal(R2, R0) and np.array_equal(t2, t0)


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


@pytest.mark.parametrize("gate_kind", ["reprojection", "mahalanobis", "pixel-gate", "huber"])
def test_compiled_refinement_rounds_equal_the_python_loop(gate_kind):
    """The compiled loop must reproduce the Python loop bit for bit (poses, inliers, residuals)."""
    from stereovo.estimation.roles.refinement import ReprojectionRefiner
    from stereovo.estimation.roles.scoring import (
        MahalanobisResidual,
        PixelMahalanobisResidual,
        ReprojectionResidual,
    )
    from stereovo.simulation import SimulationConfig, simulate_frame

    model, threshold = (MahalanobisResidual(), 7.81) if gate_kind == "mahalanobis" else (ReprojectionResidual(), 9.0)
    gate = (PixelMahalanobisResidual(), 13.28) if gate_kind == "pixel-gate" else None
    refiner = ReprojectionRefiner(iterations=6, rounds=3, gate=gate, huber_px=1.0 if gate_kind == "huber" else None)
    for seed in range(4):
        frame = simulate_frame(SimulationConfig(n_correspondences=250, outlier_ratio=0.5), np.random.default_rng(seed))
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
        R0 = frame.truth.rotation @ se3_exp(np.full(6, 2e-4 * (seed + 1)))[0]
        t0 = frame.truth.translation + 0.002 * seed
        start = model.squared(problem, R0[None], t0[None])[0] < threshold
        compiled = refiner._refine_compiled(problem, R0, t0, start, model, threshold)
        python = refiner._refine_in_python(problem, R0, t0, start, model, threshold)
        assert compiled[3] is not None
        for a, b in zip(compiled, python):
            np.testing.assert_array_equal(a, b)
        assert compiled[2].sum() > 0.9 * start.sum()


@pytest.mark.parametrize("method", ["waldsac", "r-ransac", "inlier-detection"])
def test_estimate_exposes_the_methods_counters(method):
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=300, outlier_ratio=0.5), rng=6)
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=0)
    assert est.counters and est.counters == est.report.counters
    assert all(isinstance(v, (int, float)) for v in est.counters.values())
    assert estimate_motion(frame.prev[:2], frame.curr[:2], frame.camera, method=method).counters == {}
