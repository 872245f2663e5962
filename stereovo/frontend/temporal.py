"""Temporal matching of the left images k-1 -> k, the :class:`Matches` it makes, and the
streaming :class:`StereoFrontend` that reuses frame k's features as the next pair's k-1.

A stereo-matched keypoint at k-1 is matched to one at k by descriptor distance within a square
search window (``search_radius`` px), accepted by a mutual nearest-neighbour check, Lowe's ratio
test, or both (``temporal_check``); its position at k is then refined to subpixel precision
against the k-1 patch (``subpixel``). Each surviving match is one row ``prev[i] <-> curr[i]`` in
the layout :func:`stereovo.estimation.estimate_motion` takes, with a score
(:mod:`stereovo.frontend.scores`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.frontend import kernels
from stereovo.frontend.options import FrontendOptions
from stereovo.frontend.scores import comparison_confidence, match_scores
from stereovo.frontend.stereo import StereoFeatures, second_ratio, stereo_features, window_matches
from stereovo.frontend.detection import Keypoints


@dataclass(frozen=True, eq=False)
class Matches:
    """Putative stereo matches of a frame pair ``(k-1, k)``.

    Attributes:
        prev: ``(N, 4)`` float64 ``(uL, vL, uR, vR)`` (px) at k-1.
        curr: ``(N, 4)`` at k; row i of ``prev`` and ``curr`` is one putative match.
        scores: ``(N,)`` in (0, 1), higher = more likely an inlier (:mod:`stereovo.frontend.scores`).
        prev_index: ``(N,)`` rows of the k-1 :class:`StereoFeatures` the matches came from.
        curr_index: ``(N,)`` rows of the k :class:`StereoFeatures`.
        temporal_distance: ``(N,)`` the left descriptors' distance (fraction of the largest).
        temporal_ratio: ``(N,)`` its Lowe ratio to the second-best candidate.
        n_stereo: ``(stereo matches at k-1, at k)``.
        reason: why there are no matches (``""`` when there are).
    """

    prev: np.ndarray
    curr: np.ndarray
    scores: np.ndarray
    prev_index: np.ndarray
    curr_index: np.ndarray
    temporal_distance: np.ndarray
    temporal_ratio: np.ndarray
    n_stereo: tuple[int, int]
    reason: str = ""

    def __len__(self) -> int:
        return int(self.prev.shape[0])

    @property
    def n(self) -> int:
        """Number of putative matches N."""
        return len(self)


def _empty(n_stereo: tuple[int, int], reason: str) -> Matches:
    z = np.zeros(0)
    return Matches(np.zeros((0, 4)), np.zeros((0, 4)), z, z.astype(np.int64), z.astype(np.int64), z, z, n_stereo,
                   reason)


def temporal_matches(prev: StereoFeatures, curr: StereoFeatures, options: FrontendOptions) -> Matches:
    """Match the stereo features of k-1 to those of k (see the module docstring)."""
    n_stereo = (len(prev), len(curr))
    if len(prev) == 0 or len(curr) == 0:
        which, feats = ("k-1", prev) if len(prev) == 0 else ("k", curr)
        return _empty(n_stereo, f"no stereo matches at {which}: {feats.reason or 'none found'}")
    if prev.binary != curr.binary or prev.descriptors.shape[1] != curr.descriptors.shape[1]:
        raise ValueError("the two frames' features come from different detectors: match them with one front end")
    r = np.inf if options.search_radius is None else options.search_radius
    pa, pb = prev.points[:, :2], curr.points[:, :2]
    if prev.image.shape[1] > prev.image.shape[0]:
        # The window is square, so either axis can be the one scanned in sorted order: the longer
        # one (columns, in a wide image) leaves the fewer candidates to test.
        pa, pb = pa[:, ::-1], pb[:, ::-1]
    ka = Keypoints(np.ascontiguousarray(pa), prev.descriptors, prev.binary, prev.max_distance)
    kb = Keypoints(np.ascontiguousarray(pb), curr.descriptors, curr.binary, curr.max_distance)
    best, d1, d2, back = window_matches(ka, kb, r, -r, r)
    ratio = second_ratio(d1, d2)
    keep = (best >= 0) & (d1 <= options.max_distance)
    if options.temporal_check in ("ratio", "both"):
        keep &= ratio < options.temporal_ratio
    if options.temporal_check in ("mutual", "both"):
        keep &= back[np.maximum(best, 0)] == np.arange(len(prev))
    rows = np.flatnonzero(keep)
    cols = best[rows]
    if options.temporal_check == "ratio":  # without the mutual check two k-1 features may claim one k feature
        order = np.lexsort((d1[rows], cols))
        first = np.ones(order.size, dtype=bool)
        first[1:] = cols[order][1:] != cols[order][:-1]
        rows = np.sort(rows[order[first]])
        cols = best[rows]
    p = prev.points[rows]
    c = curr.points[cols].copy()
    if options.subpixel and rows.size:
        refined = kernels.refine_shift(prev.image, curr.image, p[:, 0], p[:, 1], c[:, 0], c[:, 1],
                                       options.patch_radius, 2)
        ok = np.isfinite(refined[:, 0])
        disparity = c[ok, 0] - c[ok, 2]
        c[ok, 0], c[ok, 1] = refined[ok, 0], refined[ok, 1]
        c[ok, 2], c[ok, 3] = refined[ok, 0] - disparity, refined[ok, 1]
        rows, cols, p, c = rows[ok], cols[ok], p[ok], c[ok]
    if rows.size == 0:
        return _empty(n_stereo, f"no temporal match passed the {options.temporal_check} check "
                                f"({n_stereo[0]} stereo matches at k-1, {n_stereo[1]} at k)")
    scores = match_scores([
        comparison_confidence(prev.distance[rows], prev.ratio[rows], options.max_distance),
        comparison_confidence(curr.distance[cols], curr.ratio[cols], options.max_distance),
        comparison_confidence(d1[rows], ratio[rows], options.max_distance),
    ])
    return Matches(p, c, scores, rows.astype(np.int64), cols.astype(np.int64), d1[rows], ratio[rows], n_stereo)


class StereoFrontend:
    """The front end for a stream of rectified stereo pairs: each pair is detected and matched
    along the rows once, and matched in time against the pair before it.

    Example::

        frontend = StereoFrontend(camera)
        for left, right in pairs:
            matches = frontend.push(left, right)   # empty (with a reason) on the first pair
            if len(matches) >= 3:
                estimate = estimate_motion(matches.prev, matches.curr, camera, priors=matches.scores)

    Args:
        camera: the rectified rig; images must have its size.
        **options: :class:`FrontendOptions` fields (or ``options=`` one).
    """

    def __init__(self, camera: StereoCamera, **options: Any) -> None:
        if not isinstance(camera, StereoCamera):
            raise ValueError(f"camera must be a StereoCamera, got {type(camera).__name__}")
        self.camera = camera
        self.options = FrontendOptions.from_keywords(options, owner="StereoFrontend")
        self.options.disparity_range(camera)  # an empty range is refused now, not at the first image
        self._last: StereoFeatures | None = None

    def features(self, left: Any, right: Any, names: tuple[str, str] = ("left", "right")) -> StereoFeatures:
        """The stereo features of one pair (no state is kept)."""
        return stereo_features(left, right, self.camera, self.options, names)

    def match(self, prev: StereoFeatures, curr: StereoFeatures) -> Matches:
        """The temporal matches of two pairs' stereo features."""
        return temporal_matches(prev, curr, self.options)

    def push(self, left: Any, right: Any) -> Matches:
        """Matches of the previous pushed pair to this one (empty, with a reason, for the first)."""
        curr = self.features(left, right)
        prev, self._last = self._last, curr
        if prev is None:
            return _empty((0, len(curr)), "first pair of the stream: nothing to match in time yet")
        return self.match(prev, curr)

    def reset(self) -> None:
        """Forget the last pair: the next :meth:`push` starts a new stream."""
        self._last = None


def match_stereo_frames(left_prev: Any, right_prev: Any, left_curr: Any, right_curr: Any, camera: StereoCamera,
                        **options: Any) -> Matches:
    """Putative stereo matches of two rectified grey pairs ``(k-1, k)``.

    Detects keypoints in the four images (ORB by default), matches each pair along the rows
    (row band and disparity range from ``camera``, ratio test, subpixel disparity) and the left
    images in time (``temporal_check``), and scores each match
    (:mod:`stereovo.frontend.scores`). For a stream of pairs :class:`StereoFrontend` detects each
    image once instead of twice.

    Args:
        left_prev, right_prev, left_curr, right_curr: ``(H, W)`` uint8 grey images of the camera's size.
        camera: the rectified rig.
        **options: :class:`FrontendOptions` fields (or ``options=`` one).

    Returns:
        :class:`Matches` (``prev``, ``curr`` ``(N, 4)``, ``scores`` ``(N,)``); empty with a ``reason``
        when an image is blank or nothing matches.

    Raises:
        ValueError: a bad image or option, naming it; TypeError: an unknown keyword.
    """
    frontend = StereoFrontend(camera, **options)
    prev = frontend.features(left_prev, right_prev, ("left_prev", "right_prev"))
    curr = frontend.features(left_curr, right_curr, ("left_curr", "right_curr"))
    if prev.image.shape != curr.image.shape:  # pragma: no cover - both checked against the camera
        raise ValueError(f"left_prev is {prev.image.shape} but left_curr is {curr.image.shape}")
    return frontend.match(prev, curr)
