"""The data of one motion estimate, validated once and precomputed for every role.

``StereoProblem`` turns two ``(N, 4)`` arrays of stereo measurements into the
quantities all samplers, solvers and scorers share: triangulated points at
k-1 and k, their covariances and the pixel noise. Building it is the single
place where malformed input is rejected with ``ValueError``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stereovo.camera import StereoCamera


def _as_measurements(name: str, value: np.ndarray) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.ndim != 2 or array.shape[1] != 4:
        raise ValueError(f"{name} must have shape (N, 4) of (uL, vL, uR, vR) pixels, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        bad = int(np.count_nonzero(~np.all(np.isfinite(array), axis=1)))
        raise ValueError(f"{name} contains NaN or inf in {bad} row(s)")
    return array


@dataclass(frozen=True)
class StereoProblem:
    """Putative matches between frames k-1 and k with everything derived from them.

    Attributes:
        prev, curr: ``(N, 4)`` stereo measurements (pixels) at k-1 and k.
        camera: the rectified stereo rig.
        noise_sigma: pixel noise standard deviation (pixels) of every coordinate.
        points_prev, points_curr: ``(N, 3)`` triangulated points (metres), camera frames k-1 and k.
        cov_prev, cov_curr: ``(N, 3, 3)`` triangulation covariances (m^2).
    """

    prev: np.ndarray
    curr: np.ndarray
    camera: StereoCamera
    noise_sigma: float
    points_prev: np.ndarray
    points_curr: np.ndarray
    cov_prev: np.ndarray
    cov_curr: np.ndarray

    @classmethod
    def build(
        cls, prev: np.ndarray, curr: np.ndarray, camera: StereoCamera, noise_sigma: float = 0.5
    ) -> "StereoProblem":
        """Validate the measurements and triangulate them.

        Raises:
            ValueError: wrong shapes, mismatched N, NaN/inf, a non-positive noise, or a
                disparity at or below ``camera.min_disparity`` (no depth to triangulate).
        """
        if not isinstance(camera, StereoCamera):
            raise ValueError(f"camera must be a StereoCamera, got {type(camera).__name__}")
        prev = _as_measurements("prev", prev)
        curr = _as_measurements("curr", curr)
        if prev.shape[0] != curr.shape[0]:
            raise ValueError(f"prev and curr must have the same number of rows, got {prev.shape[0]} and {curr.shape[0]}")
        if not np.isfinite(noise_sigma) or noise_sigma <= 0:
            raise ValueError(f"noise_sigma must be a positive pixel noise, got {noise_sigma!r}")
        triangulated = []
        for name, meas in (("prev", prev), ("curr", curr)):
            try:  # triangulation checks every disparity itself; the rows are named only on failure
                triangulated.append(camera.triangulate_with_covariance(meas, noise_sigma))
            except ValueError:
                low = ~camera.has_depth(meas)
                raise ValueError(
                    f"{name} has {int(low.sum())} row(s) with disparity uL - uR <= {camera.min_disparity} px "
                    f"(first at row {int(np.argmax(low))}): no depth can be triangulated"
                ) from None
        (points_prev, cov_prev), (points_curr, cov_curr) = triangulated
        return cls(
            prev=prev,
            curr=curr,
            camera=camera,
            noise_sigma=float(noise_sigma),
            points_prev=points_prev,
            points_curr=points_curr,
            cov_prev=cov_prev,
            cov_curr=cov_curr,
        )

    @property
    def n(self) -> int:
        """Number of putative correspondences N."""
        return self.prev.shape[0]
