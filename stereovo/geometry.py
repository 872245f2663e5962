"""SO(3) / SE(3) helpers and the one place that fixes the transform convention.

Convention: the motion between frames k-1 and k is the
point transform ``x_k = R @ x_{k-1} + t``; it maps a landmark from camera frame
k-1 into camera frame k. Poses are camera-to-world 4x4 matrices ``P_k`` and
the pose update is ``P_k = P_{k-1} @ inv(T)`` with ``T = [[R, t], [0, 1]]``.

All functions accept a leading batch dimension where it makes sense:
rotation vectors ``(..., 3)``, rotations ``(..., 3, 3)``, twists ``(..., 6)``
ordered ``(rho, omega)`` (translation part first), angles in radians.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_SMALL_ANGLE = 1e-8


def hat(w: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrices ``(..., 3, 3)`` of vectors ``(..., 3)``."""
    w = np.asarray(w, dtype=float)
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1] = -w[..., 2]
    out[..., 0, 2] = w[..., 1]
    out[..., 1, 0] = w[..., 2]
    out[..., 1, 2] = -w[..., 0]
    out[..., 2, 0] = -w[..., 1]
    out[..., 2, 1] = w[..., 0]
    return out


def _rodrigues_coefficients(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coefficients a = sin/θ, b = (1-cos)/θ², c = (θ - sin)/θ³ with Taylor series near 0."""
    # At 1e-4 itself the series too: the closed forms lose 3e-8 of c to cancellation there.
    small = theta <= 1e-4
    th = np.where(small, 1.0, theta)
    th2 = th * th
    # Two terms are exact in float64 there: the next ones (theta^4 / 120, / 720, / 5040 < 1e-18) are
    # below half an ulp of 1, 1/2 and 1/6, so adding them would round back to the same value.
    a = np.where(small, 1 - theta**2 / 6, np.sin(th) / th)
    b = np.where(small, 0.5 - theta**2 / 24, (1 - np.cos(th)) / th2)
    c = np.where(small, 1 / 6 - theta**2 / 120, (th - np.sin(th)) / (th2 * th))
    return a, b, c


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` from rotation vectors ``(..., 3)`` (radians)."""
    w = np.asarray(w, dtype=float)
    theta = np.linalg.norm(w, axis=-1)
    a, b, _ = _rodrigues_coefficients(theta)
    W = hat(w)
    return np.eye(3) + a[..., None, None] * W + b[..., None, None] * (W @ W)


def so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation vectors ``(..., 3)`` of rotation matrices ``(..., 3, 3)``; angle in [0, pi].

    At a half turn (``w`` and ``-w`` the same rotation) the sign follows R's antisymmetric part; an
    exactly symmetric R gets the one whose largest component (the first of equal ones) is positive.
    """
    R = np.asarray(R, dtype=float)
    cos = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1) / 2, -1.0, 1.0)
    theta = np.arccos(cos)
    vee = np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1
    )
    sin = np.sin(theta)
    small = theta < 1e-6
    obtuse = theta > np.pi / 2
    scale = np.where(small, 0.5 + theta**2 / 12, theta / (2 * np.where(small, 1.0, sin)))
    w = scale[..., None] * vee
    if np.any(obtuse):
        # theta / (2 sin theta) magnifies the rounding of R's antisymmetric part as sin falls (1.6e-9
        # rad just below pi - 1e-3, the axis lost at pi): past a quarter turn read the axis from
        # the symmetric part B = (1 - cos) k k^T instead, where 1 - cos >= 1 keeps it exact.
        # Its row of the largest diagonal entry is (1 - cos) k_i k, |k_i| >= 1/sqrt(3): k up to sign.
        B = (R + np.swapaxes(R, -1, -2)) / 2 - np.eye(3) * cos[..., None, None]
        k = np.argmax(np.diagonal(B, axis1=-2, axis2=-1), axis=-1)
        row = np.take_along_axis(B, k[..., None, None], axis=-2)[..., 0, :]
        # Rows under a quarter turn (masked below) are divided by 1, not by their norm: 0 at the identity.
        axis = row / np.where(obtuse, np.linalg.norm(row, axis=-1), 1.0)[..., None]
        axis = np.where((np.sum(axis * vee, axis=-1) < 0)[..., None], -axis, axis)
        w = np.where(obtuse[..., None], axis * theta[..., None], w)
    return w


def _left_jacobian(w: np.ndarray) -> np.ndarray:
    theta = np.linalg.norm(w, axis=-1)
    _, b, c = _rodrigues_coefficients(theta)
    W = hat(w)
    return np.eye(3) + b[..., None, None] * W + c[..., None, None] * (W @ W)


def se3_exp(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` from twists ``(..., 6) = (rho, omega)``: ``T = exp(xi^)``."""
    xi = np.asarray(xi, dtype=float)
    rho, w = xi[..., :3], xi[..., 3:]
    R = so3_exp(w)
    t = np.einsum("...ij,...j->...i", _left_jacobian(w), rho)
    return R, t


def se3_log(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Twists ``(..., 6) = (rho, omega)`` of transforms ``(R, t)``; inverse of :func:`se3_exp`."""
    w = so3_log(R)
    rho = np.linalg.solve(_left_jacobian(w), np.asarray(t, dtype=float)[..., None])[..., 0]
    return np.concatenate([rho, w], axis=-1)


def make_transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4x4 homogeneous matrices ``(..., 4, 4)`` from ``R (..., 3, 3)`` and ``t (..., 3)`` (``t`` may
    broadcast over ``R``'s leading axes).

    Raises:
        ValueError: naming ``R`` or ``t`` and its shape, when either does not fit.
    """
    R = np.asarray(R, dtype=float)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"R must have shape (..., 3, 3), got {R.shape}")
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    try:
        T[..., :3, 3] = t
    except ValueError:
        raise ValueError(f"t must have shape (..., 3) fitting R's {R.shape}, got {np.shape(t)}") from None
    T[..., 3, 3] = 1.0
    return T


def invert_transform(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid 4x4 transforms, using ``R^T`` instead of a general inverse."""
    if type(T) is np.ndarray and T.shape == (4, 4) and T.dtype == np.float64:
        # one finite transform (the simulator's and the pose chain's case, a few a step): compiled
        out = np.empty((4, 4))  # numpy's own array (see stereovo.camera._project_rows)
        if _invert_one(T, out):
            return out
    T = np.asarray(T, dtype=float)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    return make_transform(Rt, -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3]))


@njit(cache=True, nogil=True)
def finite_motion(R, t):
    """Whether every entry of ``R (3, 3)`` and ``t (3,)`` is finite: ``np.all(np.isfinite(.))`` of both in
    one compiled pass (each estimate checks its motion this way, where numpy's passes cost microseconds)."""
    for i in range(3):
        if not math.isfinite(t[i]):
            return False
        for j in range(3):
            if not math.isfinite(R[i, j]):
                return False
    return True


@njit(cache=True, nogil=True)
def _invert_motion(R, t, out):
    """``out = invert_transform(make_transform(R, t))`` for one finite motion ``R (3, 3)``, ``t (3,)``
    (float64), bit for bit (see :func:`_invert_one`); False, ``out`` unfinished, when R or t holds
    NaN or inf."""
    if not finite_motion(R, t):
        return False
    for i in range(3):
        for j in range(3):
            out[i, j] = R[j, i]
        out[i, 3] = -(((0.0 + R[0, i] * t[0]) + R[1, i] * t[1]) + R[2, i] * t[2])
        out[3, i] = 0.0
    out[3, 3] = 1.0
    return True


@njit(cache=True, nogil=True)
def _invert_one(T, out):
    """:func:`invert_transform` of one ``(4, 4)`` float64 ``T`` into ``out``, bit for bit: einsum
    sums the three products of ``R^T t`` in order onto 0.0 (no fused multiply-add; ``+0.0`` first, so
    an all-zero sum is ``+0.0`` and its negation ``-0.0``), and ``make_transform`` writes zeros and a
    one in the last row (``tests/stereovo/test_geometry.py`` compares the two on random and signed-zero
    input). Returns False, leaving ``out`` unfinished, when ``T`` holds NaN or inf: numpy's NaN
    signs are its own business, so such input takes the numpy formulation."""
    for j in range(4):
        if not math.isfinite(T[3, j]):
            return False
    return _invert_motion(T[:3, :3], T[:3, 3], out)


def compose(R1: np.ndarray, t1: np.ndarray, R2: np.ndarray, t2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` of applying ``(R2, t2)`` first, then ``(R1, t1)``: ``x -> R1 (R2 x + t2) + t1``."""
    return R1 @ R2, np.einsum("...ij,...j->...i", R1, t2) + t1


def transform_points(R: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Apply ``x -> R x + t`` to points ``(N, 3)``; batched ``R (H, 3, 3)`` gives ``(H, N, 3)``."""
    return np.asarray(X, dtype=float) @ np.swapaxes(np.asarray(R, dtype=float), -1, -2) + np.asarray(t)[..., None, :]


def pose_update(pose_prev: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Camera-to-world pose at k from the pose at k-1 and the motion ``x_k = R x_{k-1} + t``.

    ``P_k = P_{k-1} @ inv(T)``, the single place where the convention is applied.
    """
    if (type(R) is np.ndarray and type(t) is np.ndarray and R.shape == (3, 3) and t.shape == (3,)
            and R.dtype == np.float64 and t.dtype == np.float64 and R.flags.c_contiguous and t.flags.c_contiguous):
        # one motion (a step's estimate, a sequence's frames): inv(T) straight from (R, t), compiled,
        # the values invert_transform(make_transform(R, t)) gives
        inverse = np.empty((4, 4))
        if _invert_motion(R, t, inverse):
            return np.asarray(pose_prev, dtype=float) @ inverse
    return np.asarray(pose_prev, dtype=float) @ invert_transform(make_transform(R, t))


class PoseChain:
    """Camera-to-world poses chained from frame-to-frame motions, with the constant-velocity fallback.

    The one place that turns a sequence of estimates into a trajectory: the odometry runner and the
    environments append each frame's estimate; a failed estimate (``ok=False``) reuses the last
    successful motion, or the identity before any success.

    Attributes:
        poses: ``[(4, 4)]`` camera-to-world poses, ``poses[0]`` the start; one more per ``append``.
        last_motion: ``(R (3, 3), t (3,) in m)`` of the last successful estimate, None before one.
        fallbacks: one bool per ``append``, True where the fallback motion was used.
    """

    def __init__(self, first_pose: np.ndarray):
        self.poses: list[np.ndarray] = [np.array(first_pose, dtype=float)]
        self.last_motion: tuple[np.ndarray, np.ndarray] | None = None
        self.fallbacks: list[bool] = []

    def append(self, ok: bool, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Chain the motion ``x_k = R x_{k-1} + t`` if ``ok``, else the fallback; return the new ``(4, 4)`` pose."""
        if ok:
            self.last_motion = (R, t)
        R_used, t_used = self.last_motion if self.last_motion is not None else (np.eye(3), np.zeros(3))
        self.poses.append(pose_update(self.poses[-1], R_used, t_used))
        self.fallbacks.append(not ok)
        return self.poses[-1]


def relative_motion(pose_prev: np.ndarray, pose_curr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Motion ``(R, t)`` with ``x_k = R x_{k-1} + t`` between two camera-to-world poses.

    The inverse of :func:`pose_update`: ``T = inv(P_k) @ P_{k-1}``.
    """
    T = invert_transform(pose_curr) @ np.asarray(pose_prev, dtype=float)
    return T[..., :3, :3], T[..., :3, 3]


def rotation_angle(R: np.ndarray) -> np.ndarray:
    """Rotation angle in radians, in [0, pi], of rotation matrices ``(..., 3, 3)``."""
    if type(R) is np.ndarray and R.shape == (3, 3) and R.dtype == np.float64:
        angle = _rotation_angle_one(R)
        if angle is not None:
            return angle
    R = np.asarray(R, dtype=float)
    # atan2 of sin and cos keeps full precision near 0, where arccos(1 - e) loses half the digits.
    cos = (np.trace(R, axis1=-2, axis2=-1) - 1) / 2
    vee = np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1
    )
    sin = np.linalg.norm(vee, axis=-1) / 2
    return np.arctan2(sin, cos)


def _rotation_angle_one(R: np.ndarray) -> np.float64 | None:
    """:func:`rotation_angle` of one finite ``(3, 3)`` float64 matrix on Python floats, bit for bit:
    numpy's trace and the norm's ``add.reduce`` over three values sum them in order
    (``tests/stereovo/test_geometry.py`` holds numpy to that), sqrt is correctly rounded in both, and
    ``arctan2`` stays numpy's. None for a matrix with NaN or inf (numpy's path, and its warnings). A
    frame's metrics ask for one angle; numpy's calls on 3-vectors cost ten times the sums."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rows = R.tolist()
    if not all(math.isfinite(x) for row in rows for x in row):
        return None
    cos = (((r00 + r11) + r22) - 1) / 2
    v0, v1, v2 = r21 - r12, r02 - r20, r10 - r01
    sin = math.sqrt((v0 * v0 + v1 * v1) + v2 * v2) / 2
    return np.arctan2(sin, cos)


def rotation_error(R_est: np.ndarray, R_true: np.ndarray) -> np.ndarray:
    """Angle in radians of ``R_est^T R_true`` (the geodesic distance on SO(3))."""
    if type(R_est) is np.ndarray and R_est.ndim == 2 and R_est.dtype == np.float64:
        return rotation_angle(R_est.T @ R_true)  # the same transposed view, without swapaxes' wrapper
    return rotation_angle(np.swapaxes(np.asarray(R_est, dtype=float), -1, -2) @ R_true)


def translation_error(t_est: np.ndarray, t_true: np.ndarray) -> np.ndarray:
    """Euclidean distance in metres between translation vectors ``(..., 3)``."""
    d = np.asarray(t_est, dtype=float) - t_true
    if d.shape == (3,) and d.dtype == np.float64:
        # one pair (a frame's metrics): the norm's in-order sum of squares on floats (see _rotation_angle_one)
        d0, d1, d2 = d.tolist()
        return np.float64(math.sqrt((d0 * d0 + d1 * d1) + d2 * d2))
    return np.linalg.norm(d, axis=-1)


def random_rotation(rng: np.random.Generator, max_angle: float = np.pi) -> np.ndarray:
    """A rotation with a uniformly random axis and angle uniform in [0, max_angle] (radians)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return so3_exp(axis * rng.uniform(0, max_angle))


def quaternion_from_rotation(R: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` ordered ``(qx, qy, qz, qw)`` with ``qw >= 0`` (TUM order)."""
    R = np.asarray(R, dtype=float)
    w = so3_log(R)
    theta = np.linalg.norm(w, axis=-1, keepdims=True)
    axis = np.where(theta > _SMALL_ANGLE, w / np.where(theta > _SMALL_ANGLE, theta, 1.0), 0.0)
    q = np.concatenate([axis * np.sin(theta / 2), np.cos(theta / 2)], axis=-1)
    return np.where(q[..., 3:] < 0, -q, q)
