"""The normal equations of a motion's least-squares fit and their noise sandwich, for the pose covariance.

Compiled kernels behind :func:`stereovo.estimation.covariance.pose_covariance`: one pass over the
inliers accumulates ``A = sum J^T J`` and ``S = sum (J^T F)(J^T F)^T`` with 3-vectors, never
building a point's ``(8, 6)`` Jacobian.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _projection_terms(p0, p1, p2, fx, fy, b, shared, M, JE):
    """For a point ``p`` seen by the rectified pair, with ``J = d(uL, vL, uR, vR)/dp (4, 3)``:
    ``M = J^T J (3, 3)`` and ``JE = J^T E (3, k)``, E mapping the measured pixels to the four
    rows (``(uL, uR, v)`` with one v, else the identity)."""
    iz = 1.0 / p2
    a_l = (fx * iz, 0.0, -fx * p0 * iz * iz)
    a_v = (0.0, fy * iz, -fy * p1 * iz * iz)  # the vL and vR rows are equal
    a_r = (fx * iz, 0.0, -fx * (p0 - b) * iz * iz)
    for i in range(3):
        for j in range(3):
            M[i, j] = a_l[i] * a_l[j] + 2.0 * a_v[i] * a_v[j] + a_r[i] * a_r[j]
        if shared:
            JE[i, 0], JE[i, 1], JE[i, 2] = a_l[i], a_r[i], 2.0 * a_v[i]
        else:
            JE[i, 0], JE[i, 1], JE[i, 2], JE[i, 3] = a_l[i], a_v[i], a_r[i], a_v[i]


@njit(cache=True, nogil=True)
def _triangulation_columns(meas, i, fx, fy, cx, cy, b, shared, T):
    """``T (3, k)``: d(x, y, z) / d(measured pixels) of measurement ``meas[i] (4,)``: columns
    ``(uL, uR, v)`` with one v (``shared``), else ``(uL, vL, uR, vR)``."""
    d = meas[i, 0] - meas[i, 2]
    z = fx * b / d
    x = (meas[i, 0] - cx) * z / fx
    y = ((meas[i, 1] + meas[i, 3]) / 2 - cy) * z / fy
    T[:, :] = 0.0
    if shared:
        T[0, 0], T[0, 1] = z / fx - x / d, x / d
        T[1, 0], T[1, 1], T[1, 2] = -y / d, y / d, z / fy
        T[2, 0], T[2, 1] = -z / d, z / d
    else:
        T[0, 0], T[0, 2] = z / fx - x / d, x / d
        T[1, 0], T[1, 1], T[1, 2], T[1, 3] = -y / d, z / (2 * fy), y / d, z / (2 * fy)
        T[2, 0], T[2, 2] = -z / d, z / d


@njit(cache=True, nogil=True)
def _add_lifted(A, M, c0, c1, c2, MG):
    """``A += G^T M G`` for ``G = +-[I | -c^] (3, 6)``, ``G^T w = +-(w, c x w)`` (the sign cancels);
    ``MG (3, 6)`` is scratch space."""
    # columns of M G: M e_j (j < 3), and M (e_j x c) for the rotation part (-c^ e_j = e_j x c)
    for r in range(3):
        MG[r, 0], MG[r, 1], MG[r, 2] = M[r, 0], M[r, 1], M[r, 2]
        MG[r, 3] = M[r, 2] * c1 - M[r, 1] * c2  # M (e_x x c), e_x x c = (0, -c2, c1)
        MG[r, 4] = M[r, 0] * c2 - M[r, 2] * c0  # e_y x c = (c2, 0, -c0)
        MG[r, 5] = M[r, 1] * c0 - M[r, 0] * c1  # e_z x c = (-c1, c0, 0)
    for j in range(6):
        w0, w1, w2 = MG[0, j], MG[1, j], MG[2, j]
        col = (w0, w1, w2, c1 * w2 - c2 * w1, c2 * w0 - c0 * w2, c0 * w1 - c1 * w0)
        for i in range(6):
            A[i, j] += col[i]  # sign^2 = 1


@njit(cache=True, nogil=True)
def pose_normal_equations(R, t, X, Y, mp, mc, cam, rows, min_depth):
    """``A = sum J^T J`` and ``S = sum (J^T F)(J^T F)^T`` (``(6, 6)`` each) over ``rows`` of the
    symmetric reprojection residuals (see :func:`stereovo.estimation.covariance.pose_covariance`), and the number of rows used
    (those in front of both cameras).

    Written with 3-vectors: the forward rows are ``J_P G_f`` with ``G_f = [I | -P^]``, the
    backward rows ``J_Q R^T G_b`` with ``G_b = [-I | Y^]``, so ``J^T F`` of the k-1 pixels is
    ``G_f^T (M_P R T_prev) + G_b^T R (J_Q^T E)`` and of the k pixels
    ``-G_f^T (J_P^T E) + G_b^T R (M_Q R^T T_curr)`` (``M = J^T J``, T the triangulation
    Jacobians, E the measured pixels' rows).
    """
    fx, fy, cx, cy, b = cam[0], cam[1], cam[2], cam[3], cam[4]
    shared = cam[5] == 1.0
    k = 3 if shared else 4
    A = np.zeros((6, 6))
    S = np.zeros((6, 6))
    Mp, Mq, N = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    JEp, JEq, T = np.empty((3, k)), np.empty((3, k)), np.empty((3, k))
    W = np.empty((3, 2 * k, 2))  # per measured pixel: the 3-vectors lifted by G_f^T and by G_b^T
    MG = np.empty((3, 6))
    RM = np.empty((3, 3))
    used = 0
    for i in rows:
        x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
        y0, y1, y2 = Y[i, 0], Y[i, 1], Y[i, 2]
        p0 = R[0, 0] * x0 + R[0, 1] * x1 + R[0, 2] * x2 + t[0]
        p1 = R[1, 0] * x0 + R[1, 1] * x1 + R[1, 2] * x2 + t[1]
        p2 = R[2, 0] * x0 + R[2, 1] * x1 + R[2, 2] * x2 + t[2]
        d0, d1, d2 = y0 - t[0], y1 - t[1], y2 - t[2]
        q0 = R[0, 0] * d0 + R[1, 0] * d1 + R[2, 0] * d2
        q1 = R[0, 1] * d0 + R[1, 1] * d1 + R[2, 1] * d2
        q2 = R[0, 2] * d0 + R[1, 2] * d1 + R[2, 2] * d2
        if p2 <= min_depth or q2 <= min_depth:
            continue  # no Jacobian behind the camera (the refinement gives such a point none either)
        used += 1
        _projection_terms(p0, p1, p2, fx, fy, b, shared, Mp, JEp)
        _projection_terms(q0, q1, q2, fx, fy, b, shared, Mq, JEq)
        # N = R M_Q R^T: the backward block's 3x3 term in frame k
        for r in range(3):
            for c in range(3):
                RM[r, c] = R[r, 0] * Mq[0, c] + R[r, 1] * Mq[1, c] + R[r, 2] * Mq[2, c]
        for r in range(3):
            for c in range(3):
                N[r, c] = RM[r, 0] * R[c, 0] + RM[r, 1] * R[c, 1] + RM[r, 2] * R[c, 2]
        _add_lifted(A, Mp, p0, p1, p2, MG)
        _add_lifted(A, N, y0, y1, y2, MG)
        # k-1 pixels: forward part M_P R T_prev (lifted by G_f), backward part R J_Q^T E (by G_b, sign -1)
        _triangulation_columns(mp, i, fx, fy, cx, cy, b, shared, T)
        for c in range(k):
            rt0 = R[0, 0] * T[0, c] + R[0, 1] * T[1, c] + R[0, 2] * T[2, c]
            rt1 = R[1, 0] * T[0, c] + R[1, 1] * T[1, c] + R[1, 2] * T[2, c]
            rt2 = R[2, 0] * T[0, c] + R[2, 1] * T[1, c] + R[2, 2] * T[2, c]
            for r in range(3):
                W[r, c, 0] = Mp[r, 0] * rt0 + Mp[r, 1] * rt1 + Mp[r, 2] * rt2
                W[r, c, 1] = -(R[r, 0] * JEq[0, c] + R[r, 1] * JEq[1, c] + R[r, 2] * JEq[2, c])
        # k pixels: forward part -J_P^T E (by G_f), backward part R M_Q R^T T_curr = N T_curr (by G_b)
        _triangulation_columns(mc, i, fx, fy, cx, cy, b, shared, T)
        for c in range(k):
            for r in range(3):
                W[r, k + c, 0] = -JEp[r, c]
                W[r, k + c, 1] = N[r, 0] * T[0, c] + N[r, 1] * T[1, c] + N[r, 2] * T[2, c]
        for c in range(2 * k):
            f0, f1, f2 = W[0, c, 0], W[1, c, 0], W[2, c, 0]
            g0, g1, g2 = W[0, c, 1], W[1, c, 1], W[2, c, 1]
            # G_f^T f = (f, P x f); G_b^T g = (-g, -Y x g)
            col = (
                f0 - g0, f1 - g1, f2 - g2,
                (p1 * f2 - p2 * f1) - (y1 * g2 - y2 * g1),
                (p2 * f0 - p0 * f2) - (y2 * g0 - y0 * g2),
                (p0 * f1 - p1 * f0) - (y0 * g1 - y1 * g0),
            )
            for u in range(6):
                for v in range(u, 6):
                    S[u, v] += col[u] * col[v]
    for u in range(6):
        for v in range(u):
            S[u, v] = S[v, u]
    return A, S, used
