"""Rectified stereo pinhole camera: projection, triangulation and its covariance.

A stereo measurement is ``z = (uL, vL, uR, vR)`` in pixels; the right camera
sits at ``(+baseline, 0, 0)`` in the left camera frame (x right, y down,
z forward). Every method is vectorised over points: ``(N, 3)`` points in
metres, ``(N, 4)`` measurements in pixels.

Covariances propagate the noise of what a match measured. On a rectified pair
the right feature is searched on the left feature's row, so one match
measures ``(uL, uR, v)`` with a single ``v`` noise (``v_measurement="shared"``,
the default, and what the simulator does); ``"independent"`` treats ``vL`` and
``vR`` as two measurements, whose mean has half the variance. Either way the
check is calibration: a chi-square gate passes its probability of the true
inliers under the true motion (``tests/test_covariance_calibration.py``).

A match whose disparity is at or below ``min_disparity`` (or whose triangulated
point is not finite) has no depth: :meth:`StereoCamera.triangulate_usable`
flags it and gives it NaN; :meth:`StereoCamera.triangulate` refuses it.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numba import njit

from stereovo.options import Integer, Number


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
def _triangulate_rows(meas, fx, fy, cx, cy, baseline, min_disparity, sigma, v_variance, with_covariance, usable):
    """Points ``(M, 3)`` and, if ``with_covariance``, covariances ``(M, 3, 3)`` (else ``(0, 3, 3)``)
    of measurements ``meas (M, 4)``; ``usable (M,)`` is set True on rows with depth and False on
    rows without (disparity not above ``min_disparity``, or a non-finite point or covariance),
    whose points and covariances are NaN. Returns the number of rows without depth. One pass
    instead of some forty numpy passes over ``(M,)`` temporaries.

    ``C = sigma^2 J J^T`` written out from the sparse rows of the triangulation Jacobian
    (:meth:`StereoCamera.triangulation_jacobian`) with respect to ``(uL, uR, v)``:
    ``(z/fx - x/d, x/d, 0)``, ``(-y/d, y/d, z/fy)``, ``(-z/d, z/d, 0)``; ``v_variance`` is the
    variance of the v used for y in units of ``sigma^2`` (1: one v per match, 1/2: the mean of
    independent vL and vR).
    """
    M = meas.shape[0]
    X = np.empty((M, 3))
    C = np.empty((M if with_covariance else 0, 3, 3))
    s2 = sigma * sigma
    n_bad = 0
    for m in range(M):
        d = meas[m, 0] - meas[m, 2]
        ok = d > min_disparity and np.isfinite(d)
        if ok:
            depth = fx * baseline / d
            x = (meas[m, 0] - cx) * depth / fx
            y = ((meas[m, 1] + meas[m, 3]) / 2 - cy) * depth / fy
            ok = depth > 0.0 and np.isfinite(x) and np.isfinite(y) and np.isfinite(depth)
        if ok:
            X[m, 0], X[m, 1], X[m, 2] = x, y, depth
            if with_covariance:
                x_d, y_d, z_d = x / d, y / d, depth / d
                a = depth / fx - x_d
                h = depth / fy
                C[m, 0, 0] = s2 * (a * a + x_d * x_d)
                C[m, 0, 1] = C[m, 1, 0] = s2 * (x_d - a) * y_d
                C[m, 0, 2] = C[m, 2, 0] = s2 * (x_d - a) * z_d
                if v_variance == 1.0:
                    C[m, 1, 1] = s2 * (2 * y_d * y_d + h * h)
                else:  # the mean of two v's (written as it always was, so old figures reproduce bit for bit)
                    h2 = depth / (2 * fy)
                    C[m, 1, 1] = s2 * 2 * (y_d * y_d + h2 * h2)
                C[m, 1, 2] = C[m, 2, 1] = s2 * 2 * y_d * z_d
                C[m, 2, 2] = s2 * 2 * z_d * z_d
                # one test for all six entries: an inf or NaN among them makes the sum inf or NaN
                ok = np.isfinite(C[m, 0, 0] + C[m, 0, 1] + C[m, 0, 2] + C[m, 1, 1] + C[m, 1, 2] + C[m, 2, 2])
        if not ok:
            n_bad += 1
            X[m, :] = np.nan
            if with_covariance:
                C[m, :, :] = np.nan
        usable[m] = ok
    return X, C, n_bad


V_MEASUREMENTS: tuple[str, ...] = ("shared", "independent")
"""How a match measures its rows (:attr:`StereoCamera.v_measurement`)."""

MAX_IMAGE_SIZE_PX = 2**53
"""The largest image width or height (px): pixel coordinates are float64, which hold every integer
only up to 2**53 (a larger size would not even convert to a float beyond ~1e308)."""

_CAMERA_RULES = {
    "fx": Number(low=0.0, low_open=True, unit="px"),
    "fy": Number(low=0.0, low_open=True, unit="px"),
    "cx": Number(unit="px"),
    "cy": Number(unit="px"),
    "baseline": Number(low=0.0, low_open=True, unit="m"),
    "width": Integer(low=1, high=MAX_IMAGE_SIZE_PX),
    "height": Integer(low=1, high=MAX_IMAGE_SIZE_PX),
    "min_disparity": Number(low=0.0, low_open=True, unit="px"),
}
"""Declarations (:mod:`stereovo.options`) of :class:`StereoCamera`'s numeric fields."""


@dataclass(frozen=True)
class StereoCamera:
    """A rectified stereo pair; the defaults are a KITTI-like rig (Geiger, Lenz & Urtasun, CVPR 2012).

    Args:
        fx, fy: focal lengths in pixels.
        cx, cy: principal point in pixels.
        baseline: distance between the two optical centres in metres.
        width, height: image size in pixels (integers >= 1, not bools).
        min_disparity: disparities at or below this (pixels) carry no usable depth.
        v_measurement: ``"shared"`` (one ``v`` per rectified match, ``vL = vR``; default) or
            ``"independent"`` (``vL`` and ``vR`` measured apart, each with the pixel noise): the
            noise model of triangulation covariances and of the pixel Mahalanobis residual.

    Raises:
        ValueError: naming the field and the value: fx, fy, baseline and min_disparity must be
            finite real numbers > 0, cx and cy finite real numbers, width and height integers in
            ``[1, 2**53]`` (``1.5``, ``True``, ``"700"``, ``[700]`` and ``10**400`` are refused).
    """

    fx: float = 718.856
    fy: float = 718.856
    cx: float = 607.19
    cy: float = 185.22
    baseline: float = 0.5372
    width: int = 1241
    height: int = 376
    min_disparity: float = 0.1
    v_measurement: str = "shared"

    def __post_init__(self) -> None:
        if not (isinstance(self.v_measurement, str) and self.v_measurement in V_MEASUREMENTS):
            raise ValueError(
                f"StereoCamera.v_measurement must be one of {list(V_MEASUREMENTS)}, got {self.v_measurement!r}"
            )
        # By the one options contract (stereovo.options), naming the field and the value; the values
        # are checked, not converted (a camera keeps what it was given).
        for name, rule in _CAMERA_RULES.items():
            rule.check(name, getattr(self, name), prefix="StereoCamera.")

    @property
    def v_per_match(self) -> int:
        """Independent ``v`` measurements per stereo pair: 1 (``"shared"``) or 2 (``"independent"``)."""
        return 1 if self.v_measurement == "shared" else 2

    @property
    def measurement_dof(self) -> int:
        """Independent pixel coordinates per stereo pair, ``uL``, ``uR`` and the v's: 3 or 4 (the
        degrees of freedom of a whitened stereo reprojection residual)."""
        return 2 + self.v_per_match

    @functools.cached_property
    def parameters(self) -> np.ndarray:
        """``(fx, fy, cx, cy, baseline, v_per_match)`` as one read-only float array: the layout
        compiled kernels take, built once per camera (the estimator passes it a few dozen times
        per frame)."""
        vector = np.array([self.fx, self.fy, self.cx, self.cy, self.baseline, self.v_per_match], dtype=float)
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
            ValueError: if any measurement has no depth (disparity at or below
                ``min_disparity``); such a measurement is never divided by. Use
                :meth:`triangulate_usable` to flag such rows instead.
        """
        return self._triangulate(measurements, None)[0]

    def triangulate_with_covariance(self, measurements: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`triangulate` and :meth:`triangulation_covariance` in one pass: points ``(..., 3)``
        (m) and covariances ``(..., 3, 3)`` (m^2) under isotropic pixel noise ``sigma`` (pixels)."""
        return self._triangulate(measurements, sigma)

    def triangulate_usable(
        self, measurements: np.ndarray, sigma: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points ``(N, 3)``, covariances ``(N, 3, 3)`` and the usable mask ``(N,)`` of measurements
        ``(N, 4)``, without refusing rows that have no depth: those are False in the mask and NaN in
        the points and covariances (the estimator treats them as outliers, DESIGN section 3)."""
        rows = self._rows(measurements)
        return self._triangulate_rows(rows, sigma)

    def _rows(self, measurements: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(measurements, dtype=float).reshape(-1, 4))

    def _triangulate_rows(
        self, rows: np.ndarray, sigma: float | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if sigma is not None and (not np.isfinite(sigma) or sigma <= 0):
            raise ValueError(f"sigma must be a positive pixel noise, got {sigma!r}")
        usable = np.empty(rows.shape[0], dtype=bool)
        X, C, _ = _triangulate_rows(
            rows, float(self.fx), float(self.fy), float(self.cx), float(self.cy), float(self.baseline),
            float(self.min_disparity), 1.0 if sigma is None else float(sigma), 1.0 / self.v_per_match,
            sigma is not None, usable,
        )
        return X, C, usable

    def _triangulate(self, measurements: np.ndarray, sigma: float | None) -> tuple[np.ndarray, np.ndarray]:
        z = np.asarray(measurements, dtype=float)
        X, C, usable = self._triangulate_rows(self._rows(z), sigma)
        if not usable.all():
            bad = int(np.count_nonzero(~usable))
            raise ValueError(
                f"{bad} measurement(s) have disparity <= min_disparity={self.min_disparity} px "
                "(or no finite triangulation): no depth"
            )
        lead = z.shape[:-1]
        return X.reshape(lead + (3,)), (C.reshape(lead + (3, 3)) if sigma is not None else C)

    def triangulation_jacobian(self, measurements: np.ndarray) -> np.ndarray:
        """Jacobians ``(..., 3, 4)`` of the triangulated point w.r.t. ``(uL, vL, uR, vR)``.

        Triangulation uses ``v = (vL + vR) / 2``, so the v columns are halves of
        :meth:`shared_triangulation_jacobian`'s single v column.
        """
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

    def shared_triangulation_jacobian(self, measurements: np.ndarray) -> np.ndarray:
        """Jacobians ``(..., 3, 3)`` of the triangulated point w.r.t. ``(uL, uR, v)``, the three
        quantities a rectified match measures (``v = (vL + vR) / 2``)."""
        J4 = self.triangulation_jacobian(measurements)
        return np.stack([J4[..., 0], J4[..., 2], J4[..., 1] + J4[..., 3]], axis=-1)

    def measurement_jacobian(self, measurements: np.ndarray) -> np.ndarray:
        """The triangulation Jacobian w.r.t. the measured quantities of this camera's
        ``v_measurement``: ``(..., 3, 3)`` over ``(uL, uR, v)`` (shared) or ``(..., 3, 4)`` over
        ``(uL, vL, uR, vR)`` (independent). Covariances are ``sigma^2 J J^T`` of it."""
        if self.v_measurement == "shared":
            return self.shared_triangulation_jacobian(measurements)
        return self.triangulation_jacobian(measurements)

    def triangulation_covariance(self, measurements: np.ndarray, sigma: float) -> np.ndarray:
        """Covariances ``(..., 3, 3)`` in m^2 of triangulated points: ``sigma^2 J J^T`` with ``J`` the
        :meth:`measurement_jacobian` of this camera's ``v_measurement``.

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
