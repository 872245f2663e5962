"""The compiled inlier count (stereovo/estimation/kernels/scores.py) against numpy's, and
InlierCount's score on batches and on other shapes."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation.kernels.scores import count_below
from stereovo.estimation.roles.scoring import InlierCount


def residuals(rng, shape):
    sq = rng.exponential(8.0, shape)
    flat = sq.reshape(-1)
    flat[rng.choice(flat.size, flat.size // 10, replace=False)] = 7.8  # exactly on the gate: not below
    flat[rng.choice(flat.size, flat.size // 20, replace=False)] = np.nan
    flat[rng.choice(flat.size, flat.size // 20, replace=False)] = np.inf
    return sq


@pytest.mark.parametrize("shape", [(1, 1), (3, 17), (24, 425), (0, 5), (4, 0)])
def test_count_below_is_numpys_count(shape):
    sq = residuals(np.random.default_rng(shape[0] * 31 + shape[1]), shape)
    got = count_below(sq, 7.8)
    expected = np.sum(sq < 7.8, axis=-1, dtype=float)
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("shape", [(9,), (2, 9), (2, 3, 9)])
def test_inlier_count_scores_every_shape_as_numpy_does(shape):
    sq = residuals(np.random.default_rng(1), shape)
    got = InlierCount().score(sq, 7.8)
    np.testing.assert_array_equal(got, np.sum(sq < 7.8, axis=-1, dtype=float))
    assert got.shape == shape[:-1]
    # a non-contiguous batch and a float32 one
    np.testing.assert_array_equal(InlierCount().score(sq[..., ::2], 7.8), np.sum(sq[..., ::2] < 7.8, axis=-1))
    np.testing.assert_array_equal(InlierCount().score(sq.astype(np.float32), 7.8),
                                  np.sum(sq.astype(np.float32) < 7.8, axis=-1))
