"""The adaptive environment's batch infos at a fixed shape, filled in one compiled pass.

:class:`vo_gym.StereoVOAdaptiveEnv` returns each step's verified hypotheses padded to the batch size
(its docstring's Info), so that Gymnasium's vector environments can stack them: ``batch_samples``
``(batch_size, 3)`` int64 with -1 rows past the batch, and ``batch_inliers`` ``(batch_size, M)``
bool, False outside the batch's ``[:H, :N]`` block. Filling and copying both took four numpy calls
and about 5 us a step; :func:`padded_batch` writes the same values in one pass.
"""

from __future__ import annotations

from numba import njit

__all__ = ["padded_batch"]


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
