"""Compiled Gauss-Newton / Levenberg-Marquardt on the weighted symmetric reprojection error.

The normal equations of a hypothesis are summed point by point from each side's 3x3 terms
(:func:`_cost_and_normal_equations`), solved by a damped Cholesky and applied as a twist on
the left; :func:`levenberg_marquardt` refines one motion and :func:`gauss_newton` a batch.
The refinement rounds and the minimal fits run the same :func:`levenberg_marquardt`.
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels.base import BEHIND_CAMERA_RESIDUAL, MIN_DEPTH, inline_jit, jit
from stereovo.estimation.kernels.residuals import moved_points, stereo_residuals

_SMALL_ANGLE = 1e-4  # below it, Rodrigues coefficients use their Taylor series


@inline_jit
def _irls_weight(base, sq, huber):
    """The point's weight: its base weight, times Huber's ``huber / |r|`` beyond the threshold."""
    if huber > 0.0:
        norm = np.sqrt(sq)
        if norm > huber:
            return base * huber / max(norm, 1e-12)
    return base


@inline_jit
def _stereo_terms(p0, p1, p2, fx, fy, cx, cy, b, u_l, v_l, u_r, v_r):
    """One point ``p`` seen in a rectified stereo pair against its measurement ``(u_l, v_l, u_r, v_r)``.

    Returns its squared residual (px^2), and the Gauss-Newton terms over its four pixel rows, with
    ``a_r = d(pixel_r)/dp``: ``M = sum a_r a_r^T`` (upper triangle m00, m02, m11, m12, m22; m01 is 0
    because no row depends on both x and y) and ``v = sum a_r res_r``. ``p2`` must be positive.
    """
    ip, r0, r1, r2, r3 = stereo_residuals(p0, p1, p2, fx, fy, cx, cy, b, u_l, v_l, u_r, v_r)
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


@inline_jit
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


@jit
def _cost_and_normal_equations(R, t, X, Y, mp, mc, cam, w, huber, A, g, want_system, A_back, g_back):
    """Weighted squared cost of one hypothesis; fills ``A (6, 6)``, ``g (6,)`` if ``want_system``.

    The same sums as ``J^T W J`` and ``J^T W r`` over the Jacobian rows of ``residuals._point_rows``, built
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
        p0, p1, p2, q0, q1, q2 = moved_points(R, t, X, Y, m)
        if p2 <= MIN_DEPTH or q2 <= MIN_DEPTH:
            # residual rows of BEHIND_CAMERA_RESIDUAL and no Jacobian, as in residuals._point_rows
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


@jit
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


@jit
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


@jit
def lm_scratch():
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


@jit
def levenberg_marquardt(Rh, th, Xh, Yh, mph, mch, cam, wh, huber, iterations, damping, tolerance, step_control, scratch,
                        final_cost=True):
    """Refine one motion ``Rh, th`` in place; return its final weighted cost (see :func:`gauss_newton`).

    ``final_cost=False`` (without ``step_control``) skips the cost of the motion the last step
    reaches, which every step's system is built with otherwise; the cost returned is then the one
    before that step. For a caller that keeps only the motion (the minimal fits' polish, where it
    was a third of the polish's point passes)."""
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
            if final_cost or not last:
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


@jit
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
    scratch = lm_scratch()
    for h in range(H):
        gx = h if X.shape[0] > 1 else 0
        gw = h if weights.shape[0] > 1 else 0
        cost_out[h] = levenberg_marquardt(
            R_out[h], t_out[h], X[gx], Y[gx], mp[gx], mc[gx], cam, weights[gw], huber,
            iterations, damping, tolerance, step_control, scratch,
        )
    return R_out, t_out, cost_out
