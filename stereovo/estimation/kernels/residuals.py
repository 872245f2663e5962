"""Compiled reprojection residuals: the symmetric 8-row residual with its Jacobian, and the forward error.

A point's symmetric residual (:func:`symmetric_residuals`) is its forward reprojection at k
(uL, vL, uR, vR) and its backward one at k-1, with the 8 x 6 Jacobian under the left
perturbation; :func:`forward_reprojection_sq` is the squared forward error that scoring
thresholds, written once per point in :func:`point_reprojection_sq`.
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels.base import BEHIND_CAMERA_RESIDUAL, MIN_DEPTH, inline_jit, jit


@inline_jit
def _forward_row(jac, r, a0, a1, a2, p0, p1, p2):
    """Row ``r`` for projection gradient ``a`` at the forward point P: d/d rho = a, d/d omega = P x a."""
    jac[r, 0], jac[r, 1], jac[r, 2] = a0, a1, a2
    jac[r, 3] = p1 * a2 - p2 * a1
    jac[r, 4] = p2 * a0 - p0 * a2
    jac[r, 5] = p0 * a1 - p1 * a0


@inline_jit
def _backward_row(jac, r, a0, a1, a2, R, y0, y1, y2):
    """Row ``r`` for gradient ``a`` at Q = R^T (Y - t): with c = a R^T, d/d rho = -c, d/d omega = -(Y x c)."""
    c0 = a0 * R[0, 0] + a1 * R[0, 1] + a2 * R[0, 2]
    c1 = a0 * R[1, 0] + a1 * R[1, 1] + a2 * R[1, 2]
    c2 = a0 * R[2, 0] + a1 * R[2, 1] + a2 * R[2, 2]
    jac[r, 0], jac[r, 1], jac[r, 2] = -c0, -c1, -c2
    jac[r, 3] = y2 * c1 - y1 * c2
    jac[r, 4] = y0 * c2 - y2 * c0
    jac[r, 5] = y1 * c0 - y0 * c1


@inline_jit
def moved_points(R, t, X, Y, m):
    """Point ``m`` in the other frame: ``P = R X_m + t`` (k-1 point at k) and ``Q = R^T (Y_m - t)``
    (k point at k-1), as ``(p0, p1, p2, q0, q1, q2)``."""
    p0 = R[0, 0] * X[m, 0] + R[0, 1] * X[m, 1] + R[0, 2] * X[m, 2] + t[0]
    p1 = R[1, 0] * X[m, 0] + R[1, 1] * X[m, 1] + R[1, 2] * X[m, 2] + t[1]
    p2 = R[2, 0] * X[m, 0] + R[2, 1] * X[m, 1] + R[2, 2] * X[m, 2] + t[2]
    d0, d1, d2 = Y[m, 0] - t[0], Y[m, 1] - t[1], Y[m, 2] - t[2]
    q0 = R[0, 0] * d0 + R[1, 0] * d1 + R[2, 0] * d2
    q1 = R[0, 1] * d0 + R[1, 1] * d1 + R[2, 1] * d2
    q2 = R[0, 2] * d0 + R[1, 2] * d1 + R[2, 2] * d2
    return p0, p1, p2, q0, q1, q2


@inline_jit
def stereo_residuals(p0, p1, p2, fx, fy, cx, cy, b, u_l, v_l, u_r, v_r):
    """``(1 / p2, r_uL, r_vL, r_uR, r_vR)``: the point ``p`` (``p2 > 0``) projected into a rectified
    stereo pair minus its measurement ``(u_l, v_l, u_r, v_r)``, in pixels."""
    ip = 1.0 / p2
    return (
        ip, fx * p0 * ip + cx - u_l, fy * p1 * ip + cy - v_l, fx * (p0 - b) * ip + cx - u_r, fy * p1 * ip + cy - v_r,
    )


@inline_jit
def _point_rows(R, t, X, Y, mp, mc, m, cam, res, jac, want_jac):
    """Fill ``res (8,)`` (and ``jac (8, 6)``) for point ``m`` of ``X, Y (M, 3)``, ``mp, mc (M, 4)``;
    False if it is behind a camera. (Indexing here rather than passing row views keeps the
    hot loop free of per-point array views.)"""
    fx, fy, cx, cy, b = cam[0], cam[1], cam[2], cam[3], cam[4]
    p0, p1, p2, q0, q1, q2 = moved_points(R, t, X, Y, m)
    if p2 <= MIN_DEPTH or q2 <= MIN_DEPTH:
        for r in range(8):
            res[r] = BEHIND_CAMERA_RESIDUAL
        if want_jac:
            jac[:, :] = 0.0
        return False
    ip, r0, r1, r2, r3 = stereo_residuals(p0, p1, p2, fx, fy, cx, cy, b, mc[m, 0], mc[m, 1], mc[m, 2], mc[m, 3])
    iq, r4, r5, r6, r7 = stereo_residuals(q0, q1, q2, fx, fy, cx, cy, b, mp[m, 0], mp[m, 1], mp[m, 2], mp[m, 3])
    res[0], res[1], res[2], res[3], res[4], res[5], res[6], res[7] = r0, r1, r2, r3, r4, r5, r6, r7
    if not want_jac:
        return True
    # d(projection)/d(point) rows of the forward point P (row 3 equals row 1) ...
    _forward_row(jac, 0, fx * ip, 0.0, -fx * p0 * ip * ip, p0, p1, p2)
    _forward_row(jac, 1, 0.0, fy * ip, -fy * p1 * ip * ip, p0, p1, p2)
    _forward_row(jac, 2, fx * ip, 0.0, -fx * (p0 - b) * ip * ip, p0, p1, p2)
    jac[3, :] = jac[1, :]
    # ... and of the backward point Q
    _backward_row(jac, 4, fx * iq, 0.0, -fx * q0 * iq * iq, R, Y[m, 0], Y[m, 1], Y[m, 2])
    _backward_row(jac, 5, 0.0, fy * iq, -fy * q1 * iq * iq, R, Y[m, 0], Y[m, 1], Y[m, 2])
    _backward_row(jac, 6, fx * iq, 0.0, -fx * (q0 - b) * iq * iq, R, Y[m, 0], Y[m, 1], Y[m, 2])
    jac[7, :] = jac[5, :]
    return True


@jit
def symmetric_residuals(R, t, X, Y, mp, mc, cam, want_jac):
    """Residuals ``(H, M, 8)`` and, if ``want_jac``, Jacobians ``(H, M, 8, 6)`` (else ``(0, 0, 8, 6)``)."""
    H, M = R.shape[0], X.shape[1]
    res = np.empty((H, M, 8))
    jac = np.zeros((H, M, 8, 6)) if want_jac else np.zeros((0, 0, 8, 6))
    scratch = np.zeros((8, 6))
    for h in range(H):
        g = h if X.shape[0] > 1 else 0
        for m in range(M):
            _point_rows(R[h], t[h], X[g], Y[g], mp[g], mc[g], m, cam, res[h, m], scratch, want_jac)
            if want_jac:
                jac[h, m] = scratch
    return res, jac


@inline_jit
def point_reprojection_sq(r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2,
                          x0, x1, x2, m0, m1, m2, m3, fx, fy, cx, cy, b):
    """Squared forward reprojection error (px^2) of one point ``x`` under one motion ``(R, t)``
    against its frame-k measurement ``m = (uL, vL, uR, vR)``; ``inf`` behind the camera.

    The one definition of the per-point arithmetic that full scoring and the compiled early-
    rejection tests share (scalars in, so a caller's loop over points still vectorises).
    """
    p2 = r20 * x0 + r21 * x1 + r22 * x2 + t2
    ip = 1.0 / p2
    p0 = r00 * x0 + r01 * x1 + r02 * x2 + t0
    p1 = r10 * x0 + r11 * x1 + r12 * x2 + t1
    uL = fx * p0 * ip + cx
    v = fy * p1 * ip + cy
    uR = uL - fx * b * ip
    e0, e1, e2, e3 = uL - m0, v - m1, uR - m2, v - m3
    sq = e0 * e0 + e2 * e2 + e1 * e1 + e3 * e3
    return sq if p2 > MIN_DEPTH else np.inf


@jit
def forward_reprojection_sq(R, t, X, mc, cam):
    """``(H, N)`` squared forward reprojection errors (px^2) of ``X (N, 3)`` in both images at k; inf behind.

    The coordinates are copied into one contiguous array each and the depth test is a select,
    not a branch, so the loop over points runs four points per SIMD instruction: four times
    faster than reading rows, with the same arithmetic per point.
    """
    fx, fy, cx, cy, b = cam[0], cam[1], cam[2], cam[3], cam[4]
    H, N = R.shape[0], X.shape[0]
    out = np.empty((H, N))
    X0, X1, X2 = X[:, 0].copy(), X[:, 1].copy(), X[:, 2].copy()
    m0, m1, m2, m3 = mc[:, 0].copy(), mc[:, 1].copy(), mc[:, 2].copy(), mc[:, 3].copy()
    for h in range(H):
        r00, r01, r02 = R[h, 0, 0], R[h, 0, 1], R[h, 0, 2]
        r10, r11, r12 = R[h, 1, 0], R[h, 1, 1], R[h, 1, 2]
        r20, r21, r22 = R[h, 2, 0], R[h, 2, 1], R[h, 2, 2]
        t0, t1, t2 = t[h, 0], t[h, 1], t[h, 2]
        row = out[h]
        for n in range(N):
            row[n] = point_reprojection_sq(
                r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2,
                X0[n], X1[n], X2[n], m0[n], m1[n], m2[n], m3[n], fx, fy, cx, cy, b,
            )
    return out

