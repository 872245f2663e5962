"""vo_gym.ordering.descending_order: numpy's stable argsort of the negated values, the same permutation."""

from __future__ import annotations

import numpy as np
import pytest

from vo_gym.ordering import descending_order

SPECIAL = np.array([0.0, -0.0, 1.0, -1.0, 5e-324, -5e-324, 2.2250738585072014e-308, -2.2250738585072014e-308,
                    1e308, -1e308, np.finfo(np.float64).max, -np.finfo(np.float64).max, 0.5, 2.0, 1.0 + 2**-52])


def _values(rng: np.random.Generator, kind: int, n: int, dtype) -> np.ndarray:
    if kind == 0:
        x = rng.random(n)  # match scores
    elif kind == 1:
        x = rng.standard_normal(n) * 10.0 ** rng.integers(-30, 30, n)  # every exponent, both signs
    elif kind == 2:
        x = rng.choice(SPECIAL, n)  # signed zeros, subnormals, the extremes, many ties
    elif kind == 3:
        x = np.round(rng.standard_normal(n), 1)  # ties among ordinary values
    else:
        x = rng.integers(-3, 3, n).astype(float)  # few distinct values
    with np.errstate(over="ignore"):
        return x.astype(dtype)  # float32: the largest values become inf (numpy's path)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_it_is_numpys_stable_argsort_of_the_negated_values(dtype):
    rng = np.random.default_rng(20261205)
    for trial in range(1500):
        n = int(rng.integers(0, 700)) if trial % 3 else int(rng.integers(0, 4))
        x = _values(rng, trial % 5, n, dtype)
        got, want = descending_order(x), np.argsort(-x, kind="stable")
        assert got.dtype == want.dtype == np.int64
        np.testing.assert_array_equal(got, want)


def test_signed_zeros_are_ties_in_row_order():
    x = np.array([-0.0, 0.0, -0.0, 1.0, 0.0])
    np.testing.assert_array_equal(descending_order(x), [3, 0, 1, 2, 4])
    np.testing.assert_array_equal(descending_order(x.astype(np.float32)), [3, 0, 1, 2, 4])


@pytest.mark.parametrize("x", [
    np.array([1.0, np.nan, 2.0, np.nan, -1.0]),
    np.array([np.inf, 1.0, -np.inf, 0.0]),
    np.array([3, 1, 2, 1]),  # integers
    np.array([[1.0, 2.0], [0.0, 5.0]])[:, 1],  # strided
    [0.3, 0.1, 0.2],  # a list
])
def test_other_input_is_numpys(x):
    np.testing.assert_array_equal(descending_order(x), np.argsort(-np.asarray(x), kind="stable"))


def test_the_input_is_left_alone():
    x = np.array([0.5, -0.0, 0.25])
    descending_order(x)
    np.testing.assert_array_equal(x, [0.5, -0.0, 0.25])
    assert np.signbit(x[1])


def test_finite_order_is_the_order_or_none():
    from vo_gym.ordering import finite_descending_order

    rng = np.random.default_rng(4)
    for dtype in (np.float64, np.float32):
        x = rng.random(300).astype(dtype)
        np.testing.assert_array_equal(finite_descending_order(x), np.argsort(-x, kind="stable"))
        for bad in (np.nan, np.inf, -np.inf):
            y = x.copy()
            y[17] = bad
            assert finite_descending_order(y) is None
    assert finite_descending_order(np.array([np.nan])) is None
    np.testing.assert_array_equal(finite_descending_order([2, 5, 5]), [1, 2, 0])
    assert finite_descending_order(np.zeros(0)).shape == (0,)
