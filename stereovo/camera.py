"""Rectified stereo pinhole camera: projection, triangulation and its covariance.

A stereo measurement is ``z = (uL, vL, uR, vR)`` in pixels; the right camera
sits at ``(+baseline, 0, 0)`` in the left camera frame (x right, y down,
z forward). Every method is vectorised over points: ``(N, 3)`` points in
metres, ``(N, 4)`` measurements in pixels.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _project_rows(X, fx, fy, cx, cy, minus_fx_baseline, out):
    """:meth:`StereoCamera.project` of points ``(N, 3)`` into ``out (N, 4)``, in the same order of
    operations. (The caller allocates ``out``: an array numba allocates carries a dtype object
    equal to, but not the same as, numpy's own float64, and ``np.asarray(a, dtype=float)`` then
    returns a view instead of ``a``.)"""
    n = X.shape[0]
    for i in range(n):
        inv_z = 1.0 / X[i, 2]
        uL = X[i, 0] * inv_z * fx + cx
        v = X[i, 1] * inv_z * fy + cy
        out[i, 0] = uL
        out[i, 1] = v
        out[i, 2] = inv_z * minus_fx_baseline + uL
        out[i, 3] = v


@njit(cache=True, nogil=True)
def _triangulate_rows(meas, fx, fy, cx, cy, baseline, min_disparity, sigma, with_covariance):
    """Points ``(M, 3)`` and, if ``with_covariance``, covariances ``(M, 3, 3)`` (else ``(0, 3, 3)``)
    of measurements ``meas (M, 4)``, and the first row without depth (-1 if none; the arrays are
    then incomplete). One pass instead of some forty numpy passes over ``(M,)`` temporaries.

    ``C = sigma^2 J J^T`` written out from the sparse rows of the triangulation Jacobian
    (:meth:`StereoCamera.triangulation_jacobian`):
    ``(z/fx - x/d, 0, x/d, 0)``, ``(-y/d, z/2fy, y/d, z/2fy)``, ``(-z/d, 0, z/d, 0)``.
    """
    M = meas.shape[0]
    X = np.empty((M, 3))
    C = np.empty((M if with_covariance else 0, 3, 3))
    s2 = sigma * sigma
    for m in range(M):
        d = meas[m, 0] - meas[m, 2]
        if not d > min_disparity:
            return X, C, m
        depth = fx * baseline / d
        x = (meas[m, 0] - cx) * depth / fx
        y = ((meas[m, 1] + meas[m, 3]) / 2 - cy) * depth / fy
        X[m, 0], X[m, 1], X[m, 2] = x, y, depth
        if with_covariance:
            x_d, y_d, z_d = x / d, y / d, depth / d
            a = depth / fx - x_d
            h = depth / (2 * fy)
            C[m, 0, 0] = s2 * (a * a + x_d * x_d)
            C[m, 0, 1] = C[m, 1, 0] = s2 * (x_d - a) * y_d
            C[m, 0, 2] = C[m, 2, 0] = s2 * (x_d - a) * z_d
            C[m, 1, 1] = s2 * 2 * (y_d * y_d + h * h)
            C[m, 1, 2] = C[m, 2, 1] = s2 * 2 * y_d * z_d
            C[m, 2, 2] = s2 * 2 * z_d * z_d
    return X, C, -1


@dataclass(frozen=True)
class StereoCamera:
    """A rectified stereo pair; the defaults are the KITTI-like rig of DESIGN.md.

    Args:
        fx, fy: focal lengths in pixels.
        cx, cy: principal point in pixels.
        baseline: distance between the two optical centres in metres.
        width, height: image size in pixels.
        min_disparity: disparities at or below this (pixels) carry no usable depth.
    """

    fx: float = 718.856
    fy: float = 718.856
    cx: float = 607.19
    cy: float = 185.22
    baseline: float = 0.5372
    width: int = 1241
    height: int = 376
    min_disparity: float = 0.1

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "baseline", "width", "height", "min_disparity"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"StereoCamera.{name} must be a positive finite number, got {value!r}")
        for name in ("cx", "cy"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"StereoCamera.{name} must be finite, got {getattr(self, name)!r}")

    @functools.cached_property
    def parameters(self) -> np.ndarray:
        """``(fx, fy, cx, cy, baseline)`` as one read-only float array: the layout compiled kernels
        take, built once per camera (the estimator passes it a few dozen times per frame)."""
        vector = np.array([self.fx, self.fy, self.cx, self.cy, self.baseline], dtype=float)
        vector.flags.writeable = False
        return vector

    @property
    def intrinsics(self) -> np.ndarray:
        """The 3x3 matrix K of the left camera."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, points: np.ndarray) -> np.ndarray:
        """Stereo measurements ``(..., 4)`` of points ``(..., 3)`` in the left camera frame.

        Points must lie in front of the camera (z > 0); use :meth:`is_visible` first.
        """
        X = np.asarray(points, dtype=float)
        if X.ndim == 2 and X.shape[1] == 3:  # the common case, compiled (numpy's calls cost more than the work)
            out = np.empty((X.shape[0], 4))
            _project_rows(
                X, float(self.fx), float(self.fy), float(self.cx), float(self.cy), float(-self.fx * self.baseline), out
            )
            return out
        inv_z = 1.0 / X[..., 2]
        out = np.empty(X.shape[:-1] + (4,))
        np.multiply(X[..., 0], inv_z, out=out[..., 0])
        out[..., 0] *= self.fx
        out[..., 0] += self.cx
        np.multiply(X[..., 1], inv_z, out=out[..., 1])
        out[..., 1] *= self.fy
        out[..., 1] += self.cy
        np.multiply(inv_z, -self.fx * self.baseline, out=out[..., 2])
        out[..., 2] += out[..., 0]
        out[..., 3] = out[..., 1]
        return out

    def disparity(self, measurements: np.ndarray) -> np.ndarray:
        """Disparity ``uL - uR`` in pixels of measurements ``(..., 4)``."""
        z = np.asarray(measurements, dtype=float)
        return z[..., 0] - z[..., 2]

    def has_depth(self, measurements: np.ndarray) -> np.ndarray:
        """Boolean mask of measurements whose disparity exceeds ``min_disparity``."""
        return self.disparity(measurements) > self.min_disparity

    def triangulate(self, measurements: np.ndarray) -> np.ndarray:
        """Points ``(..., 3)`` in metres from stereo measurements ``(..., 4)``.

        Raises:
            ValueError: if any disparity is at or below ``min_disparity``; such a
                measurement has no depth and is never divided by.
        """
        return self._triangulate(measurements, None)[0]

    def triangulate_with_covariance(self, measurements: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`triangulate` and :meth:`triangulation_covariance` in one pass: points ``(..., 3)``
        (m) and covariances ``(..., 3, 3)`` (m^2) under isotropic pixel noise ``sigma`` (pixels)."""
        return self._triangulate(measurements, sigma)

    def _triangulate(self, measurements: np.ndarray, sigma: float | None) -> tuple[np.ndarray, np.ndarray]:
        if sigma is not None and (not np.isfinite(sigma) or sigma <= 0):
            raise ValueError(f"sigma must be a positive pixel noise, got {sigma!r}")
        z = np.asarray(measurements, dtype=float)
        rows = np.ascontiguousarray(z.reshape(-1, 4))
        X, C, bad_row = _triangulate_rows(
            rows, float(self.fx), float(self.fy), float(self.cx), float(self.cy), float(self.baseline),
            float(self.min_disparity), 1.0 if sigma is None else float(sigma), sigma is not None,
        )
        if bad_row >= 0:
            bad = int(np.count_nonzero(~(self.disparity(z) > self.min_disparity)))
            raise ValueError(
                f"{bad} measurement(s) have disparity <= min_disparity={self.min_disparity} px: no depth"
            )
        lead = z.shape[:-1]
        return X.reshape(lead + (3,)), (C.reshape(lead + (3, 3)) if sigma is not None else C)

    def triangulation_jacobian(self, measurements: np.ndarray) -> np.ndarray:
        """Jacobians ``(..., 3, 4)`` of the triangulated point w.r.t. ``(uL, vL, uR, vR)``."""
        X = self.triangulate(measurements)
        d = self.disparity(measurements)
        x, y, depth = X[..., 0], X[..., 1], X[..., 2]
        J = np.zeros(X.shape[:-1] + (3, 4))
        J[..., 0, 0] = depth / self.fx - x / d
        J[..., 0, 2] = x / d
        J[..., 1, 0] = -y / d
        J[..., 1, 1] = depth / (2 * self.fy)
        J[..., 1, 2] = y / d
        J[..., 1, 3] = depth / (2 * self.fy)
        J[..., 2, 0] = -depth / d
        J[..., 2, 2] = depth / d
        return J

    def triangulation_covariance(self, measurements: np.ndarray, sigma: float) -> np.ndarray:
        """Covariances ``(..., 3, 3)`` in m^2 of triangulated points: ``sigma^2 J J^T``.

        Args:
            measurements: ``(..., 4)`` stereo measurements in pixels.
            sigma: isotropic pixel noise standard deviation (pixels).
        """
        return self._triangulate(measurements, sigma)[1]

    def in_image(self, measurements: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Mask of measurements whose left and right pixels lie inside the image."""
        z = np.asarray(measurements, dtype=float)
        u_max, v_max = self.width - 1 - margin, self.height - 1 - margin
        ok = (z[..., 0] >= margin) & (z[..., 0] <= u_max)
        ok &= (z[..., 2] >= margin) & (z[..., 2] <= u_max)
        ok &= (z[..., 1] >= margin) & (z[..., 1] <= v_max)
        ok &= (z[..., 3] >= margin) & (z[..., 3] <= v_max)
        return ok

    def is_visible(
        self, points: np.ndarray, z_min: float = 0.5, z_max: float = np.inf, margin: float = 0.0
    ) -> np.ndarray:
        """Mask of points ``(..., 3)`` seen by both cameras within ``[z_min, z_max]`` metres."""
        X = np.asarray(points, dtype=float)
        depth = X[..., 2]
        ok = (depth >= z_min) & (depth <= z_max)
        meas = self.project(np.where(ok[..., None], X, np.array([0.0, 0.0, 1.0])))
        return ok & self.in_image(meas, margin) & (self.disparity(meas) > self.min_disparity)
