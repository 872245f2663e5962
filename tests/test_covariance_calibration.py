"""Covariances are calibrated: chi-square gates pass their probability of the true inliers.

Under the true motion, on a few thousand true inliers of the simulator (which measures one
``v`` per rectified match, DESIGN section 4), the 3-D Mahalanobis gate (chi-square(3)) and the
pixel Mahalanobis gate (chi-square with ``camera.measurement_dof`` = 3 degrees of freedom)
must pass p +- 0.01 overall and p +- 0.03 in every depth band. Also: the triangulation
Jacobian against finite differences, and the option that selects the measurement model.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from stereovo.camera import StereoCamera
from stereovo.estimation import StereoProblem
from stereovo.estimation.roles.scoring import MahalanobisResidual, PixelMahalanobisResidual
from stereovo.simulation import SimulationConfig, simulate_frame

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


def _triangulate(cam: StereoCamera, uL: float, uR: float, v: float) -> np.ndarray:
    return cam.triangulate(np.array([[uL, v, uR, v]]))[0]


@pytest.mark.parametrize("row", [(900.0, 880.0, 300.0), (100.0, 97.5, 20.0), (607.19, 606.0, 185.22), (1200.0, 1000.0, 50.0)])
def test_triangulation_jacobian_matches_finite_differences(row):
    cam = StereoCamera()
    uL, uR, v = row
    meas = np.array([[uL, v, uR, v]])
    J = cam.shared_triangulation_jacobian(meas)[0]
    h = 1e-5
    numeric = np.empty((3, 3))
    for j, step in enumerate(np.eye(3) * h):
        plus = _triangulate(cam, uL + step[0], uR + step[1], v + step[2])
        minus = _triangulate(cam, uL - step[0], uR - step[1], v - step[2])
        numeric[:, j] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(J, numeric, rtol=1e-6, atol=1e-9)
    J4 = cam.triangulation_jacobian(meas)[0]
    numeric4 = np.empty((3, 4))
    for j, step in enumerate(np.eye(4) * h):
        numeric4[:, j] = (cam.triangulate(meas + step)[0] - cam.triangulate(meas - step)[0]) / (2 * h)
    np.testing.assert_allclose(J4, numeric4, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("model", ["shared", "independent"])
def test_covariance_is_sigma_squared_j_j_transpose_of_the_measured_quantities(model):
    cam = StereoCamera(v_measurement=model)
    meas = np.array([[900.0, 300.0, 880.0, 300.0], [100.0, 20.0, 97.5, 20.0], [650.0, 100.0, 640.0, 100.0]])
    sigma = 0.7
    J = cam.measurement_jacobian(meas)
    assert J.shape == (3, 3, 3 if model == "shared" else 4)
    np.testing.assert_allclose(cam.triangulation_covariance(meas, sigma), sigma**2 * J @ np.swapaxes(J, 1, 2), rtol=1e-12)
    # the models differ only in the y variance from v: one v (variance sigma^2) or the mean of two (sigma^2 / 2)
    other = StereoCamera(v_measurement="independent" if model == "shared" else "shared")
    diff = cam.triangulation_covariance(meas, sigma) - other.triangulation_covariance(meas, sigma)
    depth = cam.triangulate(meas)[:, 2]
    expected = (0.5 if model == "shared" else -0.5) * (sigma * depth / cam.fy) ** 2
    np.testing.assert_allclose(diff[:, 1, 1], expected, rtol=1e-9)
    diff[:, 1, 1] = 0.0
    np.testing.assert_allclose(diff, 0.0, atol=1e-15)


def test_v_measurement_option_is_validated_by_name():
    with pytest.raises(ValueError, match=r"v_measurement.*'both'"):
        StereoCamera(v_measurement="both")
    assert StereoCamera().v_measurement == "shared"
