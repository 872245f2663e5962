"""Compiled Mahalanobis residuals: of the 3D point, and of the forward reprojection at k.

:func:`mahalanobis_sq` weighs ``Y - (R X + t)`` by both triangulation covariances, evaluated
at the two observations' fused point; :func:`pixel_mahalanobis_sq` weighs the pixel residual
by the pixel noise plus the k-1 point's covariance carried through the motion and projection.
Small 3x3 algebra in scalars (adjugate inverse, congruence) keeps a point in registers.
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels.base import MIN_DEPTH, inline_jit, jit


@inline_jit
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


@inline_jit
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


@inline_jit
def _motion_entries(R, t, h):
    """Hypothesis ``h``'s ``R`` (row-major) and ``t`` as twelve scalars, read once per hypothesis."""
    return (
        R[h, 0, 0], R[h, 0, 1], R[h, 0, 2], R[h, 1, 0], R[h, 1, 1], R[h, 1, 2], R[h, 2, 0], R[h, 2, 1], R[h, 2, 2],
        t[h, 0], t[h, 1], t[h, 2],
    )


@inline_jit
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


@inline_jit
def point_mahalanobis_sq(r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2, norm_t,
                         x0, x1, x2, y0, y1, y2, inv_depth, norm_x, norm_y,
                         inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq, cap):
    """One point's squared Mahalanobis distance under one motion, as :func:`mahalanobis_sq` defines it.

    ``X = (x0, x1, x2)`` at k-1, ``Y = (y0, y1, y2)`` at k; ``inv_depth = 1 / y2``, ``norm_x = |X|``,
    ``norm_y = |Y|``, ``norm_t = |t|`` and the camera terms are computed once by the caller (the
    per-point and per-hypothesis constants of the loops that call this). Shared by full scoring
    and the compiled SPRT (:mod:`stereovo.estimation.kernels.verification`), so both agree bit for bit.
    """
    p0 = r00 * x0 + r01 * x1 + r02 * x2 + t0
    p1 = r10 * x0 + r11 * x1 + r12 * x2 + t1
    p2 = r20 * x0 + r21 * x1 + r22 * x2 + t2
    x, y, z = y0 - p0, y1 - p1, y2 - p2
    behind = p2 <= MIN_DEPTH  # a select, not a branch: the loop stays vectorisable
    if cap > 0.0 and not behind:
        r2 = x * x + y * y + z * z
        far = max(norm_x + norm_t, norm_y)  # bounds |Q|
        far_prev = max(norm_x, norm_y + norm_t)  # bounds the fused point at k-1
        far2 = far * far
        near2 = far_prev * far_prev
        bound_trace = sigma_sq * (c_lateral * (far2 + near2) + c_depth * (far2 * far2 + near2 * near2))
        if r2 >= cap * bound_trace:
            return r2 / max(bound_trace, 1e-300)
    ip, iy = 1.0 / (MIN_DEPTH if behind else p2), inv_depth
    iq = 1.0 / (ip + iy)
    q0, q1, q2 = (p0 * ip + y0 * iy) * iq, (p1 * ip + y1 * iy) * iq, 2.0 * iq
    # the fused point at k-1, fused there as Q is at k: X and W = R^T (Y - t), the k point
    # carried back, with the mean of their disparities. (Carrying Q back instead, an absurd
    # motion that sends P kilometres away put the k-1 point there too, and its covariance
    # then passed any residual.)
    d0, d1, d2 = y0 - t0, y1 - t1, y2 - t2
    w0 = r00 * d0 + r10 * d1 + r20 * d2
    w1 = r01 * d0 + r11 * d1 + r21 * d2
    w2 = r02 * d0 + r12 * d1 + r22 * d2
    if w2 <= MIN_DEPTH:  # the k point carried back has no depth at k-1 (odd motions): the measured one
        k0, k1, k2 = x0, x1, x2
    else:
        ix, iw = 1.0 / x2, 1.0 / w2
        ik = 1.0 / (ix + iw)
        k0, k1, k2 = (x0 * ix + w0 * iw) * ik, (x1 * ix + w1 * iw) * ik, 2.0 * ik
    sx00, sx01, sx02, sx11, sx12, sx22 = _covariance_at(k0, k1, k2, inv_fx, inv_fy, inv_fb, v_variance, sigma_sq)
    sy00, sy01, sy02, sy11, sy12, sy22 = _covariance_at(q0, q1, q2, inv_fx, inv_fy, inv_fb, v_variance, sigma_sq)
    if cap > 0.0:
        r2 = x * x + y * y + z * z
        trace = sx00 + sx11 + sx22 + sy00 + sy11 + sy22
        if r2 >= cap * trace or behind:  # no division: |r|^2 / trace >= cap
            return np.inf if behind else r2 / max(trace, 1e-300)
    c00, c01, c02, c11, c12, c22 = _congruence(  # R S_X R^T, plus S_Y below
        r00, r01, r02, r10, r11, r12, r20, r21, r22,
        sx00, sx01, sx02, sx11, sx12, sx22,
    )
    d2 = _symmetric_quadratic(
        c00 + sy00, c01 + sy01, c02 + sy02, c11 + sy11, c12 + sy12, c22 + sy22, x, y, z,
    )
    return np.inf if behind else d2


@inline_jit
def point_mahalanobis_sq_lanes(r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2, norm_t,
                               x0, x1, x2, y0, y1, y2, inv_depth, norm_x, norm_y,
                               inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq, cap):
    """:func:`point_mahalanobis_sq`, bit for bit, in vector lanes (:func:`point_mahalanobis_sq_pair`'s first value)."""
    return point_mahalanobis_sq_pair(
        r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2, norm_t, x0, x1, x2, y0, y1, y2, inv_depth, norm_x,
        norm_y, inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq, cap,
    )[0]


@inline_jit
def point_mahalanobis_sq_pair(r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2, norm_t,
                              x0, x1, x2, y0, y1, y2, inv_depth, norm_x, norm_y,
                              inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq, cap):
    """:func:`point_mahalanobis_sq` under ``cap``, bit for bit, without its early returns; and the
    distance without a cap (``point_mahalanobis_sq`` with cap 0), which the full form has computed anyway.

    Every branch's value is computed and the answer selected, so that a loop over points compiles to
    vector instructions (about a third of the time of the branching form on 16 hypotheses x 1000
    points, where each branch is a misprediction for some point); the branching form stays for the
    compiled SPRT, which scans point by point and whose early returns save the work of the rest.
    The operations and their order are the branching form's, so every value is the same.
    (Thirty arguments: numba's inliner refuses a thirty-first.)
    """
    p0 = r00 * x0 + r01 * x1 + r02 * x2 + t0
    p1 = r10 * x0 + r11 * x1 + r12 * x2 + t1
    p2 = r20 * x0 + r21 * x1 + r22 * x2 + t2
    x, y, z = y0 - p0, y1 - p1, y2 - p2
    behind = p2 <= MIN_DEPTH
    r2 = x * x + y * y + z * z
    far = max(norm_x + norm_t, norm_y)
    far_prev = max(norm_x, norm_y + norm_t)
    far2 = far * far
    near2 = far_prev * far_prev
    bound_trace = sigma_sq * (c_lateral * (far2 + near2) + c_depth * (far2 * far2 + near2 * near2))
    ip, iy = 1.0 / (MIN_DEPTH if behind else p2), inv_depth
    iq = 1.0 / (ip + iy)
    q0, q1, q2 = (p0 * ip + y0 * iy) * iq, (p1 * ip + y1 * iy) * iq, 2.0 * iq
    d0, d1, d2 = y0 - t0, y1 - t1, y2 - t2
    w0 = r00 * d0 + r10 * d1 + r20 * d2
    w1 = r01 * d0 + r11 * d1 + r21 * d2
    w2 = r02 * d0 + r12 * d1 + r22 * d2
    carried = w2 > MIN_DEPTH
    ix, iw = 1.0 / x2, 1.0 / (w2 if carried else 1.0)
    ik = 1.0 / (ix + iw)
    k0 = (x0 * ix + w0 * iw) * ik if carried else x0
    k1 = (x1 * ix + w1 * iw) * ik if carried else x1
    k2 = 2.0 * ik if carried else x2
    sx00, sx01, sx02, sx11, sx12, sx22 = _covariance_at(k0, k1, k2, inv_fx, inv_fy, inv_fb, v_variance, sigma_sq)
    sy00, sy01, sy02, sy11, sy12, sy22 = _covariance_at(q0, q1, q2, inv_fx, inv_fy, inv_fb, v_variance, sigma_sq)
    trace = sx00 + sx11 + sx22 + sy00 + sy11 + sy22
    c00, c01, c02, c11, c12, c22 = _congruence(
        r00, r01, r02, r10, r11, r12, r20, r21, r22,
        sx00, sx01, sx02, sx11, sx12, sx22,
    )
    d2 = _symmetric_quadratic(
        c00 + sy00, c01 + sy01, c02 + sy02, c11 + sy11, c12 + sy12, c22 + sy22, x, y, z,
    )
    capped = cap > 0.0 and not behind
    exact = np.inf if behind else d2
    value = r2 / max(trace, 1e-300) if capped and r2 >= cap * trace else exact
    return r2 / max(bound_trace, 1e-300) if capped and r2 >= cap * bound_trace else value, exact


@inline_jit
def point_columns(X, Y):
    """What the 3-D scorer reads of the points ``X, Y (N, 3)``, per point and whatever the motion:
    ``(x0, x1, x2, y0, y1, y2, inv_depth, norm_x, norm_y)``, each ``(N,)`` and contiguous (the points
    as columns, so that a loop over them runs in vector lanes), ``inv_depth = 1 / y2``, ``norm_x = |X|``,
    ``norm_y = |Y|``. The scorer, BANSAC's compiled search and the branching form's callers share it,
    so all read the same values."""
    n = X.shape[0]
    columns = np.empty((9, n))
    for i in range(n):
        for k in range(3):
            columns[k, i] = X[i, k]
            columns[3 + k, i] = Y[i, k]
        columns[6, i] = 1.0 / Y[i, 2]
        columns[7, i] = np.sqrt(X[i, 0] ** 2 + X[i, 1] ** 2 + X[i, 2] ** 2)
        columns[8, i] = np.sqrt(Y[i, 0] ** 2 + Y[i, 1] ** 2 + Y[i, 2] ** 2)
    return (columns[0], columns[1], columns[2], columns[3], columns[4], columns[5], columns[6], columns[7],
            columns[8])


@jit
def mahalanobis_sq(R, t, X, Y, cam, sigma_sq, cap):
    """``(H, N)`` squared Mahalanobis distances of ``r = Y - (R X + t)`` under ``R S_X R^T + S_Y``.

    Both covariances are evaluated at one point, the two observations' fused estimate of the
    landmark under the hypothesis, not at the two noisy triangulations: in frame k the point
    ``Q = (P / p_z + Y / y_z) / (1 / p_z + 1 / y_z)`` (``P = R X + t``), whose disparity is the
    mean of the two (the maximum-likelihood depth for equal disparity noise), and at k-1 likewise
    the point fused from ``X`` and ``W = R^T (Y - t)``. At the measured points a far match whose two depths disagree gets
    covariances inflated by the disagreement itself (depth variance grows as z^4), and the
    chi-square gate then passes too many: 0.937 instead of 0.90 at 45-60 m. At the fused point
    the depth term is the disparity difference, which is linear in the pixels.

    ``inf`` where the moved point is behind the camera. With ``cap > 0`` a distance at or above
    ``cap`` may come back as any value >= cap: a point whose ``|r|^2 / tr C`` already reaches
    ``cap`` gets that lower bound (the trace bounds C's largest eigenvalue) and skips the 3x3
    solve. Most points of a bad hypothesis are settled before the fused point is even built, by
    a bound on the trace from norms alone: ``tr S(p) <= sigma^2 (c |p|^2 + 3 |p|^4 / (fx b)^2)``
    with ``c = 2 / fx^2 + v_variance / fy^2``, and the fused point at k, a convex combination of
    ``P`` and ``Y``, is no farther than ``max(|X| + |t|, |Y|)``, the one at k-1 (of ``X`` and
    ``W``) no farther than ``max(|X|, |Y| + |t|)``.
    """
    out = np.empty((R.shape[0], X.shape[0]))
    _scan(R, t, X, Y, cam, sigma_sq, cap, out, out, False)
    return out


@jit
def mahalanobis_sq_and_exact(R, t, X, Y, cam, sigma_sq, cap):
    """``(capped, exact)``, each ``(H, N)``: :func:`mahalanobis_sq` under ``cap`` and with cap 0, bit
    for bit, from one pass (the lanes compute a point's full distance whatever the cap decides)."""
    out = np.empty((R.shape[0], X.shape[0]))
    exact = np.empty((R.shape[0], X.shape[0]))
    _scan(R, t, X, Y, cam, sigma_sq, cap, out, exact, True)
    return out, exact


@inline_jit
def _scan(R, t, X, Y, cam, sigma_sq, cap, out, exact, keep_exact):
    """Fill ``out (H, N)`` with :func:`mahalanobis_sq`'s distances under ``cap``, and ``exact`` with
    the uncapped ones if ``keep_exact`` (a constant of each caller, so each compiles its own loop)."""
    fx, fy, bl = cam[0], cam[1], cam[4]
    inv_fx, inv_fy, inv_fb = 1.0 / fx, 1.0 / fy, 1.0 / (fx * bl)
    v_variance = 1.0 / cam[5]
    H, N = R.shape[0], X.shape[0]
    c_lateral = 2.0 * inv_fx * inv_fx + v_variance * inv_fy * inv_fy
    c_depth = 3.0 * inv_fb * inv_fb
    x0, x1, x2, y0, y1, y2, inv_depth, norm_x, norm_y = point_columns(X, Y)
    for h in range(H):
        r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2 = _motion_entries(R, t, h)
        norm_t = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        row = out[h]
        if keep_exact:
            exact_row = exact[h]
            for n in range(N):
                row[n], exact_row[n] = point_mahalanobis_sq_pair(
                    r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2, norm_t,
                    x0[n], x1[n], x2[n], y0[n], y1[n], y2[n], inv_depth[n], norm_x[n], norm_y[n],
                    inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq, cap,
                )
        else:
            for n in range(N):
                row[n] = point_mahalanobis_sq_lanes(
                    r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2, norm_t,
                    x0[n], x1[n], x2[n], y0[n], y1[n], y2[n], inv_depth[n], norm_x[n], norm_y[n],
                    inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq, cap,
                )


@jit
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
    # the points, measurements and covariances as columns, so the loop over points runs in vector
    # lanes; a point behind the camera is computed with a stand-in depth and its value replaced by inf
    # (every other value is the arithmetic of the point alone, the same as a loop that skips it)
    columns = np.empty((13, N))
    for n in range(N):
        for k in range(3):
            columns[k, n] = X[n, k]
        for k in range(4):
            columns[3 + k, n] = mc[n, k]
        columns[7, n] = cov_prev[n, 0, 0]
        columns[8, n] = cov_prev[n, 0, 1]
        columns[9, n] = cov_prev[n, 0, 2]
        columns[10, n] = cov_prev[n, 1, 1]
        columns[11, n] = cov_prev[n, 1, 2]
        columns[12, n] = cov_prev[n, 2, 2]
    xs0, xs1, xs2, m0, m1, m2, m3 = columns[0], columns[1], columns[2], columns[3], columns[4], columns[5], columns[6]
    v00, v01, v02, v11, v12, v22 = columns[7], columns[8], columns[9], columns[10], columns[11], columns[12]
    for h in range(H):
        r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2 = _motion_entries(R, t, h)
        row = out[h]
        for n in range(N):
            x0, x1, x2 = xs0[n], xs1[n], xs2[n]
            p0 = r00 * x0 + r01 * x1 + r02 * x2 + t0
            p1 = r10 * x0 + r11 * x1 + r12 * x2 + t1
            p2 = r20 * x0 + r21 * x1 + r22 * x2 + t2
            behind = p2 <= MIN_DEPTH
            ip = 1.0 / (1.0 if behind else p2)
            uL = fx * p0 * ip + cx
            v = fy * p1 * ip + cy
            uR = uL - fx * bl * ip
            e0 = uL - m0[n]
            e1 = v - m1[n]
            e2 = uR - m2[n]
            e3 = v - m3[n]
            s_sum = (e1 + e3) * inv_root2
            s_diff = (e1 - e3) * inv_root2
            s00, s01, s02, s11, s12, s22 = _congruence(  # R S_X R^T
                r00, r01, r02, r10, r11, r12, r20, r21, r22,
                v00[n], v01[n], v02[n], v11[n], v12[n], v22[n],
            )
            # J S J^T for the rotated Jacobian's rows uL, sqrt(2) v, uR; sigma^2 I added below
            c00, c01, c02, c11, c12, c22 = _congruence(
                fx * ip, 0.0, -fx * p0 * ip * ip,
                0.0, root2 * fy * ip, -root2 * fy * p1 * ip * ip,
                fx * ip, 0.0, -fx * (p0 - bl) * ip * ip,
                s00, s01, s02, s11, s12, s22,
            )
            d2 = _symmetric_quadratic(
                c00 + sigma_sq, c01, c02, c11 + sum_noise, c12, c22 + sigma_sq, e0, s_sum, e2,
            ) + s_diff * s_diff * inv_sigma_sq
            row[n] = np.inf if behind else d2
    return out
