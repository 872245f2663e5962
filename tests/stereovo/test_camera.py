"""StereoCamera: projection, triangulation and their Jacobians, validity, and measurement covariances."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, strategies as st

from stereovo.camera import StereoCamera


def random_visible_points(camera, rng, n=200):
    X = np.c_[rng.uniform(-30, 30, n * 4), rng.uniform(-5, 5, n * 4), rng.uniform(2, 80, n * 4)]
    return X[camera.is_visible(X, z_min=2, z_max=80)][:n]


def _triangulate(cam: StereoCamera, uL: float, uR: float, v: float) -> np.ndarray:
    return cam.triangulate(np.array([[uL, v, uR, v]]))[0]


@given(st.integers(0, 2**32 - 1))
def test_projection_and_triangulation_invert_each_other(seed):
    camera = StereoCamera()
    rng = np.random.default_rng(seed)
    X = random_visible_points(camera, rng)
    z = camera.project(X)
    np.testing.assert_allclose(camera.triangulate(z), X, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(camera.project(camera.triangulate(z)), z, atol=1e-9)
    assert np.all(z[:, 1] == z[:, 3])


def test_default_is_kitti_like(camera):
    assert (camera.fx, camera.fy, camera.cx, camera.cy, camera.baseline) == (718.856, 718.856, 607.19, 185.22, 0.5372)
    assert (camera.width, camera.height) == (1241, 376)


def test_triangulation_jacobian_matches_finite_differences(camera):
    rng = np.random.default_rng(3)
    z = camera.project(random_visible_points(camera, rng, 20))
    J = camera.triangulation_jacobian(z)
    h = 1e-6
    for k in range(4):
        dz = np.zeros(4)
        dz[k] = h
        fd = (camera.triangulate(z + dz) - camera.triangulate(z - dz)) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, rtol=1e-5, atol=1e-8)
    # dy/dv is b/(2d) when fx = fy (a public re-implementation had b/(2d^2)).
    d = camera.disparity(z)
    np.testing.assert_allclose(J[:, 1, 1], camera.baseline / (2 * d), rtol=1e-12)


def test_covariance_is_sigma2_JJt_and_depth_error_grows_quadratically(camera):
    X = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, 10.0], [0.0, 0.0, 40.0]])
    z = camera.project(X)
    cov = camera.triangulation_covariance(z, sigma=0.5)
    J = camera.measurement_jacobian(z)  # over (uL, uR, v): one v per rectified match
    assert J.shape == (3, 3, 3)
    np.testing.assert_allclose(cov, 0.25 * J @ J.transpose(0, 2, 1))
    J4 = StereoCamera(v_measurement="independent").triangulation_jacobian(z)
    np.testing.assert_allclose(StereoCamera(v_measurement="independent").triangulation_covariance(z, 0.5),
                               0.25 * J4 @ J4.transpose(0, 2, 1))
    depth_std = np.sqrt(cov[:, 2, 2])
    # sigma_z = z^2 / (fx b) * sqrt(2) sigma
    np.testing.assert_allclose(depth_std, X[:, 2] ** 2 / (camera.fx * camera.baseline) * np.sqrt(2) * 0.5, rtol=1e-12)


def test_triangulation_with_covariance_equals_the_two_separate_calls_at_any_shape(camera):
    rng = np.random.default_rng(2)
    X = np.column_stack([rng.uniform(-10, 10, 60), rng.uniform(-2, 2, 60), rng.uniform(3, 60, 60)])
    z = camera.project(X).reshape(3, 20, 4)
    points, cov = camera.triangulate_with_covariance(z, 0.7)
    assert points.shape == (3, 20, 3) and cov.shape == (3, 20, 3, 3)
    np.testing.assert_allclose(points, X.reshape(3, 20, 3), rtol=1e-12)
    J = camera.measurement_jacobian(z)
    np.testing.assert_allclose(cov, 0.49 * J @ np.swapaxes(J, -1, -2), rtol=1e-10)
    np.testing.assert_array_equal(cov, camera.triangulation_covariance(z, 0.7))
    z[1, 7, 2] = z[1, 7, 0]  # no disparity anywhere in the batch: refused, never divided by
    with pytest.raises(ValueError, match="1 measurement"):
        camera.triangulate_with_covariance(z, 0.7)


def test_triangulation_refuses_points_without_depth(camera):
    with pytest.raises(ValueError, match="disparity"):
        camera.triangulate(np.array([[600.0, 100.0, 600.0, 100.0]]))
    with pytest.raises(ValueError, match="sigma"):
        camera.triangulation_covariance(np.array([[600.0, 100.0, 590.0, 100.0]]), sigma=-1)


def test_visibility(camera):
    X = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, -10.0], [100.0, 0.0, 10.0], [0.0, 0.0, 1e6], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(camera.is_visible(X, z_min=2.0), [True, False, False, False, False])


@pytest.mark.parametrize("field,value", [("fx", 0.0), ("baseline", -0.5), ("width", 0), ("height", -1), ("cx", np.nan)])
def test_invalid_camera_names_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        StereoCamera(**{field: value})


def test_compiled_projection_of_point_rows_equals_the_array_expression():
    """(N, 3) inputs take a compiled path; other shapes the numpy one: both must agree bit for bit."""
    cam = StereoCamera()
    rng = np.random.default_rng(4)
    X = np.column_stack([rng.uniform(-20, 20, 1000), rng.uniform(-5, 5, 1000), rng.uniform(0.5, 80, 1000)])
    np.testing.assert_array_equal(cam.project(X), cam.project(X[None])[0])
    np.testing.assert_array_equal(cam.project(X[::2]), cam.project(X[None, ::2])[0])  # strided rows too
    np.testing.assert_array_equal(cam.project(X[:1]), cam.project(X[0])[None])


@pytest.mark.parametrize("row", [(900.0, 880.0, 300.0), (100.0, 97.5, 20.0), (607.19, 606.0, 185.22), (1200.0, 1000.0, 50.0)])
def test_shared_triangulation_jacobian_matches_finite_differences(row):
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


@pytest.mark.parametrize("field,value,text", [
    ("fx", 10**400, "~1e+400 (an integer of 401 digits)"), ("fx", "700", "'700'"), ("fx", [700], "[700]"),
    ("fx", True, "True"), ("min_disparity", None, "None"), ("baseline", math.inf, "inf"), ("cy", 10**400, "~1e+400 (an integer of 401 digits)"),
    ("width", 1.5, "1.5"), ("width", True, "True"), ("height", np.bool_(True), "np.True_"), ("height", 640.0, "640.0"),
    ("width", 2**53 + 1, "9007199254740993"), ("width", "640", "'640'"),
])
def test_invalid_camera_values_are_a_value_error_naming_field_and_value(field, value, text):
    """Never numpy's 'ufunc isfinite not supported' or a comparison's TypeError: the options contract's message."""
    with pytest.raises(ValueError, match=rf"^StereoCamera\.{field} must be .*, got {re.escape(text)}$"):
        StereoCamera(**{field: value})


def test_valid_edge_cameras_are_kept_as_given():
    cam = StereoCamera(fx=700, cx=-5.0, cy=0, width=1, height=np.int64(1), min_disparity=1e-12, fy=np.float32(650.0))
    assert cam.fx == 700 and type(cam.fx) is int and type(cam.height) is np.int64 and type(cam.fy) is np.float32
    assert StereoCamera(width=2**53, height=2).width == 2**53
    assert StereoCamera(fx=1e300, baseline=1e-300).fx == 1e300
