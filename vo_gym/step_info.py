"""The adaptive environment's step infos that numpy built in several calls, each in one compiled pass.

:class:`vo_gym.StereoVOAdaptiveEnv` returns each step's verified hypotheses padded to the batch size
(its docstring's Info), so that Gymnasium's vector environments can stack them: ``batch_samples``
``(batch_size, 3)`` int64 with -1 rows past the batch, and ``batch_inliers`` ``(batch_size, M)``
bool, False outside the batch's ``[:H, :N]`` block. Filling and copying both took four numpy calls
and about 5 us a step; :func:`padded_batch` writes the same values in one pass. A frame's last step
also says whether a scored sample was all static inliers (:func:`any_all_inlier`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["padded_batch", "any_all_inlier"]


@njit(cache=True, nogil=True)
def padded_batch(samples, masks, batch_samples, batch_inliers):
    """Into ``batch_samples (B, 3)`` int64 and ``batch_inliers (B, M)`` bool (uninitialised): the
    ``(H, 3)`` ``samples`` and the ``(H, N)`` ``masks`` (``H <= B``, ``N <= M``) in their first rows
    and columns, -1 and False elsewhere (``np.full`` / ``np.zeros`` and the two slice copies)."""
    h, n = masks.shape
    for r in range(batch_samples.shape[0]):
        for c in range(3):
            batch_samples[r, c] = samples[r, c] if r < h else -1
        for c in range(batch_inliers.shape[1]):
            batch_inliers[r, c] = masks[r, c] if r < h and c < n else False


def any_all_inlier(samples: np.ndarray, inlier: np.ndarray) -> bool:
    """``bool(samples.shape[0] and np.any(np.all(inlier[samples], axis=1)))``: whether a minimal sample
    ``(H, 3)`` (row indices) is all inliers under the labels ``inlier (N,)`` bool. One compiled pass for
    int64 samples inside ``[0, N)``; numpy's expression (and its wrap-around or error) otherwise."""
    if samples.dtype == np.int64 and samples.ndim == 2 and inlier.dtype == np.bool_ and inlier.ndim == 1:
        found = _any_all_inlier(samples, inlier)
        if found >= 0:
            return bool(found)
    return bool(samples.shape[0] and np.any(np.all(inlier[samples], axis=1)))


@njit(cache=True, nogil=True)
def _any_all_inlier(samples, inlier):
    """1 if a row of ``samples`` indexes only True entries of ``inlier``, else 0; -1 on an index
    outside ``[0, N)`` (the caller's numpy then decides)."""
    n = inlier.shape[0]
    for r in range(samples.shape[0]):
        for c in range(samples.shape[1]):
            if not 0 <= samples[r, c] < n:
                return -1
    for r in range(samples.shape[0]):
        every = True
        for c in range(samples.shape[1]):
            every = every and inlier[samples[r, c]]
        if every:
            return 1
    return 0
