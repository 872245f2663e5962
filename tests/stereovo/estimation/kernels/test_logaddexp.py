"""numpy's ``logaddexp`` compiled (stereovo/estimation/kernels/logaddexp.py): bit for bit numpy's,
the short path where the exp underflows included, and MLESAC's wrapper of it."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation.kernels.logaddexp import EXP_UNDERFLOW, logaddexp_2d
from stereovo.estimation.methods.mlesac import log_add_exp

SPECIAL = [0.0, -0.0, np.inf, -np.inf, np.nan, 1e308, -1e308, 5e-324, -5e-324]


def bits(x: np.ndarray) -> np.ndarray:
    """The float64 values as integers: equal only if equal bit for bit (signed zeros and NaN too)."""
    return np.ascontiguousarray(x, dtype=np.float64).view(np.int64)


def test_logaddexp_2d_equals_numpy_bit_for_bit_everywhere_the_short_path_included():
    rng = np.random.default_rng(0)
    values = np.concatenate([rng.normal(0.0, 2000.0, 3000), rng.normal(0.0, 4.0, 3000), SPECIAL])
    a = rng.permutation(np.concatenate([values, values])).reshape(-1, 6)
    b = rng.permutation(np.concatenate([values, values[::-1]])).reshape(-1, 6)
    with np.errstate(invalid="ignore"):
        expected = np.logaddexp(a, b)
        far = np.abs(a - b) > EXP_UNDERFLOW
    assert far.mean() > 0.3 and (~far).mean() > 0.3  # both paths are taken
    np.testing.assert_array_equal(bits(logaddexp_2d(a, b)), bits(expected))


def test_the_short_path_starts_where_numpys_exp_has_underflowed():
    # differences on a fine grid across the underflow threshold, on both sides of zero
    d = np.linspace(-EXP_UNDERFLOW - 20.0, EXP_UNDERFLOW + 20.0, 400001)[None, :]
    for base in (-3.0, 0.0, 1234.5):
        a = np.full_like(d, base)
        np.testing.assert_array_equal(bits(logaddexp_2d(a, a - d)), bits(np.logaddexp(a, a - d)))
    assert np.exp(-EXP_UNDERFLOW) == 0.0


def test_logaddexp_2d_reads_arrays_of_any_strides():
    rng = np.random.default_rng(1)
    a = rng.normal(0.0, 900.0, (40, 60))
    b = np.asfortranarray(rng.normal(0.0, 900.0, (60, 40))).T
    np.testing.assert_array_equal(bits(logaddexp_2d(a[:, ::2], b[:, ::2])), bits(np.logaddexp(a[:, ::2], b[:, ::2])))


@pytest.mark.parametrize("b_shape", [(7, 30), (7, 1), (30,), ()])
def test_mlesac_wrapper_broadcasts_like_numpy(b_shape):
    rng = np.random.default_rng(2)
    a = rng.normal(-500.0, 800.0, (7, 30))
    b = rng.normal(-500.0, 800.0, b_shape)
    got = log_add_exp(a, b)
    assert got.shape == (7, 30)
    np.testing.assert_array_equal(bits(got), bits(np.logaddexp(a, b)))
    np.testing.assert_array_equal(bits(log_add_exp(a[0], b)), bits(np.logaddexp(a[0], b)))  # 1-D: numpy's own
