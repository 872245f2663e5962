"""Residual models and scores (stereovo/estimation/roles/scoring.py): the 3D and pixel Mahalanobis
residuals against explicit formulas, and the calibration of their gates in every depth band."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from stereovo import StereoCamera
from stereovo.estimation import StereoProblem
from stereovo.estimation.roles.scoring import (
    MahalanobisResidual,
    PixelMahalanobisResidual,
    InlierCount,
    ReprojectionResidual,
    TruncatedQuadratic,
    squared_and_exact,
)
from stereovo.geometry import random_rotation
from stereovo.simulation import SimulationConfig, simulate_frame
from tests.support.frames import CAMERA, noise_free_pair


PROBABILITIES = (0.9, 0.95, 0.99)
BANDS_M = ((3.0, 15.0), (15.0, 30.0), (30.0, 45.0), (45.0, 60.0))
FRAMES = 24  # about 12,000 true inliers, ~1400 in the far band


@pytest.fixture(scope="module")
def true_motion_distances():
    """Squared 3-D and pixel Mahalanobis distances of every true inlier under its frame's true
    motion, and the inliers' depths (the mean of the two frames' triangulated depths)."""
    d3, dpix, depth = [], [], []
    for seed in range(FRAMES):
        frame = simulate_frame(SimulationConfig(n_correspondences=500, outlier_ratio=0.0), rng=1000 + seed)
        inl = frame.truth.inlier
        problem = StereoProblem.build(frame.prev[inl], frame.curr[inl], frame.camera, frame.noise_sigma)
        R, t = frame.truth.rotation[None], frame.truth.translation[None]
        d3.append(MahalanobisResidual().squared(problem, R, t)[0])
        dpix.append(PixelMahalanobisResidual().squared(problem, R, t)[0])
        depth.append(0.5 * (problem.points_prev[:, 2] + problem.points_curr[:, 2]))
    return np.concatenate(d3), np.concatenate(dpix), np.concatenate(depth)


def _check_gate(d2: np.ndarray, depth: np.ndarray, dof: int) -> None:
    assert d2.size >= 2000
    for p in PROBABILITIES:
        passed = d2 < chi2.ppf(p, dof)
        assert abs(passed.mean() - p) <= 0.01, f"chi2({dof}) gate p={p}: overall pass {passed.mean():.4f}"
        for lo, hi in BANDS_M:
            band = (depth >= lo) & (depth < hi)
            assert band.sum() >= 300
            rate = passed[band].mean()
            assert abs(rate - p) <= 0.03, f"chi2({dof}) gate p={p}, {lo:g}-{hi:g} m: pass {rate:.4f}"


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


def test_3d_mahalanobis_gate_is_calibrated_in_every_depth_band(true_motion_distances):
    d3, _, depth = true_motion_distances
    _check_gate(d3, depth, 3)


def test_pixel_mahalanobis_gate_is_calibrated_in_every_depth_band(true_motion_distances):
    _, dpix, depth = true_motion_distances
    assert StereoCamera().measurement_dof == 3
    _check_gate(dpix, depth, 3)


def test_independent_v_model_is_miscalibrated_on_rectified_matches():
    """The old model (vL and vR as two measurements) halves the v variance: on the simulator's
    rectified matches its 3-D gate passes clearly fewer than p (it passed ~0.89 at 0.95)."""
    frame = simulate_frame(SimulationConfig(n_correspondences=500, outlier_ratio=0.0), rng=5)
    inl = frame.truth.inlier
    old = StereoCamera(v_measurement="independent")
    problem = StereoProblem.build(frame.prev[inl], frame.curr[inl], old, frame.noise_sigma)
    d2 = MahalanobisResidual().squared(problem, frame.truth.rotation[None], frame.truth.translation[None])[0]
    assert np.mean(d2 < chi2.ppf(0.95, 3)) < 0.93
    assert old.measurement_dof == 4


def test_v_measurement_option_is_validated_by_name():
    with pytest.raises(ValueError, match=r"v_measurement.*'both'"):
        StereoCamera(v_measurement="both")
    assert StereoCamera().v_measurement == "shared"


# --- Inlier counts and residual models: strict gates, double precision, capped and exact residuals ---


def test_inlier_count_is_strictly_under_the_gate_and_a_float_score():
    residual_sq = np.array([[8.99, 9.0, 9.01, 0.0], [9.0, 9.0, 9.0, 9.0]])
    score = InlierCount().score(residual_sq, 9.0)
    # A residual capped at the gate comes back as exactly T^2 (ResidualModel.squared): not an inlier.
    assert score.tolist() == [2.0, 0.0]
    assert score.dtype == np.float64


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_inlier_count_counts_strictly_under_the_gate_for_one_hypothesis_or_a_batch(dtype):
    """A batch of float64 residuals is counted compiled, anything else by numpy: the same counts,
    one float64 per hypothesis (a 0-d one for a single row of residuals)."""
    rows = np.array([[8.99, 9.0, 9.01, 0.0, np.inf, np.nan], [9.0] * 6, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]], dtype=dtype)
    batch = InlierCount().score(rows, 9.0)
    assert batch.shape == (3,) and batch.dtype == np.float64 and batch.tolist() == [2.0, 0.0, 6.0]
    for row, expected in zip(rows, [2.0, 0.0, 6.0]):
        one = InlierCount().score(row, 9.0)
        assert np.shape(one) == () and np.asarray(one).dtype == np.float64 and one == expected


def test_inlier_count_of_float32_residuals_compares_in_float32_as_numpy_does():
    gate = 7.814727903251178  # chi-square(3) at 0.95, not a float32
    at_gate = np.float32(gate)  # the float32 nearest the gate, a little below it
    assert float(at_gate) < gate
    residual_sq = np.array([[at_gate, 1.0]], dtype=np.float32)
    assert InlierCount().score(residual_sq, gate).tolist() == [1.0]  # at the gate in float32: not an inlier


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
    # Single-precision motions are the same motions read exactly in float64, with a cap or without.
    for cap in (None, model.threshold_sq):
        expected = model.squared(problem, R32.astype(np.float64), t32.astype(np.float64), cap=cap)
        np.testing.assert_array_equal(model.squared(problem, R32, t32, cap=cap), expected)
    if hasattr(model, "squared_and_exact"):
        both = model.squared_and_exact(problem, R32.astype(np.float64), t32.astype(np.float64), model.threshold_sq)
        for got, want in zip(model.squared_and_exact(problem, R32, t32, model.threshold_sq), both):
            np.testing.assert_array_equal(got, want)


class _CallLog:
    """A residual model that forwards to ``inner`` and records each call's cap; ``bounds_at_cap``
    copied from ``inner`` unless ``declare`` is False (a model that says nothing about caps)."""

    def __init__(self, inner, declare=True):
        self.inner, self.caps = inner, []
        self.name, self.threshold_sq = inner.name, inner.threshold_sq
        if declare:
            self.bounds_at_cap = inner.bounds_at_cap

    def squared(self, problem, R, t, cap=None):
        self.caps.append(cap)
        return self.inner.squared(problem, R, t, cap=cap)


def _problem_and_motions():
    frame = simulate_frame(SimulationConfig(n_correspondences=60, outlier_ratio=0.5, outliers="hostile"), 8)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    rng = np.random.default_rng(2)
    R = np.stack([random_rotation(rng, np.radians(a)) @ frame.truth.rotation for a in (0.0, 3.0, 40.0)])
    t = frame.truth.translation + rng.normal(0.0, 0.5, (3, 3))
    return problem, R, t


@pytest.mark.parametrize("model", [ReprojectionResidual(), PixelMahalanobisResidual()], ids=lambda m: m.name)
def test_a_model_that_ignores_the_cap_is_computed_once_for_both(model):
    problem, R, t = _problem_and_motions()
    log = _CallLog(model)
    scored, exact = squared_and_exact(log, problem, R, t, model.threshold_sq)
    assert log.caps == [model.threshold_sq] and scored is exact
    np.testing.assert_array_equal(exact, model.squared(problem, R, t))


def test_the_mahalanobis_model_fills_capped_and_exact_in_one_pass_bit_for_bit():
    problem, R, t = _problem_and_motions()
    model = MahalanobisResidual()
    scored, exact = squared_and_exact(model, problem, R, t, model.threshold_sq)
    np.testing.assert_array_equal(scored, model.squared(problem, R, t, cap=model.threshold_sq))
    np.testing.assert_array_equal(exact, model.squared(problem, R, t))
    assert np.any(scored != exact)  # the cap bounded some distances


def test_a_model_that_says_nothing_about_caps_is_called_twice_and_once_without_a_cap():
    problem, R, t = _problem_and_motions()
    log = _CallLog(MahalanobisResidual(), declare=False)
    scored, exact = squared_and_exact(log, problem, R, t, 7.8)
    assert log.caps == [7.8, None]
    np.testing.assert_array_equal(exact, MahalanobisResidual().squared(problem, R, t))
    log.caps.clear()
    scored, exact = squared_and_exact(log, problem, R, t, None)
    assert log.caps == [None] and scored is exact
