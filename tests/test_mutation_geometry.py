"""The geometry helpers' contracts that the mutmut run of ``stereovo/geometry.py`` found untested
(docs/mutation-testing.md): batched inputs (every helper takes a leading batch dimension, module
doc), and rotations about each axis. Expected values are rotations by hand (about x, y, z by a
given angle) and arithmetic on them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stereovo.geometry import (
    PoseChain,
    make_transform,
    random_rotation,
    quaternion_from_rotation,
    rotation_angle,
    rotation_error,
    se3_log,
    transform_points,
    translation_error,
)


def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


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
    from stereovo.geometry import so3_exp

    q = quaternion_from_rotation(so3_exp(axes * math.pi))  # half turns: qw = cos(pi / 2) ~ 0 either sign
    assert np.all(q[:, 3] >= 0.0)
    np.testing.assert_allclose(np.abs(np.sum(q[:, :3] * axes, axis=1)), 1.0, rtol=1e-12)
    # Below 1e-8 rad the axis is dropped: a rotation about z has no x or y component.
    tiny = quaternion_from_rotation(_rot(2, 5e-9))
    assert tiny[0] == 0.0 and tiny[1] == 0.0 and tiny[3] == pytest.approx(1.0, abs=1e-15)
