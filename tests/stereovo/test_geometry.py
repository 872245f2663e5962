"""stereovo.geometry: SO(3)/SE(3) maps, rotations, pose composition, batched inputs.

Just past 600 lines: each map is checked near its singularities (angle 0 and pi) as well as in
general position, and batched against one at a time; one file follows one module."""

from __future__ import annotations

import math
import re
from fractions import Fraction

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, strategies as st
from hypothesis.extra.numpy import arrays

from stereovo import geometry as g
from stereovo.geometry import (
    PoseChain,
    _rodrigues_coefficients,
    hat,
    invert_transform,
    make_transform,
    quaternion_from_rotation,
    random_rotation,
    rotation_angle,
    rotation_error,
    se3_exp,
    se3_log,
    so3_exp,
    so3_log,
    transform_points,
    translation_error,
)


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


# --- Exact values: each axis, batches against single rows, angles near 0 and near pi ---


def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


_EPS = 2.0**-52


def _series(theta: float, offset: int) -> float:
    """sum_n (-1)^n theta^(2n) / (2n + offset)!, exactly in rationals, rounded once: the coefficient
    a (offset 1: sin/theta), b (2: (1 - cos)/theta^2) or c (3: (theta - sin)/theta^3)."""
    x2 = Fraction(theta) ** 2
    term = Fraction(1, math.factorial(offset))
    total, n = Fraction(0), 0
    while term != 0 and abs(term) > abs(total) * Fraction(1, 2**120):
        total += term
        n += 1
        term = -term * x2 / ((2 * n + offset - 1) * (2 * n + offset))
    return float(total)


def _rodrigues(axis, angle: float) -> np.ndarray:
    """cos I + sin [k]x + (1 - cos) k k^T for a unit axis k."""
    k = np.asarray(axis, dtype=float)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return math.cos(angle) * np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * np.outer(k, k)


_ANGLES = [0.0, 1e-9, 1e-5, math.nextafter(1e-4, 0.0), 1e-4, math.nextafter(1e-4, 1.0), 1e-3, 1.0, 1.3,
           math.pi / 2, 2.0, 3.0, math.pi - 2e-3, math.nextafter(math.pi - 1e-3, 0.0), math.pi - 9e-4, math.pi - 1e-4]
# Unit axes: along z, with a zero and a negative component, the largest component negative in x,
# in y, in z, and none above 1/sqrt(2) (two equal ones).
_AXES = [(0.0, 0.0, 1.0), (0.6, 0.0, -0.8), (-0.8, 0.48, 0.36), (0.36, -0.8, -0.48), (0.48, 0.36, -0.8),
         (0.0, -math.sqrt(0.5), math.sqrt(0.5))]


def _twist_matrix(xi) -> np.ndarray:
    rho, w = xi[:3], xi[3:]
    A = np.zeros((4, 4))
    A[:3, :3] = [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]
    A[:3, 3] = rho
    return A


def test_rotation_angle_about_each_axis_one_by_one_and_batched():
    angles = [0.3, 1.1, 2.5]
    Rs = np.stack([_rot(axis, a) for axis, a in enumerate(angles)])
    np.testing.assert_allclose(rotation_angle(Rs), angles, rtol=1e-12)
    for R, a in zip(Rs, angles):
        assert rotation_angle(R) == pytest.approx(a, rel=1e-12)
    # A batch of two (not three): the trace and the axis vector are taken per rotation.
    np.testing.assert_allclose(rotation_angle(Rs[:2]), angles[:2], rtol=1e-12)


def test_rotation_error_is_the_angle_of_the_relative_rotation():
    R = _rot(2, 0.3)
    assert rotation_error(R, R) == pytest.approx(0.0, abs=1e-12)  # not the angle of R R (0.6)
    assert rotation_error(R, _rot(2, 0.5)) == pytest.approx(0.2, rel=1e-9)
    est = np.stack([_rot(0, 0.3), _rot(1, 0.7)])
    true = np.stack([_rot(0, 0.3), _rot(1, 0.2)])
    np.testing.assert_allclose(rotation_error(est, true), [0.0, 0.5], atol=1e-12)


def test_translation_error_per_row():
    est = np.array([[1.0, 2.0, 2.0], [0.0, 0.0, 1.0]])
    true = np.array([[0.0, 0.0, 0.0], [0.0, 3.0, 5.0]])
    np.testing.assert_allclose(translation_error(est, true), [3.0, 5.0], rtol=1e-15)


def test_transform_points_single_and_batched():
    X = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    Rz = _rot(2, math.pi / 2)  # x -> y, y -> -x
    t = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(transform_points(Rz, t, X), [[1.0, 3.0, 3.0], [0.0, 2.0, 3.0]], atol=1e-15)
    batch = transform_points(np.stack([Rz, np.eye(3)]), np.stack([t, -t]), X)
    assert batch.shape == (2, 2, 3)
    np.testing.assert_allclose(batch, [[[1.0, 3.0, 3.0], [0.0, 2.0, 3.0]], [[0.0, -2.0, -3.0], [-1.0, -1.0, -3.0]]],
                               atol=1e-15)


def test_quaternions_of_a_batch():
    # About z by 0.6: (0, 0, sin 0.3, cos 0.3); about x by 2.0: (sin 1, 0, 0, cos 1).
    q = quaternion_from_rotation(np.stack([_rot(2, 0.6), _rot(0, 2.0)]))
    np.testing.assert_allclose(q, [[0, 0, math.sin(0.3), math.cos(0.3)], [math.sin(1.0), 0, 0, math.cos(1.0)]],
                               atol=1e-12)


def test_pose_chain_chains_estimates_and_falls_back_to_the_last_motion():
    chain = PoseChain(np.eye(4))
    assert chain.last_motion is None and chain.fallbacks == [] and len(chain.poses) == 1
    # Before any success the fallback is the identity.
    np.testing.assert_array_equal(chain.append(False, np.zeros((3, 3)), np.zeros(3)), np.eye(4))
    # x_k = x_{k-1} + (0, 0, -1): the camera moved 1 m forward, P_1 = inv(T) puts it at z = +1.
    pose = chain.append(True, np.eye(3), np.array([0.0, 0.0, -1.0]))
    np.testing.assert_allclose(pose[:3, 3], [0.0, 0.0, 1.0], atol=1e-15)
    # A failure repeats the last successful motion: z = +2.
    np.testing.assert_allclose(chain.append(False, _rot(0, 1.0), np.ones(3))[:3, 3], [0.0, 0.0, 2.0], atol=1e-15)
    assert chain.fallbacks == [True, False, True] and len(chain.poses) == 4
    np.testing.assert_array_equal(chain.last_motion[1], [0.0, 0.0, -1.0])


def test_batched_transforms_and_twists():
    R = np.stack([np.eye(3), _rot(2, math.pi / 2)])
    t = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, -1.0]])
    T = make_transform(R, t)
    assert T.shape == (2, 4, 4)
    np.testing.assert_array_equal(T[:, 3], [[0, 0, 0, 1], [0, 0, 0, 1]])
    np.testing.assert_array_equal(T[:, :3, 3], t)
    # Pure translations: the twist is (t, 0) for each.
    xi = se3_log(np.stack([np.eye(3), np.eye(3)]), t)
    assert xi.shape == (2, 6)
    np.testing.assert_allclose(xi, [[1.0, 2.0, 3.0, 0, 0, 0], [0, 0, -1.0, 0, 0, 0]], atol=1e-15)


def test_random_rotation_angles_stay_within_the_maximum():
    angles = [float(rotation_angle(random_rotation(np.random.default_rng(seed), 0.1))) for seed in range(40)]
    assert max(angles) <= 0.1 + 1e-12 and max(angles) > 0.05  # uniform in [0, 0.1]: 40 draws reach past half


def test_quaternions_keep_qw_non_negative_at_half_turns_and_drop_a_vanishing_axis():
    axes = np.random.default_rng(0).normal(size=(200, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    q = quaternion_from_rotation(so3_exp(axes * math.pi))  # half turns: qw = cos(pi / 2) ~ 0 either sign
    assert np.all(q[:, 3] >= 0.0)
    np.testing.assert_allclose(np.abs(np.sum(q[:, :3] * axes, axis=1)), 1.0, rtol=1e-12)
    # Below 1e-8 rad the axis is dropped: a rotation about z has no x or y component.
    tiny = quaternion_from_rotation(_rot(2, 5e-9))
    assert tiny[0] == 0.0 and tiny[1] == 0.0 and tiny[3] == pytest.approx(1.0, abs=1e-15)


def test_rodrigues_coefficients_match_their_series_on_both_sides_of_1e_4():
    # 1e-4 itself takes the series: its closed form of c would be 3e-8 off.
    taylor = [0.0, 1e-9, 1e-5, 5e-5, 9e-5, math.nextafter(1e-4, 0.0), 1e-4]
    closed = [math.nextafter(1e-4, 1.0), 1e-3, 0.1, 1.0, 2.0, 3.0, math.pi]
    theta = np.array(taylor + closed)
    a, b, c = _rodrigues_coefficients(theta)
    ref = {name: np.array([_series(t, offset) for t in theta]) for name, offset in (("a", 1), ("b", 2), ("c", 3))}
    # Up to 1e-4 the series' two terms are exact to an ulp; above, the closed forms lose what their
    # cancellations lose: half an ulp of cos (of 1) over 1 - cos, half an ulp of sin (of theta) over theta - sin.
    small = theta <= 1e-4
    th = np.where(small, 1.0, theta)
    tol_b = np.where(small, 2 * _EPS, 2 * _EPS * (1 + 1 / (1 - np.cos(th))))
    tol_c = np.where(small, 2 * _EPS, 2 * _EPS * (1 + th / (th - np.sin(th))))
    assert np.all(np.abs(a / ref["a"] - 1) <= 2 * _EPS)
    assert np.all(np.abs(b / ref["b"] - 1) <= tol_b)
    assert np.all(np.abs(c / ref["c"] - 1) <= tol_c)
    # One by one (scalars) as in a batch.
    for t, ai, bi, ci in zip(theta, a, b, c):
        assert tuple(map(float, _rodrigues_coefficients(np.float64(t)))) == (ai, bi, ci)


def test_so3_exp_and_log_against_rodrigues_formula_from_zero_to_near_pi():
    for axis in _AXES:
        for angle in _ANGLES:
            w = angle * np.array(axis)
            R = _rodrigues(axis, angle)
            np.testing.assert_allclose(so3_exp(w), R, rtol=0, atol=2e-16 * 4)
            # The angle comes from arccos of the trace, off by ~1e-16 / sin(theta): past pi / 2 the
            # symmetric part's axis times it keeps that; below, theta / (2 sin theta) times the
            # antisymmetric part turns it into ~1e-16 theta / (pi - theta)^2 (at most 2.6e-16 there,
            # but 1.6e-9 just below pi - 1e-3, were it used up there).
            tol = 1e-15 * angle + (4e-16 / math.sin(angle) if angle > math.pi / 2 else
                                   4e-16 * angle / (math.pi - angle) ** 2)
            np.testing.assert_allclose(so3_log(R), w, rtol=0, atol=tol, err_msg=f"{axis} {angle}")
            np.testing.assert_allclose(so3_log(so3_exp(w)), w, rtol=0, atol=tol + 4e-16)


def test_so3_log_of_small_angles_keeps_the_second_order_of_theta_over_sin():
    # Below 1e-6 rad the scale theta / (2 sin theta) is the series 1/2 + theta^2 / 12: at 9.5e-7 rad
    # its second term is 7.5e-14 of 1/2, far above the rounding (a few 1e-16) of w = scale * vee.
    for axis in _AXES[:3]:
        for angle in (9.5e-7, 5e-7, 1.2e-6):
            w = so3_log(_rodrigues(axis, angle))
            np.testing.assert_allclose(w, angle * np.array(axis), rtol=0, atol=2e-15 * angle)


def test_so3_log_near_pi_in_a_batch_matches_one_by_one():
    angles = [math.pi - 9e-4, math.pi - 1e-4, math.pi - 1e-6]
    Rs, ws = [], []
    for axis in _AXES:
        for angle in angles:
            Rs.append(_rodrigues(axis, angle))
            ws.append(angle * np.array(axis))
    batch = so3_log(np.stack(Rs))
    for R, w, row in zip(Rs, ws, batch):
        tol = 1e-15 + 4e-16 / math.sin(np.linalg.norm(w))
        np.testing.assert_allclose(so3_log(R), w, rtol=0, atol=tol)
        np.testing.assert_allclose(row, w, rtol=0, atol=tol)
    # Two rotations only (the axes' signs differ): each row's own sign.
    pair = so3_log(np.stack(Rs[3:5]))
    np.testing.assert_allclose(pair, np.stack(ws[3:5]), rtol=0, atol=1e-11)


def test_exactly_symmetric_half_turns_get_the_largest_component_positive():
    # R = 2 k k^T - I is symmetric to the bit: no antisymmetric part tells w from -w (docstring).
    for axis, expected in (((1.0, 0.0, 0.0), (1.0, 0.0, 0.0)), ((0.0, -1.0, 0.0), (0.0, 1.0, 0.0)),
                           ((0.0, 0.0, -1.0), (0.0, 0.0, 1.0)), ((0.6, -0.8, 0.0), (-0.6, 0.8, 0.0)),
                           ((0.0, -math.sqrt(0.5), math.sqrt(0.5)), (0.0, math.sqrt(0.5), -math.sqrt(0.5)))):
        k = np.array(axis)
        R = 2 * np.outer(k, k) - np.eye(3)
        # The angle from a trace of -1 rounded by an ulp: arccos(-1 + 1e-16) is pi - 1.5e-8.
        np.testing.assert_allclose(so3_log(R), math.pi * np.array(expected), rtol=0, atol=3e-8)
    np.testing.assert_array_equal(so3_log(np.diag([1.0, -1.0, -1.0])), [math.pi, 0.0, 0.0])


def test_so3_log_clips_traces_rounded_past_three_and_minus_one():
    up, down = math.nextafter(1.0, 2.0), math.nextafter(-1.0, -2.0)  # 1 + 2.2e-16, -1 - 2.2e-16
    R = np.diag([up, up, 1.0])  # trace 3 + 4.4e-16: cos 1 + 2.2e-16 clipped to 1, not arccos(.) = nan
    assert (np.trace(R) - 1) / 2 > 1.0
    np.testing.assert_array_equal(so3_log(R), [0.0, 0.0, 0.0])
    R = np.diag([1.0, down, down])  # trace -1 - 4.4e-16: cos -1 - 2.2e-16 clipped to -1
    assert (np.trace(R) - 1) / 2 < -1.0
    np.testing.assert_array_equal(so3_log(R), [math.pi, 0.0, 0.0])


def test_zero_and_vanishing_rotations_raise_no_floating_point_error():
    # The masked branches must not divide 0 by 0 (the Taylor series' placeholders, the half turn's
    # normalisation of the identity's zero row, or its underflowing norm at 1e-100 rad).
    tiny = so3_exp(np.array([1e-100, 1e-100, 0.0]))
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        np.testing.assert_array_equal(so3_exp(np.zeros(3)), np.eye(3))
        np.testing.assert_array_equal(so3_exp(np.zeros((2, 3))), np.stack([np.eye(3)] * 2))
        np.testing.assert_array_equal(so3_log(np.eye(3)), np.zeros(3))
        w = so3_log(np.stack([np.eye(3), np.diag([1.0, -1.0, -1.0]), tiny]))
        np.testing.assert_array_equal(w[:2], [[0.0, 0.0, 0.0], [math.pi, 0.0, 0.0]])
        np.testing.assert_allclose(w[2], [1e-100, 1e-100, 0.0], rtol=1e-15, atol=0)
        R, t = se3_exp(np.zeros(6))
        np.testing.assert_array_equal(R, np.eye(3))
        np.testing.assert_array_equal(t, np.zeros(3))
        np.testing.assert_array_equal(se3_log(np.eye(3), np.array([1.0, 2.0, 3.0])), [1, 2, 3, 0, 0, 0])


def test_se3_exp_is_the_matrix_exponential_of_the_twist_one_by_one_and_batched():
    rho = np.array([0.4, -1.3, 2.0])
    xis = np.array([np.concatenate([rho, angle * np.array(axis)])
                    for angle, axis in ((0.0, _AXES[0]), (5e-5, _AXES[2]), (1e-3, _AXES[1]), (1.0, _AXES[3]),
                                        (2.5, _AXES[4]), (3.0, _AXES[5]))])
    expected = np.stack([scipy.linalg.expm(_twist_matrix(xi)) for xi in xis])
    # From 1e-4 rad the left Jacobian's (1 - cos) / theta^2 carries cos's rounding (1e-16) over
    # theta^2, times theta |rho| in t: 1e-13 at 1e-3 rad.
    angles = np.linalg.norm(xis[:, 3:], axis=1)
    tol_t = 1e-14 + np.where(angles < 1e-4, 0.0, 2 * _EPS * np.linalg.norm(rho) / np.maximum(angles, 1e-4))
    R, t = se3_exp(xis)
    np.testing.assert_allclose(R, expected[:, :3, :3], rtol=0, atol=1e-14)
    assert np.all(np.abs(t - expected[:, :3, 3]) <= tol_t[:, None])
    for xi, T, tol in zip(xis, expected, tol_t):
        R1, t1 = se3_exp(xi)
        np.testing.assert_allclose(R1, T[:3, :3], rtol=0, atol=1e-14)
        np.testing.assert_allclose(t1, T[:3, 3], rtol=0, atol=tol)
    # Two twists only: each row's own angle in its left Jacobian.
    assert np.all(np.abs(se3_exp(xis[2:4])[1] - expected[2:4, :3, 3]) <= tol_t[2:4, None])


def test_invert_transform_of_a_batch_is_each_inverse():
    T = make_transform(np.stack([_rot(0, 0.7), _rot(2, -1.2)]), np.array([[1.0, 2.0, 3.0], [-0.5, 0.0, 4.0]]))
    np.testing.assert_allclose(invert_transform(T), np.linalg.inv(T), rtol=0, atol=1e-15)
    np.testing.assert_allclose(invert_transform(T[1]), np.linalg.inv(T[1]), rtol=0, atol=1e-15)


def test_single_precision_inputs_are_computed_in_double():
    w32 = np.array([0.3, -0.2, 0.1], dtype=np.float32)
    R = so3_exp(w32)
    assert R.dtype == np.float64
    np.testing.assert_array_equal(R, so3_exp(w32.astype(np.float64)))
    R32 = so3_exp(np.array([0.5, 1.0, -2.0])).astype(np.float32)
    w = so3_log(R32)
    assert w.dtype == np.float64
    np.testing.assert_array_equal(w, so3_log(R32.astype(np.float64)))
    xi32 = np.array([0.4, -1.3, 2.0, 0.3, -0.2, 0.1], dtype=np.float32)
    R, t = se3_exp(xi32)
    assert R.dtype == t.dtype == np.float64
    R64, t64 = se3_exp(xi32.astype(np.float64))
    np.testing.assert_array_equal(R, R64)
    np.testing.assert_array_equal(t, t64)


def test_hat_negates_unsigned_integers_as_numbers():
    # -w of uint8 (1, 2, 3) would wrap to (255, 254, 253).
    np.testing.assert_array_equal(hat(np.array([1, 2, 3], dtype=np.uint8)), [[0, -3, 2], [3, 0, -1], [-2, 1, 0]])


def test_pose_chain_keeps_a_float_copy_of_an_integer_first_pose():
    first = np.eye(4, dtype=int)
    chain = PoseChain(first)
    assert chain.poses[0].dtype == np.float64
    first[0, 3] = 5
    np.testing.assert_array_equal(chain.poses[0], np.eye(4))


def _numpy_inverse(T):
    """invert_transform's numpy formulation (the compiled single-transform path's reference)."""
    from stereovo.geometry import make_transform

    T = np.asarray(T, dtype=float)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    return make_transform(Rt, -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3]))


def test_one_transform_is_inverted_bit_for_bit_as_by_numpy():
    import itertools

    from stereovo.geometry import invert_transform, make_transform, random_rotation

    rng = np.random.default_rng(0)
    cases = []
    for k in range(20000):
        R = random_rotation(rng) * (1.0 if k % 3 else rng.uniform(0.1, 10.0))
        t = rng.standard_normal(3) * 10 ** rng.uniform(-5, 5)
        t[rng.integers(0, 3)] = (0.0, -0.0, t[0])[k % 3]
        T = make_transform(R, t)
        if k % 5 == 0:
            T[3] = rng.standard_normal(4)  # not a rigid last row: still the formulation's result
        cases.append(T)
    zeros = [0.0, -0.0, 1.0, -1.0, np.inf, np.nan, 1e308, -1e-310]
    for values in itertools.product(zeros, repeat=3):
        for R in (np.eye(3), -np.eye(3), np.array([[-0.0, 1.0, 0.0], [1.0, -0.0, 0.0], [0.0, 0.0, -1.0]])):
            cases.append(make_transform(R, np.array(values)))
    for T in cases:
        ours = invert_transform(T)
        assert type(ours) is np.ndarray and ours.dtype == np.float64 and ours.flags.c_contiguous
        assert ours.tobytes() == _numpy_inverse(T).tobytes()
    stacked = np.stack(cases[:50])  # batches stay numpy's
    assert invert_transform(stacked).tobytes() == _numpy_inverse(stacked).tobytes()


def test_one_rotation_angle_and_translation_error_are_numpys_bit_for_bit():
    """The float paths for one matrix / one vector pair equal numpy's formulation (trace, add.reduce of
    the squares, arctan2), which sums three values in order: this test holds numpy to that too."""
    from stereovo.geometry import random_rotation, rotation_angle, translation_error

    def numpy_angle(R):
        cos = (np.trace(R, axis1=-2, axis2=-1) - 1) / 2
        with np.errstate(invalid="ignore"):
            vee = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]],
                           axis=-1)
        return np.arctan2(np.linalg.norm(vee, axis=-1) / 2, cos)

    rng = np.random.default_rng(1)
    cases = [random_rotation(rng, 10 ** rng.uniform(-9, 0.5)) for _ in range(20000)]
    cases += [rng.standard_normal((3, 3)) * 10 ** rng.uniform(-3, 3) for _ in range(20000)]
    cases += [np.diag([-0.0, -0.0, -0.0]), -np.eye(3), np.eye(3), np.full((3, 3), 1e300)]
    for R in cases:
        ours, theirs = rotation_angle(R), numpy_angle(R)
        assert type(ours) is type(theirs) and np.array_equal(ours, theirs, equal_nan=True)
        assert np.signbit(ours) == np.signbit(theirs)
    for _ in range(20000):
        a, b = rng.standard_normal(3) * 10 ** rng.uniform(-5, 5), rng.standard_normal(3)
        ours, theirs = translation_error(a, b), np.linalg.norm(a - b, axis=-1)
        assert type(ours) is type(theirs) and ours == theirs
    stacked = np.stack(cases[:100])
    assert rotation_angle(stacked).tobytes() == numpy_angle(stacked).tobytes()
    with pytest.warns(RuntimeWarning):  # NaN and inf take numpy's path, warnings and all
        assert np.isnan(rotation_angle(np.full((3, 3), np.inf)))
    assert np.isnan(rotation_angle(np.full((3, 3), np.nan)))


def test_pose_update_of_one_motion_is_the_numpy_formulation():
    from stereovo.geometry import invert_transform, make_transform, pose_update, random_rotation

    rng = np.random.default_rng(2)
    for k in range(5000):
        pose = make_transform(random_rotation(rng), rng.standard_normal(3) * 50)
        R = random_rotation(rng, 0.1) * (1.0 if k % 2 else rng.uniform(0.5, 2.0))
        t = rng.standard_normal(3) * 10 ** rng.uniform(-4, 2)
        t[k % 3] = (0.0, -0.0, t[k % 3])[k % 3]
        expected = np.asarray(pose, dtype=float) @ _numpy_inverse(make_transform(R, t))
        assert pose_update(pose, R, t).tobytes() == expected.tobytes()
    R[0, 0] = np.nan  # non-finite motions take the numpy formulation
    np.testing.assert_array_equal(pose_update(pose, R, t), pose @ invert_transform(make_transform(R, t)))
    np.testing.assert_array_equal(pose_update(pose, R.T[:, :], t), pose @ _numpy_inverse(make_transform(R.T, t)))


def _inverse_by_formula(R, t):
    """inv([[R, t], [0, 1]]) = [[R^T, -R^T t], [0, 1]], in float64 and by exact rationals for -R^T t."""
    R, t = np.asarray(R, dtype=np.float64), np.asarray(t, dtype=np.float64)
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = [-float(sum(Fraction(R[k, i]) * Fraction(t[k]) for k in range(3))) for i in range(3)]
    return out


def test_transforms_of_any_real_dtype_or_nested_lists_are_computed_in_double():
    """float32, float16, long double and integer entries, and nested lists, give the float64 input's result
    (float64 out): the fast paths for one 4x4 / one 3x3 take only float64 arrays, and the numpy
    formulation reads everything else as float64 first."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        R, t = random_rotation(rng), rng.standard_normal(3) * 10
        T = make_transform(R, t)
        for dtype in (np.float32, np.float16, np.longdouble, np.int64):
            Tx = (T * (100 if dtype is np.int64 else 1)).astype(dtype)
            T64 = Tx.astype(np.float64)
            ours = invert_transform(Tx)
            assert ours.dtype == np.float64
            np.testing.assert_allclose(ours, _inverse_by_formula(T64[:3, :3], T64[:3, 3]), rtol=0, atol=1e-12 * 100)
            assert ours.tobytes() == invert_transform(T64).tobytes()
            batch = invert_transform(np.stack([Tx, Tx]))
            assert batch.dtype == np.float64 and batch.tobytes() == np.stack([ours, ours]).tobytes()
        assert invert_transform(T.tolist()).tobytes() == invert_transform(T).tobytes()
        np.testing.assert_allclose(invert_transform(T.tolist()), np.linalg.inv(T), rtol=0, atol=1e-13)
        # rotation angles and translation errors: float32 and long double are read as float64
        for dtype in (np.float32, np.longdouble):
            # (a long double t_true or R_true is left as it is: only t_est and R_est are read as float64)
            Rx, tx = R.astype(dtype), t.astype(dtype)
            ux = rng.standard_normal(3).astype(np.float32 if dtype is np.float32 else np.float64)
            Ry = (R.astype(np.float32) if dtype is np.float32 else R).T
            for ours, theirs in ((rotation_angle(Rx), rotation_angle(Rx.astype(np.float64))),
                                 (rotation_angle(np.stack([Rx, Rx])),
                                  rotation_angle(np.stack([Rx, Rx]).astype(np.float64))),
                                 (translation_error(tx, ux), translation_error(tx.astype(np.float64), ux.astype(np.float64))),
                                 (rotation_error(Rx, Ry), rotation_error(Rx.astype(np.float64), Ry.astype(np.float64)))):
                assert ours.dtype == np.float64 and ours.tobytes() == theirs.tobytes()
        assert rotation_angle(R.tolist()) == rotation_angle(R)
        # transform_points, se3_log and relative_motion of long double input: float64 results
        X = rng.standard_normal((4, 3))
        for args in ((R.astype(np.longdouble), t, X), (R, t, X.astype(np.longdouble))):
            ours = transform_points(*args)
            assert ours.dtype == np.float64 and ours.tobytes() == transform_points(R, t, X).tobytes()
        xi = se3_log(R, t.astype(np.longdouble))
        assert xi.dtype == np.float64 and xi.tobytes() == se3_log(R, t).tobytes()
        P = make_transform(random_rotation(rng), rng.standard_normal(3))
        for Rr, tr in (g.relative_motion(P.astype(np.longdouble), T), g.relative_motion(P, T)):
            assert Rr.dtype == tr.dtype == np.float64
        assert g.relative_motion(P.astype(np.longdouble), T)[1].tobytes() == g.relative_motion(P, T)[1].tobytes()


def test_translation_error_of_a_batch_of_batches_is_per_innermost_vector():
    est = np.array([[[1.0, 2.0, 2.0], [0.0, 0.0, 1.0]], [[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]]])
    true = np.zeros((2, 2, 3))
    true[0, 1] = [0.0, 3.0, 5.0]
    np.testing.assert_array_equal(translation_error(est, true), [[3.0, 5.0], [5.0, 0.0]])


def test_pose_update_of_batches_lists_and_other_dtypes_is_the_formula():
    """P_k = P_{k-1} inv([[R, t], [0, 1]]) for every input the fast path for one float64 motion leaves to
    the numpy formulation: batches (per motion, or one t for all), nested lists, other real dtypes of
    the motion or the pose (read as float64, float64 out), NaN; malformed shapes are refused."""
    from stereovo.geometry import pose_update

    rng = np.random.default_rng(6)
    pose = make_transform(random_rotation(rng), rng.standard_normal(3) * 5)
    Rs = np.stack([random_rotation(rng, 0.5) for _ in range(3)])
    ts = rng.standard_normal((3, 3))
    expected = np.stack([pose @ _inverse_by_formula(R, t) for R, t in zip(Rs, ts)])
    batch = pose_update(pose, Rs, ts)
    assert batch.shape == (3, 4, 4) and batch.dtype == np.float64
    np.testing.assert_allclose(batch, expected, rtol=0, atol=1e-12)
    shared = pose_update(pose, Rs, ts[0])  # one translation for every rotation
    np.testing.assert_allclose(shared, [pose @ _inverse_by_formula(R, ts[0]) for R in Rs], rtol=0, atol=1e-12)
    R, t = Rs[0], ts[0]
    one = pose_update(pose, R, t)
    np.testing.assert_allclose(one, expected[0], rtol=0, atol=1e-12)
    assert pose_update(pose.tolist(), R.tolist(), t.tolist()).tobytes() == one.tobytes()
    assert pose_update(pose, R.tolist(), t).tobytes() == one.tobytes()
    assert pose_update(pose, R, t.tolist()).tobytes() == one.tobytes()
    # motions of other dtypes: read as float64 (float16 entries are exact in float64)
    for Rx, tx in ((R.astype(np.float32), t.astype(np.float32)), (R.astype(np.float16), t),
                   (R, t.astype(np.float16)), (R.astype(np.longdouble), t), (R, t.astype(np.longdouble))):
        ours = pose_update(pose, Rx, tx)
        theirs = pose_update(pose, Rx.astype(np.float64), tx.astype(np.float64))
        assert ours.dtype == np.float64 and ours.tobytes() == theirs.tobytes()
        np.testing.assert_allclose(ours, pose @ _inverse_by_formula(Rx, tx), rtol=0, atol=1e-12)
    # poses of other dtypes, with a float64 motion (the fast path) and a float32 one (the formulation)
    for Rx, tx in ((R, t), (R.astype(np.float32), t.astype(np.float32))):
        for px in (pose.astype(np.longdouble), pose.astype(np.float32), np.eye(4, dtype=np.int64)):
            ours = pose_update(px, Rx, tx)
            theirs = pose_update(px.astype(np.float64), Rx, tx)
            assert ours.dtype == np.float64 and ours.tobytes() == theirs.tobytes()
    # a NaN in t leaves the rotation part alone and fills the translation column with NaN
    t_nan = t.copy()
    t_nan[1] = np.nan
    nan_pose = pose_update(pose, R, t_nan)
    np.testing.assert_allclose(nan_pose[:3, :3], one[:3, :3], rtol=0, atol=1e-15)
    assert np.all(np.isnan(nan_pose[:, 3])) and np.array_equal(nan_pose[3, :3], [0.0, 0.0, 0.0])  # 0 * NaN in row 3
    for bad_R, bad_t, message in (
            (np.zeros((4, 3)), t, "R must have shape (..., 3, 3), got (4, 3)"),
            (np.zeros((3, 4)), t, "R must have shape (..., 3, 3), got (3, 4)"),
            (np.zeros(3), t, "R must have shape (..., 3, 3), got (3,)"),
            (R, np.zeros(4), "t must have shape (..., 3) fitting R's (3, 3), got (4,)"),
            (R, np.zeros((2, 3)), "t must have shape (..., 3) fitting R's (3, 3), got (2, 3)")):
        with pytest.raises(ValueError, match=re.escape(message)):
            pose_update(pose, bad_R, bad_t)
        with pytest.raises(ValueError, match=re.escape(message)):
            make_transform(bad_R, bad_t)
    # t broadcasts over R's leading axes: one translation for a batch of rotations
    batch = make_transform(np.stack([R, R.T]), t)
    assert batch.shape == (2, 4, 4) and np.array_equal(batch[1, :3, 3], t) and np.array_equal(batch[1, :3, :3], R.T)


def test_rotation_error_of_float64_matrices_is_the_swapaxes_formulation():
    rng = np.random.default_rng(5)
    for _ in range(5000):
        R_est = so3_exp(rng.standard_normal(3) * rng.uniform(0, 3))
        R_true = so3_exp(rng.standard_normal(3) * rng.uniform(0, 3))
        if rng.random() < 0.3:
            R_est = np.asfortranarray(R_est)
        want = rotation_angle(np.swapaxes(np.asarray(R_est, dtype=float), -1, -2) @ R_true)
        assert rotation_error(R_est, R_true) == want
    stack = np.stack([np.eye(3), so3_exp(np.array([0.1, 0.2, 0.3]))])
    np.testing.assert_array_equal(rotation_error(stack, np.eye(3)), rotation_angle(np.swapaxes(stack, -1, -2)))
    # nested lists and other dtypes take the general formulation, with the same values
    R_est, R_true = so3_exp(np.array([0.3, -0.2, 0.1])), so3_exp(np.array([0.0, 0.4, 0.2]))
    assert rotation_error(R_est.tolist(), R_true) == rotation_error(R_est, R_true)
    assert rotation_error(R_est.astype(np.float32), R_true) == rotation_angle(
        np.swapaxes(R_est.astype(np.float32).astype(float), -1, -2) @ R_true)
