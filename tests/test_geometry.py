import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from stereovo import geometry as g

finite = st.floats(-3.0, 3.0, allow_nan=False)
rotvec = arrays(float, 3, elements=st.floats(-3.0, 3.0)).filter(lambda w: np.linalg.norm(w) < np.pi - 1e-3)
twist = arrays(float, 6, elements=st.floats(-3.0, 3.0)).filter(lambda x: np.linalg.norm(x[3:]) < np.pi - 1e-3)


@given(rotvec)
def test_so3_exp_log_round_trip(w):
    R = g.so3_exp(w)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(g.so3_log(R), w, atol=1e-9)


@given(twist)
def test_se3_exp_log_round_trip(xi):
    R, t = g.se3_exp(xi)
    np.testing.assert_allclose(g.se3_log(R, t), xi, atol=1e-9)


def test_so3_log_near_pi_recovers_axis():
    axis = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    for angle in (np.pi - 1e-5, np.pi):
        w = g.so3_log(g.so3_exp(axis * angle))
        np.testing.assert_allclose(g.so3_exp(w), g.so3_exp(axis * angle), atol=1e-9)


def test_batched_exp_matches_single():
    rng = np.random.default_rng(0)
    W = rng.normal(size=(5, 3))
    np.testing.assert_allclose(g.so3_exp(W), np.stack([g.so3_exp(w) for w in W]), atol=1e-15)


@given(twist, twist)
def test_pose_update_and_relative_motion_are_inverse(xi_pose, xi_motion):
    P_prev = g.make_transform(*g.se3_exp(xi_pose))
    R, t = g.se3_exp(xi_motion)
    P_curr = g.pose_update(P_prev, R, t)
    R2, t2 = g.relative_motion(P_prev, P_curr)
    np.testing.assert_allclose(R2, R, atol=1e-9)
    np.testing.assert_allclose(t2, t, atol=1e-9)


def test_pose_update_follows_point_transform_convention():
    # A world landmark seen at k-1 maps into camera k by x_k = R x_{k-1} + t.
    rng = np.random.default_rng(1)
    P_prev = g.make_transform(g.random_rotation(rng), rng.normal(size=3))
    R, t = g.random_rotation(rng, 0.3), rng.normal(size=3)
    P_curr = g.pose_update(P_prev, R, t)
    landmark = rng.normal(size=3) * 10
    x_prev = (g.invert_transform(P_prev) @ np.append(landmark, 1))[:3]
    x_curr = (g.invert_transform(P_curr) @ np.append(landmark, 1))[:3]
    np.testing.assert_allclose(x_curr, R @ x_prev + t, atol=1e-9)


def test_errors_and_quaternion():
    R = g.so3_exp([0.0, 0.1, 0.0])
    assert g.rotation_error(R, np.eye(3)) == pytest.approx(0.1)
    assert g.translation_error(np.array([1.0, 2, 2]), np.zeros(3)) == pytest.approx(3.0)
    q = g.quaternion_from_rotation(R)
    np.testing.assert_allclose(q, [0, np.sin(0.05), 0, np.cos(0.05)], atol=1e-12)
    np.testing.assert_allclose(g.quaternion_from_rotation(np.eye(3)), [0, 0, 0, 1])


def test_compose_and_transform_points():
    rng = np.random.default_rng(2)
    R1, t1, R2, t2 = g.random_rotation(rng), rng.normal(size=3), g.random_rotation(rng), rng.normal(size=3)
    X = rng.normal(size=(4, 3))
    R, t = g.compose(R1, t1, R2, t2)
    np.testing.assert_allclose(g.transform_points(R, t, X), g.transform_points(R1, t1, g.transform_points(R2, t2, X)))
