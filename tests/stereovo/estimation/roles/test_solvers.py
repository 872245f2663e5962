"""The minimal solvers (stereovo/estimation/roles/solvers.py): the closed-form fit and degenerate triplets."""

import numpy as np
import pytest

from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.solvers import degenerate_triplets, kabsch_batch
from stereovo.geometry import random_rotation
from tests.support.frames import CAMERA, noise_free_pair


def _svd_kabsch(X: np.ndarray, Y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference weighted Kabsch/Umeyama: SVD of the cross-covariance with the det(R) = +1 fix."""
    w = w / w.sum()
    mx, my = w @ X, w @ Y
    U, _, Vt = np.linalg.svd(((Y - my) * w[:, None]).T @ (X - mx))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return R, my - R @ mx


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
        np.testing.assert_allclose(t3[h], t_ref, atol=1e-8)


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
