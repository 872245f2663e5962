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
    np.testing.assert_array_equal(bits(log_add_exp(b, a)), bits(np.logaddexp(b, a)))  # the full shape second
    np.testing.assert_array_equal(bits(log_add_exp(a[0], b)), bits(np.logaddexp(a[0], b)))  # 1-D: numpy's own


def test_mlesac_wrapper_computes_in_float64_and_leaves_other_ranks_to_numpy():
    rng = np.random.default_rng(3)
    a, b = rng.normal(-20.0, 30.0, (5, 40)), rng.normal(-20.0, 30.0, (5, 40))
    a32, b32 = a.astype(np.float32), b.astype(np.float32)
    expected = np.logaddexp(a32.astype(np.float64), b32.astype(np.float64))
    for x, y in ((a32, b32), (a32, b32.astype(np.float64)), (a32.astype(np.float64), b32)):
        got = log_add_exp(x, y)
        assert got.dtype == np.float64
        np.testing.assert_array_equal(bits(got), bits(expected))
    cube = rng.normal(-20.0, 30.0, (2, 3, 4))
    np.testing.assert_array_equal(bits(log_add_exp(cube, cube[::-1])), bits(np.logaddexp(cube, cube[::-1])))


def numpy_mixture_log_likelihood(gamma, log_p_in, log_p_out):
    """MLESAC's likelihood as numpy computed it before the kernel."""
    g = np.clip(gamma, 1e-6, 1 - 1e-6)[:, None]
    return np.sum(np.logaddexp(np.log(g) + log_p_in, np.log1p(-g) + log_p_out), axis=-1)


def numpy_em(log_p_in, log_p_out, iterations=5, tolerance=1e-4):
    """MLESAC's EM as numpy computed it before the kernel: ``(gamma, L)``."""
    gamma = np.full(log_p_in.shape[0], 0.5)
    for _ in range(iterations):
        g = np.clip(gamma, 1e-6, 1 - 1e-6)[:, None]
        a = np.log(g) + log_p_in
        b = np.log1p(-g) + log_p_out
        new = np.mean(np.exp(a - np.logaddexp(a, b)), axis=1)
        change = np.max(np.abs(new - gamma))
        gamma = new
        if change < tolerance:
            break
    return gamma, numpy_mixture_log_likelihood(gamma, log_p_in, log_p_out)


@pytest.mark.parametrize("scalar_out", [False, True])
def test_mlesac_likelihood_and_em_equal_their_numpy_formulas_bit_for_bit(scalar_out):
    from stereovo.estimation.methods.mlesac import mixture_log_likelihood, mlesac_em

    rng = np.random.default_rng(4)
    # squared distances as scoring gives them: inliers near 0, outliers up to 1e9, some inf
    sq = np.where(rng.random((40, 300)) < 0.3, rng.chisquare(3, (40, 300)), 10.0 ** rng.uniform(0, 9, (40, 300)))
    sq[rng.random(sq.shape) < 0.01] = np.inf
    log_p_in = rng.normal(2.0, 3.0, 300) - 0.5 * sq
    log_p_out = -4.0 if scalar_out else rng.normal(-4.0, 2.0, 300)
    gamma = rng.uniform(0.0, 1.0, 40)
    gamma[:3] = (0.0, 1.0, 0.5)
    np.testing.assert_array_equal(bits(mixture_log_likelihood(gamma, log_p_in, log_p_out)),
                                  bits(numpy_mixture_log_likelihood(gamma, log_p_in, log_p_out)))
    for got, expected in zip(mlesac_em(log_p_in, log_p_out), numpy_em(log_p_in, log_p_out)):
        np.testing.assert_array_equal(bits(got), bits(expected))
