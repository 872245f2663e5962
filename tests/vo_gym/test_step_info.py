"""vo_gym.step_info: the padded batch infos are numpy's fills and copies, bit for bit, and the all-inlier
test is numpy's expression."""

from __future__ import annotations

import numpy as np
import pytest

from vo_gym.step_info import any_all_inlier, padded_batch


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


def test_any_all_inlier_is_numpys_expression():
    rng = np.random.default_rng(3)
    for _ in range(500):
        n, h = int(rng.integers(3, 200)), int(rng.integers(0, 40))
        inlier = rng.random(n) < rng.random()
        samples = rng.integers(0, n, (h, 3)).astype(np.int64)
        want = bool(samples.shape[0] and np.any(np.all(inlier[samples], axis=1)))
        assert any_all_inlier(samples, inlier) is want
    inlier = np.array([True, True, False, True])
    assert any_all_inlier(np.array([[-1, 0, 1]]), inlier) is True  # numpy's wrap-around: row 3
    assert any_all_inlier(np.array([[0, 1, 3]], dtype=np.int32), inlier) is True
    with pytest.raises(IndexError):
        any_all_inlier(np.array([[0, 1, 4]]), inlier)
