"""Symmetric stereo reprojection residuals and their se(3) Jacobians, batched.

A motion ``(R, t)`` maps a point triangulated at k-1 into camera k, where it
is projected into both images and compared with the measurement at k; the
inverse motion does the same for the point triangulated at k. Pixel noise is
isotropic in this space, which is why hypotheses are polished and the final
model refined here rather than on triangulated points, whose depth error
grows as z^2 / (fx b).

Perturbation: ``T <- exp(delta^) T`` with ``delta = (rho, omega)`` (left
multiplication), matching :func:`stereovo.geometry.se3_exp`.

Shapes: ``H`` hypotheses, ``M`` points each. Residuals ``(H, M, 8)`` in pixels
(forward uL, vL, uR, vR then backward), Jacobians ``(H, M, 8, 6)``.
"""

from __future__ import annotations

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.geometry import se3_exp

# A transformed point this close to the camera plane cannot be projected: its residual
# is replaced by a large constant and its Jacobian zeroed, so it stops pulling.
_MIN_DEPTH = 1e-3
_BEHIND_CAMERA_RESIDUAL = 1e3


def _project_with_jacobian(camera: StereoCamera, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Projections ``(..., 4)``, d(projection)/dP ``(..., 4, 3)`` and a validity mask."""
    x, y, z = P[..., 0], P[..., 1], P[..., 2]
    valid = z > _MIN_DEPTH
    inv_z = 1.0 / np.where(valid, z, 1.0)
    fx, fy, b = camera.fx, camera.fy, camera.baseline
    proj = np.empty(P.shape[:-1] + (4,))
    proj[..., 0] = fx * x * inv_z + camera.cx
    proj[..., 1] = fy * y * inv_z + camera.cy
    proj[..., 2] = proj[..., 0] - fx * b * inv_z
    proj[..., 3] = proj[..., 1]
    J = np.zeros(P.shape[:-1] + (4, 3))
    fx_z = fx * inv_z
    J[..., 0, 0] = fx_z
    J[..., 0, 2] = -fx_z * x * inv_z
    J[..., 1, 1] = fy * inv_z
    J[..., 1, 2] = -fy * y * inv_z * inv_z
    J[..., 2, 0] = fx_z
    J[..., 2, 2] = -fx_z * (x - b) * inv_z
    J[..., 3, :] = J[..., 1, :]
    return proj, J, valid


def _cross_rows(P: np.ndarray, A: np.ndarray, out: np.ndarray) -> None:
    """``out[..., r, :] = P x A[..., r, :]`` for points ``(..., 3)`` and rows ``(..., R, 3)``.

    Written out by component: ``np.cross`` on small trailing axes costs several times more.
    """
    p0, p1, p2 = P[..., 0, None], P[..., 1, None], P[..., 2, None]
    a0, a1, a2 = A[..., 0], A[..., 1], A[..., 2]
    out[..., 0] = p1 * a2 - p2 * a1
    out[..., 1] = p2 * a0 - p0 * a2
    out[..., 2] = p0 * a1 - p1 * a0


def residuals_and_jacobians(
    camera: StereoCamera,
    R: np.ndarray,
    t: np.ndarray,
    points_prev: np.ndarray,
    points_curr: np.ndarray,
    meas_prev: np.ndarray,
    meas_curr: np.ndarray,
    with_jacobian: bool = True,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Symmetric reprojection residuals ``(H, M, 8)`` and Jacobians ``(H, M, 8, 6)``.

    Args:
        R, t: ``(H, 3, 3)`` and ``(H, 3)`` motions, ``x_k = R x_{k-1} + t``.
        points_prev, points_curr: ``(H, M, 3)`` or ``(M, 3)`` triangulated points.
        meas_prev, meas_curr: matching ``(..., M, 4)`` pixel measurements.
        with_jacobian: False skips the Jacobian (returned as None) for cost-only evaluations.
    """
    fwd = points_prev @ np.swapaxes(R, -1, -2) + t[:, None, :]
    bwd = (points_curr - t[:, None, :]) @ R
    proj_f, Jp_f, ok_f = _project_with_jacobian(camera, fwd)
    proj_b, Jp_b, ok_b = _project_with_jacobian(camera, bwd)
    res = np.concatenate([proj_f - meas_curr, proj_b - meas_prev], axis=-1)
    bad = ~(ok_f & ok_b)
    if np.any(bad):
        res = np.where(bad[..., None], _BEHIND_CAMERA_RESIDUAL, res)
    if not with_jacobian:
        return res, None
    # Rows a of d(proj)/dP: d/d rho = a and d/d omega = P x a for the forward point;
    # with b = a R^T, d/d rho = -b and d/d omega = b x Y = -(Y x b) for the backward one.
    jac = np.empty(res.shape + (6,))
    jac[..., :4, :3] = Jp_f
    _cross_rows(fwd, Jp_f, jac[..., :4, 3:])
    B = Jp_b @ np.swapaxes(R, -1, -2)[:, None]
    jac[..., 4:, :3] = -B
    _cross_rows(np.broadcast_to(points_curr, bwd.shape), B, jac[..., 4:, 3:])
    jac[..., 4:, 3:] *= -1.0
    if np.any(bad):
        jac = np.where(bad[..., None, None], 0.0, jac)
    return res, jac


def _step(
    R: np.ndarray, t: np.ndarray, res: np.ndarray, jac: np.ndarray, w: np.ndarray | None, damping: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One (damped) Gauss-Newton step per hypothesis: solve the weighted normal equations with
    ``damping (H,)`` relative to their diagonal, apply ``exp(delta)`` on the left.

    Returns the new ``(R, t)`` and the steps ``delta (H, 6)``.
    """
    H = R.shape[0]
    J = jac.reshape(H, -1, 6)
    JtW = np.swapaxes(J if w is None else J * np.repeat(w, jac.shape[2], axis=1)[..., None], -1, -2)
    A = JtW @ J
    g = (JtW @ res.reshape(H, -1, 1))[..., 0]
    scale = np.maximum(np.einsum("hkk->hk", A), 1e-9)
    A = A + (damping[:, None] * scale)[:, :, None] * np.eye(6)
    try:
        delta = -np.linalg.solve(A, g[..., None])[..., 0]
    except np.linalg.LinAlgError:
        delta = -np.einsum("hkl,hl->hk", np.linalg.pinv(A), g)
    dR, dt = se3_exp(delta)
    return dR @ R, np.einsum("hij,hj->hi", dR, t) + dt, delta


def gauss_newton_steps(
    camera: StereoCamera,
    R: np.ndarray,
    t: np.ndarray,
    points_prev: np.ndarray,
    points_curr: np.ndarray,
    meas_prev: np.ndarray,
    meas_curr: np.ndarray,
    weights: np.ndarray | None = None,
    iterations: int = 3,
    damping: float = 1e-6,
    huber: float | None = None,
    tolerance: float = 1e-12,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Levenberg-Marquardt iterations on the symmetric reprojection error, for H hypotheses at once.

    Args:
        weights: optional ``(H, M)`` or ``(M,)`` per-point weights (0 drops a point).
        damping: LM damping added to the normal equations' diagonal (relative to its scale).
        huber: optional Huber threshold in pixels on each point's residual norm.
        tolerance: stop early once every hypothesis' step is below this (radians / metres) or
            its cost fell by less than a relative 1e-9.

    Returns:
        ``(R, t, cost)``: refined motions and the final weighted squared cost ``(H,)`` (pixels^2).
        A step that raises the cost is rejected for that hypothesis and its damping raised.
    """
    H = R.shape[0]
    lam = np.full(H, damping)
    w_base = None if weights is None else np.broadcast_to(np.asarray(weights, dtype=float), (H, meas_curr.shape[-2]))

    def weights_and_cost(res):
        sq = np.sum(res**2, axis=-1)
        w = np.ones_like(sq) if w_base is None else w_base
        if huber is not None:
            norm = np.sqrt(sq)
            w = w * np.where(norm > huber, huber / np.maximum(norm, 1e-12), 1.0)
        return w, np.sum(w * sq, axis=-1)

    args = (points_prev, points_curr, meas_prev, meas_curr)
    res, jac = residuals_and_jacobians(camera, R, t, *args)
    w, cost = weights_and_cost(res)
    for _ in range(iterations):
        R_new, t_new, delta = _step(R, t, res, jac, w, lam)
        res_new, _ = residuals_and_jacobians(camera, R_new, t_new, *args, with_jacobian=False)
        w_new, cost_new = weights_and_cost(res_new)
        better = cost_new <= cost
        lam = np.where(better, lam * 0.3, lam * 10.0)
        if not np.any(better):
            continue
        converged = np.all(better) and (
            np.all(np.abs(delta) < tolerance) or np.all(cost - cost_new <= 1e-9 * cost)
        )
        R = np.where(better[:, None, None], R_new, R)
        t = np.where(better[:, None], t_new, t)
        cost = np.where(better, cost_new, cost)
        if converged:
            break
        res, jac = residuals_and_jacobians(camera, R, t, *args)
        w, cost = weights_and_cost(res)
    return R, t, cost


def gauss_newton_polish(
    camera: StereoCamera,
    R: np.ndarray,
    t: np.ndarray,
    points_prev: np.ndarray,
    points_curr: np.ndarray,
    meas_prev: np.ndarray,
    meas_curr: np.ndarray,
    iterations: int = 2,
) -> tuple[np.ndarray, np.ndarray]:
    """Plain Gauss-Newton steps for many small problems (minimal samples), no step control.

    Started from a Kabsch fit, the undamped steps converge in one or two iterations; a
    hypothesis that diverges instead just scores badly, which is cheaper than checking
    every step's cost for all of them.
    """
    damping = np.full(R.shape[0], 1e-9)  # only guards a singular system, no step control
    for _ in range(iterations):
        res, jac = residuals_and_jacobians(camera, R, t, points_prev, points_curr, meas_prev, meas_curr)
        R, t, _ = _step(R, t, res, jac, None, damping)
    return R, t


def reprojection_sq(
    camera: StereoCamera, R: np.ndarray, t: np.ndarray, points_prev: np.ndarray, meas_curr: np.ndarray
) -> np.ndarray:
    """Squared forward reprojection error ``(H, N)`` in pixels^2 of the k-1 points in both images at k."""
    fwd = points_prev @ np.swapaxes(R, -1, -2) + t[:, None, :]
    z = fwd[..., 2]
    valid = z > _MIN_DEPTH
    inv_z = 1.0 / np.where(valid, z, 1.0)
    uL = camera.fx * fwd[..., 0] * inv_z + camera.cx
    v = camera.fy * fwd[..., 1] * inv_z + camera.cy
    uR = uL - camera.fx * camera.baseline * inv_z
    sq = (uL - meas_curr[:, 0]) ** 2 + (uR - meas_curr[:, 2]) ** 2 + (v - meas_curr[:, 1]) ** 2 + (v - meas_curr[:, 3]) ** 2
    return np.where(valid, sq, np.inf)
