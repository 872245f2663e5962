"""Stereo matching of one rectified pair along the rows: keypoints of the left image matched to
those of the right within a row band and a disparity range, by descriptor distance with Lowe's
ratio test (Lowe, IJCV 2004), one left keypoint per right keypoint, and subpixel disparities.

The search window comes from the camera: rows within ``row_tolerance`` px of the left keypoint's
(rectified images put a point on one row in both), disparities between the camera's
``min_disparity`` and ``fx * baseline / min_depth`` (:meth:`FrontendOptions.disparity_range`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.frontend import kernels
from stereovo.frontend.detection import Keypoints, detect
from stereovo.frontend.images import blank_reason, grey_image, same_size
from stereovo.frontend.options import FrontendOptions


@dataclass(frozen=True, eq=False)
class StereoFeatures:
    """The stereo-matched keypoints of one rectified pair.

    Attributes:
        points: ``(M, 4)`` float64 measurements ``(uL, vL, uR, vR)`` (px), ``vR = vL`` (rectified).
        descriptors: ``(M, W)`` the left keypoints' descriptors (for the temporal match).
        distance: ``(M,)`` the stereo descriptor distance as a fraction of the largest possible.
        ratio: ``(M,)`` the distance over the second best candidate's in the band (0 when alone).
        image: the left image ``(H, W)`` uint8 (the temporal refinement reads its patches).
        n_left, n_right: keypoints detected in each image.
        binary: descriptors are bit strings (Hamming) rather than vectors (L2).
        max_distance: the descriptors' largest possible distance.
        reason: why there are no matches (``""`` when there are).
    """

    points: np.ndarray
    descriptors: np.ndarray
    distance: np.ndarray
    ratio: np.ndarray
    image: np.ndarray
    n_left: int
    n_right: int
    binary: bool
    max_distance: float
    reason: str = ""

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @property
    def disparity(self) -> np.ndarray:
        """``(M,)`` disparities ``uL - uR`` (px)."""
        return self.points[:, 0] - self.points[:, 2]


def second_ratio(d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """Lowe's ratio ``d1 / d2`` of the nearest two distances; 0 where there is no second candidate
    (nothing to confuse the match with), 1 where both are zero."""
    ratio = np.zeros(d1.shape)
    both = np.isfinite(d2)
    np.divide(d1, d2, out=ratio, where=both & (d2 > 0))
    ratio[both & (d2 <= 0)] = 1.0
    return ratio


def window_matches(a: Keypoints, b: Keypoints, v_tol: float, du_lo: float, du_hi: float):
    """For each keypoint of ``a``, its nearest keypoint of ``b`` within the window, the distances of
    the nearest two (fractions of the largest; inf where missing), and for each of ``b`` its nearest
    of ``a``: ``(best, d1, d2, back)``."""
    order = np.argsort(b.xy[:, 1], kind="stable")
    vb = np.ascontiguousarray(b.xy[order, 1])
    if a.binary:  # one compiled pass
        best, d1, d2, back = kernels.window_best_two_hamming(
            a.xy, b.xy, order, vb, a.descriptors, b.descriptors, v_tol, du_lo, du_hi)
    else:
        ia, jb = kernels.window_pairs(a.xy, b.xy, order, vb, v_tol, du_lo, du_hi)
        dist = kernels.l2_pairs(a.descriptors, b.descriptors, ia, jb)
        best, d1, d2 = kernels.best_two(ia, jb, dist, len(a))
        back, _, _ = kernels.best_two(jb, ia, dist, len(b))
    return best, d1 / a.max_distance, d2 / a.max_distance, back


def _empty(image: np.ndarray, n_left: int, n_right: int, binary: bool, max_distance: float, width: int,
           dtype: Any, reason: str) -> StereoFeatures:
    return StereoFeatures(
        np.zeros((0, 4)), np.zeros((0, width), dtype=dtype), np.zeros(0), np.zeros(0), image, n_left, n_right,
        binary, max_distance, reason,
    )


def match_pair(left: np.ndarray, right: np.ndarray, kl: Keypoints, kr: Keypoints, camera: StereoCamera,
               options: FrontendOptions) -> StereoFeatures:
    """Stereo matches of checked images and their keypoints (see the module docstring)."""
    width, dtype = kl.descriptors.shape[1], kl.descriptors.dtype
    if len(kl) == 0 or len(kr) == 0:
        which = "left" if len(kl) == 0 else "right"
        return _empty(left, len(kl), len(kr), kl.binary, kl.max_distance, width, dtype,
                      f"no keypoints in the {which} image")
    d_lo, d_hi = options.disparity_range(camera)
    best, d1, d2, _ = window_matches(kl, kr, options.row_tolerance, d_lo, d_hi)
    ratio = second_ratio(d1, d2)
    keep = (best >= 0) & (d1 <= options.max_distance) & (ratio < options.stereo_ratio)
    rows = np.flatnonzero(keep)
    cols = best[rows]
    # One left keypoint per right keypoint: where several claim one, the nearest in descriptor wins.
    order = np.lexsort((d1[rows], cols))
    first = np.ones(order.size, dtype=bool)
    first[1:] = cols[order][1:] != cols[order][:-1]
    rows = np.sort(rows[order[first]])
    cols = best[rows]
    uL, vL = kl.xy[rows, 0], kl.xy[rows, 1]
    disparity = uL - kr.xy[cols, 0]
    if options.subpixel and rows.size:
        disparity = kernels.refine_disparity(left, right, uL, vL, disparity, options.patch_radius, 3)
    ok = np.isfinite(disparity) & (disparity > d_lo) & (disparity <= d_hi)
    rows, uL, vL, disparity = rows[ok], uL[ok], vL[ok], disparity[ok]
    if rows.size == 0:
        return _empty(left, len(kl), len(kr), kl.binary, kl.max_distance, width, dtype,
                      f"no stereo match passed the row band, disparity range [{d_lo:g}, {d_hi:g}] px and ratio test "
                      f"({len(kl)} left, {len(kr)} right keypoints)")
    points = np.column_stack([uL, vL, uL - disparity, vL])
    return StereoFeatures(
        points, np.ascontiguousarray(kl.descriptors[rows]), d1[rows], ratio[rows], left, len(kl), len(kr),
        kl.binary, kl.max_distance,
    )


def stereo_features(left: Any, right: Any, camera: StereoCamera, options: FrontendOptions,
                    names: tuple[str, str] = ("left", "right")) -> StereoFeatures:
    """Check one rectified pair, detect its keypoints and match them along the rows."""
    if not isinstance(camera, StereoCamera):
        raise ValueError(f"camera must be a StereoCamera, got {type(camera).__name__}")
    images = {names[0]: grey_image(left, names[0]), names[1]: grey_image(right, names[1])}
    same_size(images, camera)
    left, right = images[names[0]], images[names[1]]
    reason = blank_reason(left, names[0]) or blank_reason(right, names[1])
    if reason:
        binary = options.detector != "sift"
        width = 4 if options.detector == "orb" else 8 if binary else 128
        return _empty(left, 0, 0, binary, 256.0 if binary else 2.0, width, np.uint64 if binary else np.float32, reason)
    return match_pair(left, right, detect(left, options), detect(right, options), camera, options)


def stereo_matches(left: Any, right: Any, camera: StereoCamera, **options: Any) -> StereoFeatures:
    """Stereo matches of one rectified grey pair.

    Args:
        left, right: ``(H, W)`` uint8 grey images of the camera's size.
        camera: the rectified rig (its ``fx``, ``baseline`` and ``min_disparity`` set the
            disparity range).
        **options: :class:`~stereovo.frontend.options.FrontendOptions` fields (or ``options=`` one).

    Returns:
        :class:`StereoFeatures`; empty with a ``reason`` when an image is blank or nothing matches.

    Raises:
        ValueError: a bad image (type, dtype, shape, colour, size) or option, named.
        TypeError: an unknown keyword.
    """
    opts = FrontendOptions.from_keywords(options, owner="stereo_matches")
    return stereo_features(left, right, camera, opts)
