"""The environments' action space: a Gymnasium ``Box`` whose ``sample()`` costs less, and what the
environments do with an action's values on each step: the clip (:func:`clipped_finite`) and the
softmax's unnormalised weights (:func:`exp_shifted`).

Gymnasium's ``Box.sample`` classifies every coordinate as bounded, half-bounded or unbounded
on each call and draws each class apart (about 25 us for 500 slots, 4 % of a one-shot step
under Gymnasium's benchmarks, more of an in-frame step). The environments' boxes are bounded
float boxes, where all of that comes down to one uniform draw: :class:`ActionBox` makes that one
draw, the same generator call on the same values, so the same seed gives the same samples
(``tests/vo_gym/test_action_box.py``). It is a ``Box`` in every other respect (equality,
batching by Gymnasium's vector environments, pickling).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from numba import njit

__all__ = ["ActionBox", "clipped_finite", "exp_shifted", "plain_float_action"]


class ActionBox(spaces.Box):
    """A ``gymnasium.spaces.Box``; for a float box bounded on both sides ``sample()`` is one draw.

    ``Box.sample`` draws such a box as ``np_random.uniform(low=low[bounded], high=high[bounded],
    size=(n,))`` with every coordinate bounded, then casts to the box's dtype; this is that draw
    with ``low`` and ``high`` themselves (the same values in the same C order) and the same cast.
    Where every coordinate has the same bounds (the environments' boxes) they are passed as two
    numbers: numpy computes each value as ``low + (high - low) * next_double`` either way, and skips
    the broadcasting of two arrays. Other boxes, and calls with a mask or probability, go to
    ``Box.sample`` itself.
    """

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._one_uniform_draw = self.dtype.kind == "f" and bool(np.all(self.bounded_below & self.bounded_above))
        low, high = self.low.astype(np.float64), self.high.astype(np.float64)  # what numpy's uniform reads
        same = self.low.size > 0 and bool(np.all(low == low.flat[0]) and np.all(high == high.flat[0]))
        self._bounds = (float(low.flat[0]), float(high.flat[0])) if same else (low, high)

    def sample(self, mask: None = None, probability: None = None) -> np.ndarray:
        if mask is not None or probability is not None or not self._one_uniform_draw:
            return super().sample(mask, probability)
        low, high = self._bounds
        return self.np_random.uniform(low=low, high=high, size=self.shape).astype(self.dtype)


_FLOAT_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))


def plain_float_action(action: object, length: int) -> bool:
    """True for a float32 or float64 ndarray of shape ``(length,)``: an action :func:`clipped_finite`
    reads as it is, without ``real_array``'s check and float64 cast (``ActionBox.sample`` gives float32)."""
    return type(action) is np.ndarray and action.dtype in _FLOAT_DTYPES and action.shape == (length,)


def clipped_finite(values: np.ndarray, bound: float, scale: float = 1.0) -> np.ndarray | None:
    """``np.minimum(np.maximum(values, -bound), bound) * scale`` of a 1-D float64 array whose values
    are all finite, in one compiled pass with numpy's values (``bound`` and ``scale`` floats); None when
    a value is NaN or infinite (the caller says what that means). np.isfinite, two clips and a product
    cost about 10 us on an action of 500 slots, the compiled pass 1. A float32 array gives the values
    of its float64 cast (each float32 is a float64 exactly), without the cast."""
    out = np.empty(values.shape[0])
    return out if _clipped_finite(values, float(bound), float(scale), out) else None


@njit(cache=True, nogil=True)
def _clipped_finite(values, bound, scale, out):
    low = -bound
    for i in range(values.shape[0]):
        x = np.float64(values[i])
        if not np.isfinite(x):
            return False
        if x < low:  # np.maximum(x, -bound); x and the bound are finite
            x = low
        if x > bound:
            x = bound
        out[i] = x * scale
    return True


def exp_shifted(values: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """``np.exp(l - l.max())`` with ``l = values * scale``, for a 1-D float64 array: the product, the
    maximum and the difference in one compiled pass, the exponential numpy's. Finite values give
    numpy's weights bit for bit (when the maximum is a zero, its sign does not reach them: ``x - 0.0``
    and ``x + 0.0`` differ only for ``x = -0.0``, and ``exp`` maps both zeros to 1); an empty array or
    one with NaN or inf takes numpy's expression itself."""
    out = np.empty(values.shape[0])
    if values.shape[0] and _shifted(values, float(scale), out):
        return np.exp(out, out=out)
    logits = values * scale
    return np.exp(logits - logits.max())


@njit(cache=True, nogil=True)
def _shifted(values, scale, out):
    """``out = values * scale - max(values * scale)``; False (``out`` unfinished) on a non-finite value."""
    top = -np.inf
    for i in range(values.shape[0]):
        x = values[i] * scale
        if not np.isfinite(x):
            return False
        out[i] = x
        if x > top:
            top = x
    for i in range(values.shape[0]):
        out[i] = out[i] - top
    return True
