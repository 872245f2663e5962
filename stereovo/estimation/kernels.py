"""Compiled (numba) kernels behind the hot paths of the estimator core.

The numpy formulation of these computations builds ``(H, N, 8, 6)`` Jacobians and
a dozen ``(H, N)`` temporaries per call, and the core calls them a few hundred
times per frame; memory traffic and per-call overhead, not arithmetic, set the
time. Each kernel here walks the hypotheses and points once, keeps a point's
residual and Jacobian in registers and accumulates what the caller needs (the
normal equations, a cost, one squared residual). The Python wrappers in
:mod:`stereovo.estimation.reprojection`, :mod:`stereovo.estimation.scoring`,
:mod:`stereovo.estimation.solvers`, :mod:`stereovo.estimation.samplers`,
:mod:`stereovo.estimation.refinement` (whose refine / re-gate rounds run here in one call,
:func:`refine_rounds`) and :mod:`stereovo.estimation.sample_check` keep the shapes and
documentation; nothing outside them calls this module.

Conventions (as in :mod:`stereovo.estimation.reprojection`): a motion maps
``x_k = R x_{k-1} + t``; the perturbation is ``T <- exp(delta^) T`` with
``delta = (rho, omega)``; a point's symmetric residual has 8 rows (forward
uL, vL, uR, vR at k, then backward at k-1), in pixels.

Array arguments: ``R (H, 3, 3)``, ``t (H, 3)``; point arrays ``(G, M, .)`` where
``G`` is 1 (shared by all hypotheses) or H (one set per hypothesis); ``cam`` is
``(fx, fy, cx, cy, baseline, v_per_match)`` (:attr:`stereovo.camera.StereoCamera.parameters`). All float64, C-contiguous (the wrappers ensure it).
No kernel draws random numbers or reduces in parallel, so results are
bit-for-bit repeatable.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from stereovo.estimation.rigidity import distance_change_sq_jit, rigid_distance_consistent_jit

MIN_DEPTH = 1e-3  # a transformed point this close to the camera plane cannot be projected
BEHIND_CAMERA_RESIDUAL = 1e3  # its residual rows are set to this and its Jacobian zeroed
_SMALL_ANGLE = 1e-4  # below it, Rodrigues coefficients use their Taylor series

_jit = njit(cache=True, nogil=True, error_model="numpy")
# Helpers that take arrays and run once per point or per hypothesis are inlined into their callers:
# a compiled call passes each array as a struct and reference-counts it on entry and exit, which
# cost more than the arithmetic of a point's residual (89 against ~20 ns measured).
_inline_jit = njit(cache=True, nogil=True, error_model="numpy", inline="always")


@_inline_jit
def _forward_row(jac, r, a0, a1, a2, p0, p1, p2):
    """Row ``r`` for projection gradient ``a`` at the forward point P: d/d rho = a, d/d omega = P x a."""
    jac[r, 0], jac[r, 1], jac[r, 2] = a0, a1, a2
    jac[r, 3] = p1 * a2 - p2 * a1
    jac[r, 4] = p2 * a0 - p0 * a2
    jac[r, 5] = p0 * a1 - p1 * a0


@_inline_jit
def _backward_row(jac, r, a0, a1, a2, R, y0, y1, y2):
    """Row ``r`` for gradient ``a`` at Q = R^T (Y - t): with c = a R^T, d/d rho = -c, d/d omega = -(Y x c)."""
    c0 = a0 * R[0, 0] + a1 * R[0, 1] + a2 * R[0, 2]
    c1 = a0 * R[1, 0] + a1 * R[1, 1] + a2 * R[1, 2]
    c2 = a0 * R[2, 0] + a1 * R[2, 1] + a2 * R[2, 2]
    jac[r, 0], jac[r, 1], jac[r, 2] = -c0, -c1, -c2
    jac[r, 3] = y2 * c1 - y1 * c2
    jac[r, 4] = y0 * c2 - y2 * c0
    jac[r, 5] = y1 * c0 - y0 * c1


@_inline_jit
def _moved_points(R, t, X, Y, m):
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


@_inline_jit
def _stereo_residuals(p0, p1, p2, fx, fy, cx, cy, b, u_l, v_l, u_r, v_r):
    """``(1 / p2, r_uL, r_vL, r_uR, r_vR)``: the point ``p`` (``p2 > 0``) projected into a rectified
    stereo pair minus its measurement ``(u_l, v_l, u_r, v_r)``, in pixels."""
    ip = 1.0 / p2
    return (
        ip, fx * p0 * ip + cx - u_l, fy * p1 * ip + cy - v_l, fx * (p0 - b) * ip + cx - u_r, fy * p1 * ip + cy - v_r,
    )


@_inline_jit
def _point_rows(R, t, X, Y, mp, mc, m, cam, res, jac, want_jac):
    """Fill ``res (8,)`` (and ``jac (8, 6)``) for point ``m`` of ``X, Y (M, 3)``, ``mp, mc (M, 4)``;
    False if it is behind a camera. (Indexing here rather than passing row views keeps the
    hot loop free of per-point array views.)"""
    fx, fy, cx, cy, b = cam[0], cam[1], cam[2], cam[3], cam[4]
    p0, p1, p2, q0, q1, q2 = _moved_points(R, t, X, Y, m)
    if p2 <= MIN_DEPTH or q2 <= MIN_DEPTH:
        for r in range(8):
            res[r] = BEHIND_CAMERA_RESIDUAL
        if want_jac:
            jac[:, :] = 0.0
        return False
    ip, r0, r1, r2, r3 = _stereo_residuals(p0, p1, p2, fx, fy, cx, cy, b, mc[m, 0], mc[m, 1], mc[m, 2], mc[m, 3])
    iq, r4, r5, r6, r7 = _stereo_residuals(q0, q1, q2, fx, fy, cx, cy, b, mp[m, 0], mp[m, 1], mp[m, 2], mp[m, 3])
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


@_jit
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


@_inline_jit
def _irls_weight(base, sq, huber):
    """The point's weight: its base weight, times Huber's ``huber / |r|`` beyond the threshold."""
    if huber > 0.0:
        norm = np.sqrt(sq)
        if norm > huber:
            return base * huber / max(norm, 1e-12)
    return base


@_inline_jit
def _stereo_terms(p0, p1, p2, fx, fy, cx, cy, b, u_l, v_l, u_r, v_r):
    """One point ``p`` seen in a rectified stereo pair against its measurement ``(u_l, v_l, u_r, v_r)``.

    Returns its squared residual (px^2), and the Gauss-Newton terms over its four pixel rows, with
    ``a_r = d(pixel_r)/dp``: ``M = sum a_r a_r^T`` (upper triangle m00, m02, m11, m12, m22; m01 is 0
    because no row depends on both x and y) and ``v = sum a_r res_r``. ``p2`` must be positive.
    """
    ip, r0, r1, r2, r3 = _stereo_residuals(p0, p1, p2, fx, fy, cx, cy, b, u_l, v_l, u_r, v_r)
    sq = r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3
    ex, ey = fx * ip, fy * ip
    # the rows' depth derivatives; both v rows share a_v = (0, ey, cv)
    cl, cv, cr = -fx * p0 * ip * ip, -fy * p1 * ip * ip, -fx * (p0 - b) * ip * ip
    rv = r1 + r3
    return (
        sq,
        2.0 * ex * ex, ex * (cl + cr), 2.0 * ey * ey, 2.0 * ey * cv, cl * cl + cr * cr + 2.0 * cv * cv,
        ex * (r0 + r2), ey * rv, cl * r0 + cr * r2 + cv * rv,
    )


@_inline_jit
def _add_point_block(A, g, wm, p0, p1, p2, m00, m02, m11, m12, m22, v0, v1, v2):
    """``A += wm G^T M G`` (upper triangle) and ``g += wm G^T v`` for ``G = [I | -p^]`` (3, 6), the
    derivative of a point ``p`` under the left perturbation ``exp(delta^)``, ``M`` symmetric with m01 = 0.

    Written out in scalars because ``G^T M G`` has this fixed structure: the rotation blocks are
    ``C = -M p^`` (row i of C is ``p x`` row i of M) and ``p^ C``.
    """
    m00, m02, m11, m12, m22 = wm * m00, wm * m02, wm * m11, wm * m12, wm * m22
    v0, v1, v2 = wm * v0, wm * v1, wm * v2
    # rows of M: (m00, 0, m02), (0, m11, m12), (m02, m12, m22)
    c00, c01, c02 = p1 * m02, p2 * m00 - p0 * m02, -p1 * m00
    c10, c11, c12 = p1 * m12 - p2 * m11, -p0 * m12, p0 * m11
    c20, c21, c22 = p1 * m22 - p2 * m12, p2 * m02 - p0 * m22, p0 * m12 - p1 * m02
    A[0, 0] += m00
    A[0, 2] += m02
    A[1, 1] += m11
    A[1, 2] += m12
    A[2, 2] += m22
    A[0, 3] += c00
    A[0, 4] += c01
    A[0, 5] += c02
    A[1, 3] += c10
    A[1, 4] += c11
    A[1, 5] += c12
    A[2, 3] += c20
    A[2, 4] += c21
    A[2, 5] += c22
    # (p^ C)_ij = (p x column j of C)_i
    A[3, 3] += p1 * c20 - p2 * c10
    A[3, 4] += p1 * c21 - p2 * c11
    A[3, 5] += p1 * c22 - p2 * c12
    A[4, 4] += p2 * c01 - p0 * c21
    A[4, 5] += p2 * c02 - p0 * c22
    A[5, 5] += p0 * c12 - p1 * c02
    g[0] += v0
    g[1] += v1
    g[2] += v2
    g[3] += p1 * v2 - p2 * v1
    g[4] += p2 * v0 - p0 * v2
    g[5] += p0 * v1 - p1 * v0


@_jit
def _cost_and_normal_equations(R, t, X, Y, mp, mc, cam, w, huber, A, g, want_system, A_back, g_back):
    """Weighted squared cost of one hypothesis; fills ``A (6, 6)``, ``g (6,)`` if ``want_system``.

    The same sums as ``J^T W J`` and ``J^T W r`` over the Jacobian rows of :func:`_point_rows`, built
    from each side's 3x3 terms (:func:`_add_point_block`) instead of its 8 x 6 rows. The backward
    rows ``-a^T R^T [I | -Y^]`` equal ``-a^T [I | -Y'^] diag(R^T, R^T)`` with ``Y' = R^T Y``, so
    they are summed in that rotated frame (``A_back (6, 6)``, ``g_back (6,)``, scratch space) and
    rotated into ``A, g`` once.
    """
    fx, fy, cx, cy, b = cam[0], cam[1], cam[2], cam[3], cam[4]
    # s = R^T t, so that the backward point Q = R^T (Y - t) plus s is Y' = R^T Y
    s0 = R[0, 0] * t[0] + R[1, 0] * t[1] + R[2, 0] * t[2]
    s1 = R[0, 1] * t[0] + R[1, 1] * t[1] + R[2, 1] * t[2]
    s2 = R[0, 2] * t[0] + R[1, 2] * t[1] + R[2, 2] * t[2]
    cost = 0.0
    if want_system:
        A[:, :] = 0.0
        g[:] = 0.0
        A_back[:, :] = 0.0
        g_back[:] = 0.0
    for m in range(X.shape[0]):
        if w[m] == 0.0:
            continue
        p0, p1, p2, q0, q1, q2 = _moved_points(R, t, X, Y, m)
        if p2 <= MIN_DEPTH or q2 <= MIN_DEPTH:
            # residual rows of BEHIND_CAMERA_RESIDUAL and no Jacobian, as in _point_rows
            cost += _irls_weight(w[m], 8.0 * BEHIND_CAMERA_RESIDUAL**2, huber) * 8.0 * BEHIND_CAMERA_RESIDUAL**2
            continue
        fwd = _stereo_terms(p0, p1, p2, fx, fy, cx, cy, b, mc[m, 0], mc[m, 1], mc[m, 2], mc[m, 3])
        bwd = _stereo_terms(q0, q1, q2, fx, fy, cx, cy, b, mp[m, 0], mp[m, 1], mp[m, 2], mp[m, 3])
        sq = fwd[0] + bwd[0]
        wm = _irls_weight(w[m], sq, huber)
        cost += wm * sq
        if want_system:
            _add_point_block(A, g, wm, p0, p1, p2, fwd[1], fwd[2], fwd[3], fwd[4], fwd[5], fwd[6], fwd[7], fwd[8])
            _add_point_block(
                A_back, g_back, wm, q0 + s0, q1 + s1, q2 + s2, bwd[1], bwd[2], bwd[3], bwd[4], bwd[5], bwd[6], bwd[7],
                bwd[8],
            )
    if want_system:
        for i in range(6):
            for j in range(i):
                A_back[i, j] = A_back[j, i]
        # A += diag(R, R) A_back diag(R, R)^T, g -= diag(R, R) g_back (the backward rows carry a minus sign)
        for bi in range(0, 6, 3):
            for bj in range(bi, 6, 3):
                B = A_back[bi:bi + 3, bj:bj + 3]
                for i in range(3):
                    # row i of R B, then its products with the rows of R
                    r0 = R[i, 0] * B[0, 0] + R[i, 1] * B[1, 0] + R[i, 2] * B[2, 0]
                    r1 = R[i, 0] * B[0, 1] + R[i, 1] * B[1, 1] + R[i, 2] * B[2, 1]
                    r2 = R[i, 0] * B[0, 2] + R[i, 1] * B[1, 2] + R[i, 2] * B[2, 2]
                    for j in range(3):
                        A[bi + i, bj + j] += r0 * R[j, 0] + r1 * R[j, 1] + r2 * R[j, 2]
            for i in range(3):
                g[bi + i] -= R[i, 0] * g_back[bi] + R[i, 1] * g_back[bi + 1] + R[i, 2] * g_back[bi + 2]
        for i in range(6):
            for j in range(i):
                A[i, j] = A[j, i]
    return cost


@_jit
def _solve_damped(A, g, damping, delta, L, y):
    """``delta = -(A + damping diag(A)) ^-1 g`` by Cholesky; False if not positive definite.

    ``L (6, 6)`` and ``y (6,)`` are scratch space.
    """
    for i in range(6):
        for j in range(i + 1):
            s = A[i, j]
            if i == j:
                s += damping * max(A[i, i], 1e-9)
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if s <= 0.0:
                    return False
                L[i, i] = np.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    for i in range(6):
        s = -g[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    for i in range(5, -1, -1):
        s = y[i]
        for k in range(i + 1, 6):
            s -= L[k, i] * delta[k]
        delta[i] = s / L[i, i]
    return True


@_jit
def _apply_twist(R, t, delta, R_out, t_out, dR, dt):
    """``(R_out, t_out) = exp(delta^) (R, t)`` with ``delta = (rho, omega)`` (left perturbation).

    ``dR (3, 3)`` and ``dt (3,)`` are scratch space.
    """
    w0, w1, w2 = delta[3], delta[4], delta[5]
    theta = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if theta < _SMALL_ANGLE:
        th2 = theta * theta
        ca = 1.0 - th2 / 6.0 + th2 * th2 / 120.0
        cb = 0.5 - th2 / 24.0 + th2 * th2 / 720.0
        cc = 1.0 / 6.0 - th2 / 120.0 + th2 * th2 / 5040.0
    else:
        ca = np.sin(theta) / theta
        cb = (1.0 - np.cos(theta)) / (theta * theta)
        cc = (theta - np.sin(theta)) / (theta * theta * theta)
    # W = hat(w), W^2 = w w^T - theta^2 I: dR = I + ca W + cb W^2, V = I + cb W + cc W^2
    ww = ((w0 * w0, w0 * w1, w0 * w2), (w1 * w0, w1 * w1, w1 * w2), (w2 * w0, w2 * w1, w2 * w2))
    Wm = ((0.0, -w2, w1), (w2, 0.0, -w0), (-w1, w0, 0.0))
    th2 = theta * theta
    for i in range(3):
        dt[i] = 0.0
        for j in range(3):
            W2 = ww[i][j] - (th2 if i == j else 0.0)
            eye = 1.0 if i == j else 0.0
            dR[i, j] = eye + ca * Wm[i][j] + cb * W2
            dt[i] += (eye + cb * Wm[i][j] + cc * W2) * delta[j]
    for i in range(3):
        t_out[i] = dR[i, 0] * t[0] + dR[i, 1] * t[1] + dR[i, 2] * t[2] + dt[i]
        for j in range(3):
            R_out[i, j] = dR[i, 0] * R[0, j] + dR[i, 1] * R[1, j] + dR[i, 2] * R[2, j]


@_jit
def _lm_scratch():
    """Scratch arrays of one Levenberg-Marquardt run:
    A, g, delta, R_new, t_new, A_back, g_back, L, y, dR, dt, A_trial, g_trial."""
    return (
        np.empty((6, 6)), np.empty(6), np.empty(6), np.empty((3, 3)), np.empty(3), np.empty((6, 6)),
        np.empty(6), np.empty((6, 6)), np.empty(6), np.empty((3, 3)), np.empty(3),
        np.empty((6, 6)), np.empty(6),
    )


# A step that would move the pose by less than this fraction of its own standard deviation ends
# the refinement: what is left of it lies far inside the estimate's uncertainty.
CONVERGED_STEP_IN_STD = 0.01


@_jit
def _levenberg_marquardt(Rh, th, Xh, Yh, mph, mch, cam, wh, huber, iterations, damping, tolerance, step_control, scratch):
    """Refine one motion ``Rh, th`` in place; return its final weighted cost (see :func:`gauss_newton`)."""
    A, g, delta, R_new, t_new, A_back, g_back, L, y, dR, dt, A_trial, g_trial = scratch
    lam = damping
    cost = _cost_and_normal_equations(Rh, th, Xh, Yh, mph, mch, cam, wh, huber, A, g, True, A_back, g_back)
    # residual degrees of freedom: 8 rows per weighted point, 6 pose parameters
    n_rows = 0
    for m in range(wh.shape[0]):
        if wh[m] != 0.0:
            n_rows += 8
    dof = max(n_rows - 6, 1)
    for it in range(iterations):
        # after the last step only the cost is needed, not the normal equations
        last = it == iterations - 1
        if not _solve_damped(A, g, lam, delta, L, y):
            break
        if step_control:
            # delta^T A delta / sigma^2: the step's squared length in standard deviations of the
            # pose, with sigma^2 estimated from the residuals (the covariance is sigma^2 A^-1)
            moved = 0.0
            for i in range(6):
                for j in range(6):
                    moved += delta[i] * A[i, j] * delta[j]
            if moved * dof <= CONVERGED_STEP_IN_STD * CONVERGED_STEP_IN_STD * cost:
                break
        _apply_twist(Rh, th, delta, R_new, t_new, dR, dt)
        if not step_control:
            Rh[:, :] = R_new
            th[:] = t_new
            cost = _cost_and_normal_equations(Rh, th, Xh, Yh, mph, mch, cam, wh, huber, A, g, not last, A_back, g_back)
            continue
        # The trial pose's system is built in the same pass as its cost: near convergence every
        # step is accepted, so a separate cost-only pass would double the work.
        cost_new = _cost_and_normal_equations(
            R_new, t_new, Xh, Yh, mph, mch, cam, wh, huber, A_trial, g_trial, not last, A_back, g_back
        )
        if not cost_new <= cost:
            lam *= 10.0
            continue  # A and g still hold the current pose's system: retry with more damping
        lam *= 0.3
        Rh[:, :] = R_new
        th[:] = t_new
        cost = cost_new
        A[:, :] = A_trial
        g[:] = g_trial
        small = True
        for i in range(6):
            if abs(delta[i]) >= tolerance:
                small = False
        if small:
            break
    return cost


@_jit
def gauss_newton(R, t, X, Y, mp, mc, cam, weights, huber, iterations, damping, tolerance, step_control):
    """Per-hypothesis Gauss-Newton / Levenberg-Marquardt on the weighted symmetric reprojection error.

    With ``step_control`` a step that raises the cost is rejected and the damping multiplied
    by 10 (0.3 after an accepted step), and a hypothesis stops once its step is below
    ``tolerance`` or the next step would move it by less than ``CONVERGED_STEP_IN_STD`` of the
    pose's standard deviation (``delta^T A delta <= 1e-4 sigma^2``, ``sigma^2`` the residuals'
    variance; that step is not taken). Without it every step is taken (minimal samples started
    from a closed-form fit converge in one or two).

    Returns refined ``R (H, 3, 3)``, ``t (H, 3)`` and the final weighted cost ``(H,)`` (px^2).
    """
    H = R.shape[0]
    R_out = R.copy()
    t_out = t.copy()
    cost_out = np.empty(H)
    scratch = _lm_scratch()
    for h in range(H):
        gx = h if X.shape[0] > 1 else 0
        gw = h if weights.shape[0] > 1 else 0
        cost_out[h] = _levenberg_marquardt(
            R_out[h], t_out[h], X[gx], Y[gx], mp[gx], mc[gx], cam, weights[gw], huber,
            iterations, damping, tolerance, step_control, scratch,
        )
    return R_out, t_out, cost_out


@_inline_jit
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


@_jit
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


@_inline_jit
def _symmetric_quadratic(a, bb, c, d, e, f, x, y, z):
    """``v^T C^-1 v`` for the symmetric 3x3 ``C = [[a, bb, c], [bb, d, e], [c, e, f]]`` and ``v = (x, y, z)``,
    by the adjugate (no pivoting needed: C is a covariance)."""
    A00 = d * f - e * e
    A01 = c * e - bb * f
    A02 = bb * e - c * d
    A11 = a * f - c * c
    A12 = bb * c - a * e
    A22 = a * d - bb * bb
    det = a * A00 + bb * A01 + c * A02
    quad = A00 * x * x + A11 * y * y + A22 * z * z + 2.0 * (A01 * x * y + A02 * x * z + A12 * y * z)
    return quad / max(det, 1e-300)


@_inline_jit
def _congruence(a00, a01, a02, a10, a11, a12, a20, a21, a22, s00, s01, s02, s11, s12, s22):
    """Upper triangle ``(c00, c01, c02, c11, c12, c22)`` of ``A S A^T`` for a symmetric ``S``: a
    covariance carried through the linear map ``A``. In scalars, so that the per-point covariance
    stays in registers (through scratch arrays it cost twice as much)."""
    # rows of A S
    b00 = a00 * s00 + a01 * s01 + a02 * s02
    b01 = a00 * s01 + a01 * s11 + a02 * s12
    b02 = a00 * s02 + a01 * s12 + a02 * s22
    b10 = a10 * s00 + a11 * s01 + a12 * s02
    b11 = a10 * s01 + a11 * s11 + a12 * s12
    b12 = a10 * s02 + a11 * s12 + a12 * s22
    b20 = a20 * s00 + a21 * s01 + a22 * s02
    b21 = a20 * s01 + a21 * s11 + a22 * s12
    b22 = a20 * s02 + a21 * s12 + a22 * s22
    return (
        b00 * a00 + b01 * a01 + b02 * a02,
        b00 * a10 + b01 * a11 + b02 * a12,
        b00 * a20 + b01 * a21 + b02 * a22,
        b10 * a10 + b11 * a11 + b12 * a12,
        b10 * a20 + b11 * a21 + b12 * a22,
        b20 * a20 + b21 * a21 + b22 * a22,
    )


@_inline_jit
def _motion_entries(R, t, h):
    """Hypothesis ``h``'s ``R`` (row-major) and ``t`` as twelve scalars, read once per hypothesis."""
    return (
        R[h, 0, 0], R[h, 0, 1], R[h, 0, 2], R[h, 1, 0], R[h, 1, 1], R[h, 1, 2], R[h, 2, 0], R[h, 2, 1], R[h, 2, 2],
        t[h, 0], t[h, 1], t[h, 2],
    )


@_inline_jit
def _covariance_at(x, y, z, inv_fx, inv_fy, inv_fb, v_variance, s2):
    """Upper triangle ``(c00, c01, c02, c11, c12, c22)`` of the triangulation covariance of a point
    ``(x, y, z)`` (m^2): ``sigma^2 J J^T`` of :class:`stereovo.camera.StereoCamera`, evaluated at
    that point (disparity ``fb / z``) rather than read from a measured one. Reciprocals of the
    camera constants are passed in: divisions would dominate the kernel that calls this."""
    w = z * inv_fb  # 1 / disparity
    xd, yd, zd = x * w, y * w, z * w
    a = z * inv_fx - xd
    h = z * inv_fy
    return (
        s2 * (a * a + xd * xd), s2 * (xd - a) * yd, s2 * (xd - a) * zd,
        s2 * (2.0 * yd * yd + v_variance * h * h), s2 * 2.0 * yd * zd, s2 * 2.0 * zd * zd,
    )


@_jit
def mahalanobis_sq(R, t, X, Y, cam, sigma_sq, cap):
    """``(H, N)`` squared Mahalanobis distances of ``r = Y - (R X + t)`` under ``R S_X R^T + S_Y``.

    Both covariances are evaluated at one point, the two observations' fused estimate of the
    landmark under the hypothesis, not at the two noisy triangulations: in frame k the point
    ``Q = (P / p_z + Y / y_z) / (1 / p_z + 1 / y_z)`` (``P = R X + t``), whose disparity is the
    mean of the two (the maximum-likelihood depth for equal disparity noise), and
    ``R^T (Q - t)`` at k-1. At the measured points a far match whose two depths disagree gets
    covariances inflated by the disagreement itself (depth variance grows as z^4), and the
    chi-square gate then passes too many: 0.937 instead of 0.90 at 45-60 m. At the fused point
    the depth term is the disparity difference, which is linear in the pixels.

    ``inf`` where the moved point is behind the camera. With ``cap > 0`` a distance at or above
    ``cap`` may come back as any value >= cap: a point whose ``|r|^2 / tr C`` already reaches
    ``cap`` gets that lower bound (the trace bounds C's largest eigenvalue) and skips the 3x3
    solve. Most points of a bad hypothesis are settled before the fused point is even built, by
    a bound on the trace from norms alone: ``tr S(p) <= sigma^2 (c |p|^2 + 3 |p|^4 / (fx b)^2)``
    with ``c = 2 / fx^2 + v_variance / fy^2``, and the fused point, a convex combination of
    ``P`` and ``Y``, is no farther than ``max(|X| + |t|, |Y|)`` (``R^T (Q - t)``: plus ``|t|``).
    """
    fx, fy, bl = cam[0], cam[1], cam[4]
    inv_fx, inv_fy, inv_fb = 1.0 / fx, 1.0 / fy, 1.0 / (fx * bl)
    v_variance = 1.0 / cam[5]
    H, N = R.shape[0], X.shape[0]
    out = np.empty((H, N))
    c_lateral = 2.0 * inv_fx * inv_fx + v_variance * inv_fy * inv_fy
    c_depth = 3.0 * inv_fb * inv_fb
    inv_depth = np.empty(N)
    norm_x = np.empty(N)
    norm_y = np.empty(N)
    for n in range(N):
        inv_depth[n] = 1.0 / Y[n, 2]
        norm_x[n] = np.sqrt(X[n, 0] ** 2 + X[n, 1] ** 2 + X[n, 2] ** 2)
        norm_y[n] = np.sqrt(Y[n, 0] ** 2 + Y[n, 1] ** 2 + Y[n, 2] ** 2)
    for h in range(H):
        r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2 = _motion_entries(R, t, h)
        norm_t = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        for n in range(N):
            x0, x1, x2 = X[n, 0], X[n, 1], X[n, 2]
            p0 = r00 * x0 + r01 * x1 + r02 * x2 + t0
            p1 = r10 * x0 + r11 * x1 + r12 * x2 + t1
            p2 = r20 * x0 + r21 * x1 + r22 * x2 + t2
            y0, y1, y2 = Y[n, 0], Y[n, 1], Y[n, 2]
            x, y, z = y0 - p0, y1 - p1, y2 - p2
            behind = p2 <= MIN_DEPTH  # a select, not a branch: the loop stays vectorisable
            if cap > 0.0 and not behind:
                r2 = x * x + y * y + z * z
                far = max(norm_x[n] + norm_t, norm_y[n])  # bounds |Q|; |R^T (Q - t)| <= far + |t|
                far2 = far * far
                near2 = (far + norm_t) * (far + norm_t)
                bound_trace = sigma_sq * (c_lateral * (far2 + near2) + c_depth * (far2 * far2 + near2 * near2))
                if r2 >= cap * bound_trace:
                    out[h, n] = r2 / max(bound_trace, 1e-300)
                    continue
            ip, iy = 1.0 / (MIN_DEPTH if behind else p2), inv_depth[n]
            iq = 1.0 / (ip + iy)
            q0, q1, q2 = (p0 * ip + y0 * iy) * iq, (p1 * ip + y1 * iy) * iq, 2.0 * iq
            # the fused point at k-1: R^T (Q - t)
            d0, d1, d2 = q0 - t0, q1 - t1, q2 - t2
            k0 = r00 * d0 + r10 * d1 + r20 * d2
            k1 = r01 * d0 + r11 * d1 + r21 * d2
            k2 = r02 * d0 + r12 * d1 + r22 * d2
            if k2 <= MIN_DEPTH:  # no depth at k-1 for the fused point (odd motions): the measured one
                k0, k1, k2 = x0, x1, x2
            sx00, sx01, sx02, sx11, sx12, sx22 = _covariance_at(k0, k1, k2, inv_fx, inv_fy, inv_fb, v_variance, sigma_sq)
            sy00, sy01, sy02, sy11, sy12, sy22 = _covariance_at(q0, q1, q2, inv_fx, inv_fy, inv_fb, v_variance, sigma_sq)
            if cap > 0.0:
                r2 = x * x + y * y + z * z
                trace = sx00 + sx11 + sx22 + sy00 + sy11 + sy22
                if r2 >= cap * trace or behind:  # no division: |r|^2 / trace >= cap
                    out[h, n] = np.inf if behind else r2 / max(trace, 1e-300)
                    continue
            c00, c01, c02, c11, c12, c22 = _congruence(  # R S_X R^T, plus S_Y below
                r00, r01, r02, r10, r11, r12, r20, r21, r22,
                sx00, sx01, sx02, sx11, sx12, sx22,
            )
            d2 = _symmetric_quadratic(
                c00 + sy00, c01 + sy01, c02 + sy02, c11 + sy11, c12 + sy12, c22 + sy22, x, y, z,
            )
            out[h, n] = np.inf if behind else d2
    return out


@_jit
def pixel_mahalanobis_sq(R, t, X, cov_prev, mc, cam, sigma_sq):
    """``(H, N)`` squared Mahalanobis distances of the forward reprojection residuals at k.

    The residual ``e = pi(R X + t) - m_k`` (uL, vL, uR, vR) has covariance
    ``C = sigma^2 I + J R S_X R^T J^T`` (J: the projection's 4x3 Jacobian at the moved point).
    Its vL and vR rows of J are equal, so in the basis ``((e1 + e3) / sqrt 2, (e1 - e3) / sqrt 2)``
    C splits into a 3x3 block (rows a, sqrt(2) b, c) plus ``sigma^2`` for the vertical
    difference; both are inverted in closed form. ``inf`` where the moved point is behind.

    ``cam[5]`` is the camera's v measurements per match. With one (``v_measurement="shared"``)
    the match measured ``(uL, uR, v)``: the vertical sum carries ``2 sigma^2`` of pixel noise
    and there is no vertical difference, so the distance has 3 degrees of freedom; with two
    (``"independent"``) it has 4.
    """
    fx, fy, cx, cy, bl = cam[0], cam[1], cam[2], cam[3], cam[4]
    H, N = R.shape[0], X.shape[0]
    out = np.empty((H, N))
    root2 = np.sqrt(2.0)
    inv_root2 = 1.0 / root2
    shared_v = cam[5] == 1.0
    inv_sigma_sq = 0.0 if shared_v else 1.0 / sigma_sq
    sum_noise = 2.0 * sigma_sq if shared_v else sigma_sq
    for h in range(H):
        r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2 = _motion_entries(R, t, h)
        for n in range(N):
            x0, x1, x2 = X[n, 0], X[n, 1], X[n, 2]
            p0 = r00 * x0 + r01 * x1 + r02 * x2 + t0
            p1 = r10 * x0 + r11 * x1 + r12 * x2 + t1
            p2 = r20 * x0 + r21 * x1 + r22 * x2 + t2
            if p2 <= MIN_DEPTH:
                out[h, n] = np.inf
                continue
            ip = 1.0 / p2
            uL = fx * p0 * ip + cx
            v = fy * p1 * ip + cy
            uR = uL - fx * bl * ip
            e0 = uL - mc[n, 0]
            e1 = v - mc[n, 1]
            e2 = uR - mc[n, 2]
            e3 = v - mc[n, 3]
            s_sum = (e1 + e3) * inv_root2
            s_diff = (e1 - e3) * inv_root2
            Sx = cov_prev[n]
            s00, s01, s02, s11, s12, s22 = _congruence(  # R S_X R^T
                r00, r01, r02, r10, r11, r12, r20, r21, r22,
                Sx[0, 0], Sx[0, 1], Sx[0, 2], Sx[1, 1], Sx[1, 2], Sx[2, 2],
            )
            # J S J^T for the rotated Jacobian's rows uL, sqrt(2) v, uR; sigma^2 I added below
            c00, c01, c02, c11, c12, c22 = _congruence(
                fx * ip, 0.0, -fx * p0 * ip * ip,
                0.0, root2 * fy * ip, -root2 * fy * p1 * ip * ip,
                fx * ip, 0.0, -fx * (p0 - bl) * ip * ip,
                s00, s01, s02, s11, s12, s22,
            )
            out[h, n] = _symmetric_quadratic(
                c00 + sigma_sq, c01, c02, c11 + sum_noise, c12, c22 + sigma_sq, e0, s_sum, e2,
            ) + s_diff * s_diff * inv_sigma_sq
    return out


@_jit
def _centred_cross_covariance(X, Y, w, mx, my, cov):
    """Fill weighted means ``mx, my (3,)`` and ``cov (3, 3) = sum w (y - my)(x - mx)^T`` of ``X, Y (M, 3)``."""
    M = X.shape[0]
    total = 0.0
    for m in range(M):
        total += w[m]
    scale = 1.0 / max(total, 1e-300)
    mx[:] = 0.0
    my[:] = 0.0
    cov[:, :] = 0.0
    for m in range(M):
        wm = w[m] * scale
        for i in range(3):
            mx[i] += wm * X[m, i]
            my[i] += wm * Y[m, i]
    for m in range(M):
        wm = w[m] * scale
        for i in range(3):
            dy = wm * (Y[m, i] - my[i])
            for j in range(3):
                cov[i, j] += dy * (X[m, j] - mx[j])


@_jit
def _jacobi_top_eigenvector(N, V):
    """Eigenvector of the largest eigenvalue of the symmetric ``N (4, 4)``, by cyclic Jacobi sweeps.

    ``N`` is overwritten (diagonalised) and ``V (4, 4)`` receives all eigenvectors as columns;
    returns the column index of the top one. Jacobi keeps high relative accuracy and, on a
    4x4, converges in about four sweeps: cheaper than a LAPACK call, with no allocation.
    """
    scale = 0.0
    for i in range(4):
        for j in range(4):
            V[i, j] = 1.0 if i == j else 0.0
            scale += N[i, j] * N[i, j]
    for _ in range(16):
        off = 0.0
        for p in range(3):
            for q in range(p + 1, 4):
                off += N[p, q] * N[p, q]
        if off <= 1e-32 * scale:
            break
        for p in range(3):
            for q in range(p + 1, 4):
                apq = N[p, q]
                if apq == 0.0:
                    continue
                theta = (N[q, q] - N[p, p]) / (2.0 * apq)
                tan = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    tan = -tan
                c = 1.0 / np.sqrt(tan * tan + 1.0)
                s = tan * c
                N[p, p] -= tan * apq
                N[q, q] += tan * apq
                N[p, q] = N[q, p] = 0.0
                for r in range(4):
                    if r != p and r != q:
                        arp, arq = N[r, p], N[r, q]
                        N[r, p] = N[p, r] = c * arp - s * arq
                        N[r, q] = N[q, r] = s * arp + c * arq
                for r in range(4):
                    vrp, vrq = V[r, p], V[r, q]
                    V[r, p] = c * vrp - s * vrq
                    V[r, q] = s * vrp + c * vrq
    top = 0
    for i in range(1, 4):
        if N[i, i] > N[top, top]:
            top = i
    return top


@_inline_jit
def _det3(a00, a01, a02, a10, a11, a12, a20, a21, a22):
    return a00 * (a11 * a22 - a12 * a21) - a01 * (a10 * a22 - a12 * a20) + a02 * (a10 * a21 - a11 * a20)


@_jit
def _top_eigenvector_newton(N, V):
    """Unit eigenvector ``V[:, 0]`` of the largest eigenvalue of the symmetric, traceless ``N (4, 4)``;
    False if that eigenvalue is not well separated (the caller then uses Jacobi sweeps).

    The eigenvalue is the largest root of the characteristic quartic ``l^4 + a2 l^2 + a1 l + a0``,
    found by Newton's method from the upper bound ``sqrt(3/4 tr N^2)``: beyond the largest root
    the quartic is increasing and convex, so the iterates fall monotonically onto it. The
    eigenvector is the largest row of the adjugate of ``N - l I`` (Theobald's QCP, 2005). About a
    fifth of the Jacobi sweeps' time on the 4x4 of a rigid fit.
    """
    n00, n01, n02, n03 = N[0, 0], N[0, 1], N[0, 2], N[0, 3]
    n11, n12, n13 = N[1, 1], N[1, 2], N[1, 3]
    n22, n23, n33 = N[2, 2], N[2, 3], N[3, 3]
    trace_sq = (
        n00 * n00 + n11 * n11 + n22 * n22 + n33 * n33
        + 2.0 * (n01 * n01 + n02 * n02 + n03 * n03 + n12 * n12 + n13 * n13 + n23 * n23)
    )
    if not trace_sq > 0.0:
        return False
    a2 = -0.5 * trace_sq
    a1 = -(
        _det3(n00, n01, n02, n01, n11, n12, n02, n12, n22) + _det3(n00, n01, n03, n01, n11, n13, n03, n13, n33)
        + _det3(n00, n02, n03, n02, n22, n23, n03, n23, n33) + _det3(n11, n12, n13, n12, n22, n23, n13, n23, n33)
    )
    a0 = (
        n00 * _det3(n11, n12, n13, n12, n22, n23, n13, n23, n33)
        - n01 * _det3(n01, n12, n13, n02, n22, n23, n03, n23, n33)
        + n02 * _det3(n01, n11, n13, n02, n12, n23, n03, n13, n33)
        - n03 * _det3(n01, n11, n12, n02, n12, n22, n03, n13, n23)
    )
    bound = np.sqrt(0.75 * trace_sq)
    lam = bound
    for _ in range(60):
        slope = 4.0 * lam * lam * lam + 2.0 * a2 * lam + a1
        if not slope > 0.0:
            break
        step = (((lam * lam + a2) * lam + a1) * lam + a0) / slope
        lam -= step
        if step <= 1e-15 * bound:
            break
    # rows of adj(N - lam I): each is proportional to the eigenvector; take the largest
    b00, b11, b22, b33 = n00 - lam, n11 - lam, n22 - lam, n33 - lam
    best = 0.0
    for row in range(4):
        if row == 0:
            v0 = _det3(b11, n12, n13, n12, b22, n23, n13, n23, b33)
            v1 = -_det3(n01, n12, n13, n02, b22, n23, n03, n23, b33)
            v2 = _det3(n01, b11, n13, n02, n12, n23, n03, n13, b33)
            v3 = -_det3(n01, b11, n12, n02, n12, b22, n03, n13, n23)
        elif row == 1:
            v0 = -_det3(n01, n02, n03, n12, b22, n23, n13, n23, b33)
            v1 = _det3(b00, n02, n03, n02, b22, n23, n03, n23, b33)
            v2 = -_det3(b00, n01, n03, n02, n12, n23, n03, n13, b33)
            v3 = _det3(b00, n01, n02, n02, n12, b22, n03, n13, n23)
        elif row == 2:
            v0 = _det3(n01, n02, n03, b11, n12, n13, n13, n23, b33)
            v1 = -_det3(b00, n02, n03, n01, n12, n13, n03, n23, b33)
            v2 = _det3(b00, n01, n03, n01, b11, n13, n03, n13, b33)
            v3 = -_det3(b00, n01, n02, n01, b11, n12, n03, n13, n23)
        else:
            v0 = -_det3(n01, n02, n03, b11, n12, n13, n12, b22, n23)
            v1 = _det3(b00, n02, n03, n01, n12, n13, n02, b22, n23)
            v2 = -_det3(b00, n01, n03, n01, b11, n13, n02, n12, n23)
            v3 = _det3(b00, n01, n02, n01, b11, n12, n02, n12, b22)
        size = v0 * v0 + v1 * v1 + v2 * v2 + v3 * v3
        if size > best:
            best = size
            V[0, 0], V[1, 0], V[2, 0], V[3, 0] = v0, v1, v2, v3
    # |adj| is the product of the three gaps below lam: too small means a repeated top eigenvalue
    if not best > (1e-6 * bound**3) ** 2:
        return False
    inv_norm = 1.0 / np.sqrt(best)
    for i in range(4):
        V[i, 0] *= inv_norm
    return True


@_jit
def _horn_fit(cov, mx, my, R, t, N, V):
    """Least-squares rigid motion from a centred cross-covariance, filled in place.

    ``cov (3, 3) = sum w (y - my)(x - mx)^T``; ``R`` maximises ``tr(R^T cov)`` over proper
    rotations: Horn's (1987) unit quaternion, the top eigenvector of a symmetric 4x4 built
    from ``cov``. It is the minimiser Kabsch/Arun find with an SVD and the det(R) = +1
    correction, but needs no reflection fix-up and no LAPACK call. ``t = my - R mx``.
    ``N, V (4, 4)`` are scratch space.
    """
    # s_ab = sum w (x_a - mx_a)(y_b - my_b)
    sxx, sxy, sxz = cov[0, 0], cov[1, 0], cov[2, 0]
    syx, syy, syz = cov[0, 1], cov[1, 1], cov[2, 1]
    szx, szy, szz = cov[0, 2], cov[1, 2], cov[2, 2]
    N[0, 0] = sxx + syy + szz
    N[0, 1] = N[1, 0] = syz - szy
    N[0, 2] = N[2, 0] = szx - sxz
    N[0, 3] = N[3, 0] = sxy - syx
    N[1, 1] = sxx - syy - szz
    N[1, 2] = N[2, 1] = sxy + syx
    N[1, 3] = N[3, 1] = szx + sxz
    N[2, 2] = -sxx + syy - szz
    N[2, 3] = N[3, 2] = syz + szy
    N[3, 3] = -sxx - syy + szz
    top = 0 if _top_eigenvector_newton(N, V) else _jacobi_top_eigenvector(N, V)
    inv_norm = 1.0 / np.sqrt(V[0, top] ** 2 + V[1, top] ** 2 + V[2, top] ** 2 + V[3, top] ** 2)
    qw, qx, qy, qz = V[0, top] * inv_norm, V[1, top] * inv_norm, V[2, top] * inv_norm, V[3, top] * inv_norm
    R[0, 0] = qw * qw + qx * qx - qy * qy - qz * qz
    R[0, 1] = 2.0 * (qx * qy - qw * qz)
    R[0, 2] = 2.0 * (qx * qz + qw * qy)
    R[1, 0] = 2.0 * (qy * qx + qw * qz)
    R[1, 1] = qw * qw - qx * qx + qy * qy - qz * qz
    R[1, 2] = 2.0 * (qy * qz - qw * qx)
    R[2, 0] = 2.0 * (qz * qx - qw * qy)
    R[2, 1] = 2.0 * (qz * qy + qw * qx)
    R[2, 2] = qw * qw - qx * qx - qy * qy + qz * qz
    for i in range(3):
        t[i] = my[i] - (R[i, 0] * mx[0] + R[i, 1] * mx[1] + R[i, 2] * mx[2])


@_jit
def rigid_fits(X, Y, w):
    """Weighted least-squares motions ``Y ~ R X + t``: ``R (H, 3, 3)``, ``t (H, 3)``.

    ``X, Y (H, M, 3)``; ``w (H, M)`` non-negative weights, normalised per hypothesis here.
    """
    H = X.shape[0]
    R = np.empty((H, 3, 3))
    t = np.empty((H, 3))
    mx, my, cov = np.empty(3), np.empty(3), np.empty((3, 3))
    N, V = np.empty((4, 4)), np.empty((4, 4))
    for h in range(H):
        _centred_cross_covariance(X[h], Y[h], w[h], mx, my, cov)
        _horn_fit(cov, mx, my, R[h], t[h], N, V)
    return R, t


@_inline_jit
def _triplet_degenerate(P, area_ratio):
    """True if the triangle ``P (3, 3)`` has twice-area / 2 below ``area_ratio`` times its squared
    longest side, or that side is below 1e-6 m."""
    # in scalars: array expressions here would allocate temporaries for every hypothesis
    a0, a1, a2 = P[1, 0] - P[0, 0], P[1, 1] - P[0, 1], P[1, 2] - P[0, 2]
    b0, b1, b2 = P[2, 0] - P[0, 0], P[2, 1] - P[0, 1], P[2, 2] - P[0, 2]
    c0 = a1 * b2 - a2 * b1
    c1 = a2 * b0 - a0 * b2
    c2 = a0 * b1 - a1 * b0
    area = 0.5 * np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    d0, d1, d2 = b0 - a0, b1 - a1, b2 - a2
    longest = max(a0 * a0 + a1 * a1 + a2 * a2, b0 * b0 + b1 * b1 + b2 * b2, d0 * d0 + d1 * d1 + d2 * d2)
    return not (area >= area_ratio * longest) or longest < 1e-12


@_jit
def degenerate_triplets(X, Y, area_ratio):
    """``(H,)`` True where a triplet ``(H, 3, 3)`` is near-collinear or near-coincident in X or Y."""
    H = X.shape[0]
    bad = np.zeros(H, dtype=np.bool_)
    for h in range(H):
        bad[h] = _triplet_degenerate(X[h], area_ratio) or _triplet_degenerate(Y[h], area_ratio)
    return bad


@_jit
def distinct_triplets(u, m):
    """Three distinct indices per row from uniforms ``u (B, 3)`` and pool sizes ``m (B,)``.

    Draws from ``range(m)``, ``range(m - 1)``, ``range(m - 2)`` and shifts each index past
    those already taken: exact sampling without replacement, no rejection.
    """
    B = u.shape[0]
    out = np.empty((B, 3), dtype=np.int64)
    for k in range(B):
        mk = m[k]
        a = min(np.int64(u[k, 0] * mk), mk - 1)
        b = min(np.int64(u[k, 1] * (mk - 1)), mk - 2)
        c = min(np.int64(u[k, 2] * (mk - 2)), mk - 3)
        if b >= a:
            b += 1
        lo, hi = min(a, b), max(a, b)
        if c >= lo:
            c += 1
        if c >= hi:
            c += 1
        out[k, 0], out[k, 1], out[k, 2] = a, b, c
    return out


# Residual models the compiled refinement loop can gate with (see :func:`refine_rounds`).
GATE_REPROJECTION, GATE_MAHALANOBIS, GATE_PIXEL_MAHALANOBIS = 0, 1, 2


@_jit
def _gate_sq(gate, R, t, X, Y, cov_prev, cov_curr, mc, cam, sigma_sq):
    """``(H, N)`` squared residuals of the residual model ``gate`` (uncapped)."""
    if gate == GATE_REPROJECTION:
        return forward_reprojection_sq(R, t, X, mc, cam)
    if gate == GATE_MAHALANOBIS:
        return mahalanobis_sq(R, t, X, Y, cam, sigma_sq, 0.0)
    return pixel_mahalanobis_sq(R, t, X, cov_prev, mc, cam, sigma_sq)


@_jit
def refine_rounds(
    R, t, X, Y, mp, mc, cam, cov_prev, cov_curr, sigma_sq, inliers, gate, threshold_sq, regate,
    rounds, iterations, huber, damping, tolerance,
):
    """:meth:`ReprojectionRefiner.refine_with_residuals` for a gate with a compiled residual kernel.

    Alternates Levenberg-Marquardt on the inliers (:func:`gauss_newton` with step control) with
    re-selecting them under ``threshold_sq`` of the model ``gate`` (``GATE_*``), for at most
    ``rounds`` rounds; with ``regate`` the given inliers are first re-selected by the gate (kept
    if at least half as many). A round that loses more than half the inliers is undone, and the
    rounds end once the inliers stay the same. The same arithmetic as the Python loop, without
    its per-round overhead. Returns ``R (3, 3)``, ``t (3,)``, the inliers ``(N,)``, the gate's
    squared residuals ``(N,)`` of the returned motion and whether those were computed (False:
    the motion is the one given and was not gated).
    """
    N = X.shape[0]
    current_R = np.empty((1, 3, 3))
    current_t = np.empty((1, 3))
    current_R[0] = R
    current_t[0] = t
    trial_R = np.empty((1, 3, 3))
    trial_t = np.empty((1, 3))
    selected = inliers.copy()
    n_selected = 0
    for i in range(N):
        n_selected += selected[i]
    residual_sq = np.empty(N)
    have_residuals = False
    if regate:
        sq = _gate_sq(gate, current_R, current_t, X, Y, cov_prev, cov_curr, mc, cam, sigma_sq)[0]
        n_gated = 0
        for i in range(N):
            n_gated += sq[i] < threshold_sq
        if n_gated >= n_selected // 2:
            for i in range(N):
                selected[i] = sq[i] < threshold_sq
            n_selected, residual_sq, have_residuals = n_gated, sq, True
    weights = np.empty(N)
    scratch = _lm_scratch()
    for _ in range(rounds):
        if n_selected < 3:
            break
        for i in range(N):
            weights[i] = 1.0 if selected[i] else 0.0
        trial_R[0] = current_R[0]
        trial_t[0] = current_t[0]
        _levenberg_marquardt(
            trial_R[0], trial_t[0], X, Y, mp, mc, cam, weights, huber, iterations, damping, tolerance, True, scratch
        )
        sq = _gate_sq(gate, trial_R, trial_t, X, Y, cov_prev, cov_curr, mc, cam, sigma_sq)[0]
        n_new = 0
        for i in range(N):
            n_new += sq[i] < threshold_sq
        if n_new < n_selected // 2:
            break  # refinement ran away from the consensus: keep what we had
        current_R[0] = trial_R[0]
        current_t[0] = trial_t[0]
        residual_sq, have_residuals = sq, True
        same = n_new == n_selected
        for i in range(N):
            now = sq[i] < threshold_sq
            if now != selected[i]:
                same = False
            selected[i] = now
        n_selected = n_new
        if same:
            break
    return current_R[0].copy(), current_t[0].copy(), selected, residual_sq, have_residuals


@_inline_jit
def _first_above(cdf, mass):
    """Index of the first ``cdf`` entry above ``mass`` (``np.searchsorted(cdf, mass, "right")``),
    capped at the last index."""
    lo, hi = 0, cdf.shape[0]
    while lo < hi:
        mid = (lo + hi) >> 1
        if cdf[mid] <= mass:
            lo = mid + 1
        else:
            hi = mid
    return min(lo, cdf.shape[0] - 1)


@_jit
def weighted_triplets(u, w, cdf, before):
    """Ordered draws without replacement, P(i) proportional to ``w (N,)``, from uniforms ``u (B, 3)``.

    ``cdf`` and ``before`` are the inclusive and exclusive cumulative sums of ``w``. Each draw
    inverts the cumulative weights with the indices already drawn cut out of them (a position in
    the remaining mass is shifted past each drawn interval it reaches). Rounding at an interval's
    edge can return a drawn or zero-weight index: those rows are flagged in ``suspect (B,)``
    for the caller to redraw exactly. Returns ``(samples (B, 3), suspect (B,))``.
    """
    B = u.shape[0]
    total = cdf[cdf.shape[0] - 1]
    out = np.empty((B, 3), dtype=np.int64)
    suspect = np.zeros(B, dtype=np.bool_)
    for k in range(B):
        a = _first_above(cdf, u[k, 0] * total)
        x = u[k, 1] * (total - w[a])
        b = _first_above(cdf, x if x < before[a] else x + w[a])
        lo, hi = min(a, b), max(a, b)
        x = u[k, 2] * (total - w[a] - w[b])
        if not x < before[lo]:
            x = x + w[lo]
        c = _first_above(cdf, x if x < before[hi] else x + w[hi])
        out[k, 0], out[k, 1], out[k, 2] = a, b, c
        suspect[k] = b == a or c == a or c == b or w[a] == 0 or w[b] == 0 or w[c] == 0
    return out, suspect


@_jit
def prior_defects(p):
    """One pass over priors ``p (N,)``: ``(any non-finite, minimum, number of positive weights)``."""
    nonfinite = False
    minimum = np.inf
    positive = 0
    for i in range(p.shape[0]):
        x = p[i]
        if not np.isfinite(x):
            nonfinite = True
        elif x < minimum:
            minimum = x
        if x > 0:
            positive += 1
    return nonfinite, minimum, positive


@_jit
def minimal_fits(samples, X, Y, mp, mc, cam, area_ratio, polish_iterations):
    """One motion per minimal sample: degeneracy test, Horn fit, Gauss-Newton polish, in one pass.

    ``samples (H, 3)`` index the problem's ``X, Y (N, 3)`` and ``mp, mc (N, 4)``. The polish is
    plain Gauss-Newton on the sample's symmetric reprojection error (damping 1e-9 only guards a
    singular system). Returns ``R (H, 3, 3)``, ``t (H, 3)`` and ``valid (H,)``: False for a
    degenerate triplet (its motion is left as the identity) or a non-finite result.
    """
    H = samples.shape[0]
    R = np.zeros((H, 3, 3))
    t = np.zeros((H, 3))
    valid = np.zeros(H, dtype=np.bool_)
    Xs, Ys = np.empty((3, 3)), np.empty((3, 3))
    mps, mcs = np.empty((3, 4)), np.empty((3, 4))
    ones = np.ones(3)
    mx, my, cov = np.empty(3), np.empty(3), np.empty((3, 3))
    N, V = np.empty((4, 4)), np.empty((4, 4))
    scratch = _lm_scratch()
    for h in range(H):
        for k in range(3):
            i = samples[h, k]
            Xs[k] = X[i]
            Ys[k] = Y[i]
            mps[k] = mp[i]
            mcs[k] = mc[i]
        if _triplet_degenerate(Xs, area_ratio) or _triplet_degenerate(Ys, area_ratio):
            R[h, 0, 0] = R[h, 1, 1] = R[h, 2, 2] = 1.0
            continue
        _centred_cross_covariance(Xs, Ys, ones, mx, my, cov)
        _horn_fit(cov, mx, my, R[h], t[h], N, V)
        if polish_iterations > 0:
            _levenberg_marquardt(R[h], t[h], Xs, Ys, mps, mcs, cam, ones, 0.0, polish_iterations, 1e-9, 0.0, False, scratch)
        ok = True
        for i in range(3):
            if not np.isfinite(t[h, i]):
                ok = False
            for j in range(3):
                if not np.isfinite(R[h, i, j]):
                    ok = False
        valid[h] = ok
    return R, t, valid


@_inline_jit
def _summed_quadratic_form(cov, a, b, x0, x1, x2):
    """``x^T (cov[a] + cov[b]) x`` for symmetric ``cov (N, 3, 3)``."""
    S, T = cov[a], cov[b]
    return (
        x0 * x0 * (S[0, 0] + T[0, 0]) + x1 * x1 * (S[1, 1] + T[1, 1]) + x2 * x2 * (S[2, 2] + T[2, 2])
        + 2.0 * (x0 * x1 * (S[0, 1] + T[0, 1]) + x0 * x2 * (S[0, 2] + T[0, 2]) + x1 * x2 * (S[1, 2] + T[1, 2]))
    )


@_inline_jit
def _pair_is_rigid(X, Y, cov_prev, cov_curr, a, b, threshold_sq):
    """The rigid-distance test (:mod:`stereovo.estimation.rigidity`) for points ``a`` and ``b``: their
    distance changes from k-1 to k by less than ``sqrt(threshold_sq)`` standard deviations, ``var``
    carrying both points' triangulation covariances in both frames onto the direction between them
    (first order). False for coincident points."""
    x0, x1, x2 = X[a, 0] - X[b, 0], X[a, 1] - X[b, 1], X[a, 2] - X[b, 2]
    y0, y1, y2 = Y[a, 0] - Y[b, 0], Y[a, 1] - Y[b, 1], Y[a, 2] - Y[b, 2]
    lx_sq = x0 * x0 + x1 * x1 + x2 * x2
    ly_sq = y0 * y0 + y1 * y1 + y2 * y2
    if not (lx_sq > 0.0 and ly_sq > 0.0):
        return False
    # u^T S u for the unit direction u: the quadratic forms of the difference vectors over their squared lengths
    var = _summed_quadratic_form(cov_prev, a, b, x0, x1, x2) / lx_sq
    var += _summed_quadratic_form(cov_curr, a, b, y0, y1, y2) / ly_sq
    return rigid_distance_consistent_jit(distance_change_sq_jit(x0, x1, x2, y0, y1, y2), var, threshold_sq)


@_jit
def rigid_triplets(samples, X, Y, cov_prev, cov_curr, threshold_sq):
    """``(H,)`` True where all three pairwise distances of a sample agree between k-1 and k within
    ``threshold_sq`` (a chi-square(1) quantile) of their standardised change."""
    H = samples.shape[0]
    keep = np.empty(H, dtype=np.bool_)
    for h in range(H):
        i, j, k = samples[h, 0], samples[h, 1], samples[h, 2]
        keep[h] = (
            _pair_is_rigid(X, Y, cov_prev, cov_curr, i, j, threshold_sq)
            and _pair_is_rigid(X, Y, cov_prev, cov_curr, i, k, threshold_sq)
            and _pair_is_rigid(X, Y, cov_prev, cov_curr, j, k, threshold_sq)
        )
    return keep
