"""The stable descending order of a frame's values: ``np.argsort(-values, kind="stable")``, sorted by radix.

The features order the match scores (the rank column and the consistency anchors) and the PROSAC
environment orders the agent's scores, 500 values each step. numpy's stable sort of fresh values
is a merge sort whose comparisons the branch predictor cannot learn: about 22 us for 500 values,
against 7 us when the same array is sorted again and again (which is why a warm micro-benchmark
hid it). A least-significant-digit radix sort of the values' bit patterns has no data-dependent
branch and is stable, so equal values keep their row order as numpy's stable sort keeps them:
the same permutation, in about a fifth of the time. ``tests/vo_gym/test_ordering.py`` compares
the two on random, tied, signed-zero, subnormal and extreme values.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["descending_order", "finite_descending_order"]

_SIGN64 = np.uint64(1 << 63)
_SIGN32 = np.uint32(1 << 31)
_EXPONENT64 = np.uint64(0x7FF << 52)
_EXPONENT32 = np.uint32(0xFF << 23)


def descending_order(values: np.ndarray) -> np.ndarray:
    """``np.argsort(-values, kind="stable")`` (int64) of a 1-D float64 or float32 array.

    Finite values go through the radix sort; an array with NaN or inf, of another dtype or
    shape, goes to numpy (whose ordering of NaN the radix keys do not reproduce).
    """
    order = _radix_descending_order(values)
    return np.argsort(-np.asarray(values), kind="stable") if order is None else order


def finite_descending_order(values: np.ndarray) -> np.ndarray | None:
    """:func:`descending_order` of 1-D values that are all finite; None when one is NaN or infinite
    (the check of finite values and the sort in one pass, for callers that refuse them)."""
    order = _radix_descending_order(values)
    if order is not None:
        return order
    a = np.asarray(values)
    return np.argsort(-a, kind="stable") if np.isfinite(a).all() else None


def _radix_descending_order(values) -> np.ndarray | None:
    """The radix order of a 1-D float64 or float32 ndarray of finite values; None otherwise."""
    a = values
    if type(a) is np.ndarray and a.ndim == 1 and (a.dtype == np.float64 or a.dtype == np.float32):
        a = np.ascontiguousarray(a)
        order = _descending_order64(a) if a.dtype == np.float64 else _descending_order32(a)
        if order.shape[0] == a.shape[0]:
            return order
    return None


# The keys: for -v, the bit pattern with its sign bit set when -v >= 0 and every bit flipped when
# -v < 0 (so unsigned order is the order of the values); -0.0 reads as +0.0, since the two compare
# equal and a stable sort keeps such ties in row order. -v's bits are v's with the sign flipped.

@njit(cache=True, nogil=True)
def _descending_keys64(values, keys):
    """Into ``keys (N,)`` uint64: keys whose ascending order is the ascending order of ``-values``
    (float64, C-contiguous). False, with ``keys`` unfinished, when a value is NaN or infinite."""
    bits = values.view(np.uint64)
    for i in range(values.shape[0]):
        b = bits[i]
        if (b & _EXPONENT64) == _EXPONENT64:
            return False
        b = np.uint64(0) if (b << np.uint64(1)) == np.uint64(0) else b ^ _SIGN64  # +-0.0 -> +0.0, else -v
        keys[i] = ~b if b & _SIGN64 else b | _SIGN64
    return True


@njit(cache=True, nogil=True)
def _descending_keys32(values, keys):
    """:func:`_descending_keys64` of float32 values (32-bit keys, in the low half)."""
    bits = values.view(np.uint32)
    for i in range(values.shape[0]):
        b = bits[i]
        if (b & _EXPONENT32) == _EXPONENT32:
            return False
        b = np.uint32(0) if (b << np.uint32(1)) == np.uint32(0) else b ^ _SIGN32
        keys[i] = np.uint64(~b if b & _SIGN32 else b | _SIGN32)
    return True


@njit(cache=True, nogil=True)
def _descending_order64(values):
    """The radix order of float64 ``values``; empty when one is NaN or infinite."""
    keys = np.empty(values.shape[0], dtype=np.uint64)
    if not _descending_keys64(values, keys):
        return np.empty(0, dtype=np.int64)
    return _radix_order(keys, 8)


@njit(cache=True, nogil=True)
def _descending_order32(values):
    """The radix order of float32 ``values``; empty when one is NaN or infinite."""
    keys = np.empty(values.shape[0], dtype=np.uint64)
    if not _descending_keys32(values, keys):
        return np.empty(0, dtype=np.int64)
    return _radix_order(keys, 4)


@njit(cache=True, nogil=True)
def _radix_order(keys, n_bytes):
    """The stable ascending order (int64) of ``keys (N,)`` uint64 whose top ``8 - n_bytes`` bytes are
    zero: one byte a pass from the lowest, each pass stable; a byte
    that every key shares is skipped (it moves nothing)."""
    n = keys.shape[0]
    counts = np.zeros((n_bytes, 256), dtype=np.int64)
    for i in range(n):
        k = keys[i]
        for b in range(n_bytes):
            counts[b, (k >> np.uint64(8 * b)) & np.uint64(255)] += 1
    order = np.arange(n)
    spare = np.empty(n, dtype=np.int64)
    for b in range(n_bytes):
        shift = np.uint64(8 * b)
        c = counts[b]
        if n == 0 or c[(keys[0] >> shift) & np.uint64(255)] == n:
            continue
        total = 0
        for d in range(256):
            here = c[d]
            c[d] = total
            total += here
        for i in range(n):
            row = order[i]
            d = (keys[row] >> shift) & np.uint64(255)
            spare[c[d]] = row
            c[d] += 1
        order, spare = spare, order
    return order
