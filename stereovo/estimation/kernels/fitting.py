"""Compiled rigid fits: weighted least-squares motions (Horn's quaternion) and minimal-sample fits.

:func:`rigid_fits` fits one motion per weighted point set; :func:`minimal_fits` tests a
triplet for degeneracy, fits it and polishes it by Gauss-Newton in one pass;
:func:`degenerate_triplets` is the degeneracy test alone. The top eigenvector of Horn's 4x4
comes from Newton's method on its characteristic quartic, Jacobi sweeps as the fallback.
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels.base import inline_jit, jit
from stereovo.estimation.kernels.least_squares import levenberg_marquardt, lm_scratch


@jit
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


@jit
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


@inline_jit
def _det3(a00, a01, a02, a10, a11, a12, a20, a21, a22):
    return a00 * (a11 * a22 - a12 * a21) - a01 * (a10 * a22 - a12 * a20) + a02 * (a10 * a21 - a11 * a20)


@jit
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


@jit
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


@jit
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


@inline_jit
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


@jit
def degenerate_triplets(X, Y, area_ratio):
    """``(H,)`` True where a triplet ``(H, 3, 3)`` is near-collinear or near-coincident in X or Y."""
    H = X.shape[0]
    bad = np.zeros(H, dtype=np.bool_)
    for h in range(H):
        bad[h] = _triplet_degenerate(X[h], area_ratio) or _triplet_degenerate(Y[h], area_ratio)
    return bad


@jit
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
    scratch = lm_scratch()
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
            levenberg_marquardt(R[h], t[h], Xs, Ys, mps, mcs, cam, ones, 0.0, polish_iterations, 1e-9, 0.0, False, scratch,
                                False)
        ok = True
        for i in range(3):
            if not np.isfinite(t[h, i]):
                ok = False
            for j in range(3):
                if not np.isfinite(R[h, i, j]):
                    ok = False
        valid[h] = ok
    return R, t, valid
