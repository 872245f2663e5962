"""The data of one motion estimate, validated once and precomputed for every role.

``StereoProblem`` turns two ``(N, 4)`` arrays of stereo measurements into the
quantities all samplers, solvers and scorers share: triangulated points at
k-1 and k, their covariances and the pixel noise. Building it is the single
place where malformed input is rejected with ``ValueError``: shapes, NaN/inf,
mismatched N, non-real values. The arrays are converted there once to
C-contiguous float64, so the compiled kernels see one layout whatever the
caller passed (a Fortran-order, strided or float32 array would otherwise be a
new compilation).

A row without a resolvable depth is not malformed: real front ends emit such
mismatches, and NaN rows. It is an *unusable row*: flagged in
:attr:`StereoProblem.usable`, its points and covariances NaN. The estimator runs
on :meth:`StereoProblem.usable_subproblem` and reports those rows as outliers.
A row is unusable where, at k-1 or at k, a coordinate is not finite, the
disparity is at or below ``camera.min_disparity``, or the disparity is at or below
``min_disparity_sigmas`` standard deviations of its noise (``sqrt(2) sigma``:
``uL`` and ``uR`` are measured apart).

Why the last rule (derived in docs/algorithms.md, "Rows without a resolvable
depth"): the triangulation covariance is a linearisation in the disparity ``d``,
and the depth ``fb / d`` is far from Gaussian once ``sigma_d / d`` is not small.
At ``d <= 2 sigma_d`` the two-sigma interval of ``d`` reaches zero, so the depth is
unbounded at 95 %, and the covariance (growing as ``z^4``) spans kilometres: under
a 3-D Mahalanobis gate such a row agrees with almost any motion that sends its
point far away, and in a minimal sample it makes the fit meaningless. Such a row
carries no depth evidence, so it is not a measurement of the motion in 3-D.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.estimation.kernels.depth import resolvable_rows
from stereovo.options import real_array


MIN_DISPARITY_SIGMAS = 2.0
"""Default disparity-to-noise ratio at or below which a row has no resolvable depth (see the module
docstring): the two-sigma interval of the disparity then reaches infinite depth."""


def as_measurements(name: str, value: np.ndarray) -> np.ndarray:
    """``value`` as a C-contiguous float64 ``(N, 4)`` array of stereo measurements.

    The input is returned itself when it already is one (no copy on the common path). NaN and inf
    are accepted: such rows become unusable rows of the problem (a front end's failed matches).

    Raises:
        ValueError: naming ``name``: not numeric, complex, or wrong shape.
    """
    array = real_array(name, value, ("N", 4), entries="(uL, vL, uR, vR) pixels",
                       per="one (uL, vL, uR, vR) row per correspondence",
                       what="a numeric (N, 4) array of (uL, vL, uR, vR) pixels")
    return np.ascontiguousarray(array)


def resolvable_depth(measurements: np.ndarray, noise_sigma: float, sigmas: float) -> np.ndarray:
    """``(N,)`` bool: the disparity ``uL - uR`` of ``measurements (N, 4)`` exceeds ``sigmas``
    standard deviations of its noise, ``sqrt(2) noise_sigma`` px (False on non-finite rows)."""
    with np.errstate(invalid="ignore"):
        return (measurements[:, 0] - measurements[:, 2]) > sigmas * np.sqrt(2.0) * noise_sigma


@dataclass(frozen=True)
class StereoProblem:
    """Putative matches between frames k-1 and k with everything derived from them.

    Attributes:
        prev, curr: ``(N, 4)`` stereo measurements (pixels) at k-1 and k, C-contiguous float64.
        camera: the rectified stereo rig (its ``v_measurement`` sets the covariance model).
        noise_sigma: pixel noise standard deviation (pixels) of every coordinate.
        points_prev, points_curr: ``(N, 3)`` triangulated points (metres), camera frames k-1 and k;
            NaN on unusable rows.
        cov_prev, cov_curr: ``(N, 3, 3)`` triangulation covariances (m^2); NaN on unusable rows.
        usable: ``(N,)`` bool, True where both frames give the match a resolvable depth; None when
            every row is usable (the common case, which then costs nothing).
        min_disparity_sigmas: the disparity-to-noise ratio at or below which a row was made unusable.
    """

    prev: np.ndarray
    curr: np.ndarray
    camera: StereoCamera
    noise_sigma: float
    points_prev: np.ndarray
    points_curr: np.ndarray
    cov_prev: np.ndarray
    cov_curr: np.ndarray
    usable: np.ndarray | None = None
    min_disparity_sigmas: float = MIN_DISPARITY_SIGMAS

    @classmethod
    def build(
        cls, prev: np.ndarray, curr: np.ndarray, camera: StereoCamera, noise_sigma: float = 0.5,
        min_disparity_sigmas: float = MIN_DISPARITY_SIGMAS,
    ) -> "StereoProblem":
        """Validate the measurements and triangulate them; rows without a resolvable depth (NaN or
        inf, no disparity, or a disparity within ``min_disparity_sigmas`` of its noise: see the
        module docstring) are flagged, not refused.

        Raises:
            ValueError: wrong shapes, mismatched N, complex or non-numeric values, a non-positive
                noise or a negative ``min_disparity_sigmas``.
        """
        if not isinstance(camera, StereoCamera):
            raise ValueError(f"camera must be a StereoCamera, got {type(camera).__name__}")
        prev = as_measurements("prev", prev)
        curr = as_measurements("curr", curr)
        if prev.shape[0] != curr.shape[0]:
            raise ValueError(f"prev and curr must have the same number of rows, got {prev.shape[0]} and {curr.shape[0]}")
        if isinstance(noise_sigma, (bool, np.bool_)) or not isinstance(noise_sigma, (int, float, np.integer, np.floating)):
            raise ValueError(f"noise_sigma must be a positive pixel noise, got {noise_sigma!r}")
        if not np.isfinite(noise_sigma) or noise_sigma <= 0:
            raise ValueError(f"noise_sigma must be a positive pixel noise, got {noise_sigma!r}")
        if (isinstance(min_disparity_sigmas, (bool, np.bool_)) or not isinstance(min_disparity_sigmas, (int, float, np.integer, np.floating))
                or not np.isfinite(min_disparity_sigmas) or min_disparity_sigmas < 0):
            raise ValueError(f"min_disparity_sigmas must be a finite number >= 0, got {min_disparity_sigmas!r}")
        points_prev, cov_prev, usable_prev = camera.triangulate_usable(prev, noise_sigma)
        points_curr, cov_curr, usable_curr = camera.triangulate_usable(curr, noise_sigma)
        # resolvable_depth's rule on both frames (its threshold, computed alike: sqrt(2) is np.sqrt's
        # correctly rounded value) and the test that every row passes, in one compiled pass
        threshold = float(min_disparity_sigmas) * math.sqrt(2.0) * float(noise_sigma)
        usable = None
        if not resolvable_rows(prev, curr, threshold, bool(min_disparity_sigmas > 0), usable_prev, usable_curr):
            usable = usable_prev & usable_curr
            # a row usable in one frame only is unusable: give it NaN in both, so nothing reads half of it
            for points, cov in ((points_prev, cov_prev), (points_curr, cov_curr)):
                points[~usable] = np.nan
                cov[~usable] = np.nan
        return cls(
            prev=prev,
            curr=curr,
            camera=camera,
            noise_sigma=float(noise_sigma),
            points_prev=points_prev,
            points_curr=points_curr,
            cov_prev=cov_prev,
            cov_curr=cov_curr,
            usable=usable,
            min_disparity_sigmas=float(min_disparity_sigmas),
        )

    @property
    def n(self) -> int:
        """Number of putative correspondences N."""
        return self.prev.shape[0]

    @property
    def usable_mask(self) -> np.ndarray:
        """``(N,)`` bool: True where the match has a depth in both frames."""
        return np.ones(self.n, dtype=bool) if self.usable is None else self.usable

    @property
    def n_unusable(self) -> int:
        """Number of rows without depth."""
        return 0 if self.usable is None else int(np.count_nonzero(~self.usable))

    def select(self, rows: np.ndarray) -> "StereoProblem":
        """The correspondences ``rows`` (int array ``(M,)``) as a problem of their own.

        No validation or triangulation is repeated: the rows are sliced from this already
        validated problem (their usable flags with them).
        """
        return dataclasses.replace(
            self,
            prev=self.prev[rows],
            curr=self.curr[rows],
            points_prev=self.points_prev[rows],
            points_curr=self.points_curr[rows],
            cov_prev=self.cov_prev[rows],
            cov_curr=self.cov_curr[rows],
            usable=None if self.usable is None else self.usable[rows],
        )

    def usable_subproblem(self) -> tuple["StereoProblem", np.ndarray | None]:
        """The usable rows as a problem of their own, and their indices ``(M,)`` into this one.

        Without unusable rows this is ``(self, None)``: no copy. The sub-problem's rows are in
        their original relative order; nothing is validated or triangulated again.
        """
        if self.usable is None:
            return self, None
        rows = np.flatnonzero(self.usable)
        return dataclasses.replace(self.select(rows), usable=None), rows
