"""The compiled Mahalanobis kernels (stereovo/estimation/kernels/mahalanobis.py): the batch scorer's
branch-free point distance against the branching one the compiled SPRT scans with, bit for bit, and
the pixel distance of a point behind the camera, and the capped and exact distances from one pass."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation.kernels.mahalanobis import (
    mahalanobis_sq,
    mahalanobis_sq_and_exact,
    pixel_mahalanobis_sq,
    point_mahalanobis_sq,
)
from stereovo.estimation.problem import StereoProblem
from stereovo.geometry import random_rotation
from stereovo.simulation import SimulationConfig, simulate_frame

CHI2_3_95 = 7.814727903251178


def usable_problem(n, eps, outliers, seed):
    frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=eps, outliers=outliers), seed)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    return frame, problem.usable_subproblem()[0]


def motions(frame, rng):
    """Near the truth, a little off, and absurd: big rotations, and translations that carry points
    behind the camera (p_z <= MIN_DEPTH) or the k point behind the k-1 camera (no fused depth)."""
    R, t = [frame.truth.rotation], [frame.truth.translation]
    for degrees, metres in ((0.2, 0.02, ), (5.0, 0.5), (120.0, 5.0), (179.0, 80.0)):
        for _ in range(4):
            R.append(random_rotation(rng, np.radians(degrees)) @ frame.truth.rotation)
            t.append(frame.truth.translation + rng.normal(0.0, metres, 3))
    R.append(np.eye(3))
    t.append(np.array([0.0, 0.0, -200.0]))  # every point behind the camera at k
    R.append(np.eye(3))
    t.append(np.array([0.0, 0.0, 200.0]))  # every k point behind the camera at k-1
    return np.ascontiguousarray(np.stack(R)), np.ascontiguousarray(np.stack(t))


def branching_sq(R, t, X, Y, cam, sigma_sq, cap):
    """``mahalanobis_sq`` point by point through :func:`point_mahalanobis_sq` (the SPRT's form)."""
    fx, fy, bl = cam[0], cam[1], cam[4]
    inv_fx, inv_fy, inv_fb = 1.0 / fx, 1.0 / fy, 1.0 / (fx * bl)
    v_variance = 1.0 / cam[5]
    c_lateral = 2.0 * inv_fx * inv_fx + v_variance * inv_fy * inv_fy
    c_depth = 3.0 * inv_fb * inv_fb
    out = np.empty((R.shape[0], X.shape[0]))
    for h in range(R.shape[0]):
        r, tt = R[h], t[h]
        norm_t = np.sqrt(tt[0] * tt[0] + tt[1] * tt[1] + tt[2] * tt[2])
        for n in range(X.shape[0]):
            x, y = X[n], Y[n]
            out[h, n] = point_mahalanobis_sq(
                *r.ravel(), *tt, norm_t, *x, *y, 1.0 / y[2],
                np.sqrt(x[0] ** 2 + x[1] ** 2 + x[2] ** 2), np.sqrt(y[0] ** 2 + y[1] ** 2 + y[2] ** 2),
                inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq, cap,
            )
    return out


@pytest.mark.parametrize("outliers", ["default", "hostile"])
@pytest.mark.parametrize("cap", [0.0, CHI2_3_95, 1e-3, 1e6])
def test_batch_scorer_equals_the_branching_point_distance_bit_for_bit(outliers, cap):
    frame, problem = usable_problem(60, 0.5, outliers, 11)
    R, t = motions(frame, np.random.default_rng(5))
    args = (problem.points_prev, problem.points_curr, problem.camera.parameters, problem.noise_sigma**2, cap)
    got = mahalanobis_sq(R, t, *args)
    expected = branching_sq(R, t, *args)
    np.testing.assert_array_equal(got, expected)
    assert np.isinf(got[-2]).all()  # behind the camera: inf, whatever the cap
    if cap == CHI2_3_95:
        # every branch was taken somewhere: the norm bound, the trace bound and the full distance
        assert np.any(got < cap) and np.any(got >= cap)
        assert np.any(np.isfinite(got) & (got >= cap))


@pytest.mark.parametrize("outliers", ["default", "hostile"])
@pytest.mark.parametrize("cap", [CHI2_3_95, 1e-3, 0.0])
def test_one_pass_gives_the_capped_and_the_exact_distances_bit_for_bit(outliers, cap):
    frame, problem = usable_problem(60, 0.8, outliers, 3)
    R, t = motions(frame, np.random.default_rng(9))
    args = (problem.points_prev, problem.points_curr, problem.camera.parameters, problem.noise_sigma**2)
    capped, exact = mahalanobis_sq_and_exact(R, t, *args, cap)
    np.testing.assert_array_equal(capped, mahalanobis_sq(R, t, *args, cap))
    np.testing.assert_array_equal(exact, mahalanobis_sq(R, t, *args, 0.0))
    if cap == CHI2_3_95:
        # the cap bounded some distances, so the two outputs are not one array read twice
        assert np.any(capped != exact)
        assert np.array_equal(capped < cap, exact < cap)


def test_pixel_distance_is_inf_behind_the_camera_and_finite_elsewhere():
    frame, problem = usable_problem(40, 0.2, "default", 2)
    R, t = motions(frame, np.random.default_rng(1))
    sq = pixel_mahalanobis_sq(R, t, problem.points_prev, problem.cov_prev, problem.curr,
                              problem.camera.parameters, problem.noise_sigma**2)
    P = np.einsum("hij,nj->hni", R, problem.points_prev) + t[:, None, :]
    behind = P[..., 2] <= 1e-3
    assert behind.any() and (~behind).any()
    assert np.isinf(sq[behind]).all()
    assert np.isfinite(sq[~behind]).all()
