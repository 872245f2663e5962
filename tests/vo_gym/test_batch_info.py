"""vo_gym.batch_info: the padded batch infos are numpy's fills and copies, bit for bit."""

from __future__ import annotations

import numpy as np

from vo_gym.batch_info import padded_batch


def test_padded_batch_is_numpys_fill_and_copy():
    rng = np.random.default_rng(2)
    for _ in range(300):
        b, m = int(rng.integers(1, 20)), int(rng.integers(1, 600))
        h, n = int(rng.integers(0, b + 1)), int(rng.integers(1, m + 1))
        samples = rng.integers(0, n, (h, 3)).astype(np.int64)
        masks = rng.random((h, n)) < rng.random()
        want_samples = np.full((b, 3), -1, dtype=np.int64)
        want_samples[:h] = samples
        want_inliers = np.zeros((b, m), dtype=bool)
        want_inliers[:h, :n] = masks
        ours_samples, ours_inliers = np.empty((b, 3), np.int64), np.empty((b, m), bool)
        padded_batch(samples, masks, ours_samples, ours_inliers)
        assert ours_samples.tobytes() == want_samples.tobytes()
        assert ours_inliers.tobytes() == want_inliers.tobytes()
