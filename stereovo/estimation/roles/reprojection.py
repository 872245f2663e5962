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

The arithmetic runs in the compiled kernels of :mod:`stereovo.estimation.kernels`;
this module fixes the shapes, defaults and meaning.
"""

from __future__ import annotations

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.estimation.kernels.least_squares import gauss_newton
from stereovo.estimation.kernels.residuals import forward_reprojection_sq, symmetric_residuals


def _grouped(array: np.ndarray, width: int) -> np.ndarray:
    """``(G, M, width)`` contiguous float view: ``(M, width)`` becomes one group shared by all hypotheses."""
    if (
        type(array) is np.ndarray and array.dtype == np.float64 and array.ndim == 2
        and array.shape[1] == width and array.flags.c_contiguous
    ):
        return array[None]  # the common case (a problem's own arrays): a view, no conversion or copy
    array = np.asarray(array, dtype=float)
    if array.ndim == 2:
        array = array[None]
    if array.ndim != 3 or array.shape[-1] != width:
        raise ValueError(f"expected points of shape (M, {width}) or (H, M, {width}), got {array.shape}")
    return np.ascontiguousarray(array)


def _motions(R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(t, dtype=float)


def _kernel_problem(camera, R, t, points_prev, points_curr, meas_prev, meas_curr) -> tuple:
    """``(R, t, X, Y, meas_prev, meas_curr, cam)`` in the layout the kernels take."""
    return (*_motions(R, t), _grouped(points_prev, 3), _grouped(points_curr, 3), _grouped(meas_prev, 4),
            _grouped(meas_curr, 4), camera.parameters)


def residuals_and_jacobians(
    camera: StereoCamera, R: np.ndarray, t: np.ndarray, points_prev: np.ndarray, points_curr: np.ndarray,
    meas_prev: np.ndarray, meas_curr: np.ndarray, with_jacobian: bool = True,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Symmetric reprojection residuals ``(H, M, 8)`` and Jacobians ``(H, M, 8, 6)``.

    Args:
        R, t: ``(H, 3, 3)`` and ``(H, 3)`` motions, ``x_k = R x_{k-1} + t``.
        points_prev, points_curr: ``(H, M, 3)`` or ``(M, 3)`` triangulated points.
        meas_prev, meas_curr: matching ``(..., M, 4)`` pixel measurements.
        with_jacobian: False skips the Jacobian (returned as None) for cost-only evaluations.

    A point behind either camera gets residual rows of ``1e3`` px and a zero Jacobian.
    """
    args = _kernel_problem(camera, R, t, points_prev, points_curr, meas_prev, meas_curr)
    res, jac = symmetric_residuals(*args, with_jacobian)
    return res, (jac if with_jacobian else None)


def gauss_newton_steps(
    camera: StereoCamera, R: np.ndarray, t: np.ndarray, points_prev: np.ndarray, points_curr: np.ndarray,
    meas_prev: np.ndarray, meas_curr: np.ndarray,
    weights: np.ndarray | None = None,
    iterations: int = 3,
    damping: float = 1e-6,
    huber: float | None = None,
    tolerance: float = 1e-12,
    step_control: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Levenberg-Marquardt iterations on the symmetric reprojection error, for H hypotheses at once.

    Args:
        weights: optional ``(H, M)`` or ``(M,)`` per-point weights (0 drops a point).
        damping: LM damping added to the normal equations' diagonal (relative to its scale).
        huber: optional Huber threshold in pixels on each point's residual norm.
        tolerance: a hypothesis stops once its step is below this (radians / metres) or, with
            step control, once the next step would move it by less than 1 % of the pose's standard
            deviation (:data:`stereovo.estimation.kernels.least_squares.CONVERGED_STEP_IN_STD`).
        step_control: False takes every step (plain Gauss-Newton, as the minimal-sample polish does).

    Returns:
        ``(R, t, cost)``: refined motions and the final weighted squared cost ``(H,)`` (pixels^2).
        With step control, a step that raises the cost is rejected for that hypothesis and its
        damping raised.
    """
    args = _kernel_problem(camera, R, t, points_prev, points_curr, meas_prev, meas_curr)
    w = np.ones((1, args[2].shape[1])) if weights is None else np.asarray(weights, dtype=float)
    w = np.ascontiguousarray(w[None] if w.ndim == 1 else w)
    return gauss_newton(
        *args, w, 0.0 if huber is None else float(huber), int(iterations), float(damping), float(tolerance),
        step_control,
    )


def reprojection_sq(
    camera: StereoCamera, R: np.ndarray, t: np.ndarray, points_prev: np.ndarray, meas_curr: np.ndarray
) -> np.ndarray:
    """Squared forward reprojection error ``(H, N)`` in pixels^2 of the k-1 points in both images at k.

    ``inf`` where the moved point is behind the camera.
    """
    R, t = _motions(R, t)
    return forward_reprojection_sq(
        R, t, np.ascontiguousarray(points_prev, dtype=float), np.ascontiguousarray(meas_curr, dtype=float),
        camera.parameters,
    )
