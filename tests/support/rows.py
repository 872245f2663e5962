"""Helpers for the unusable-rows tests: a frame and its spoiled rows."""

from __future__ import annotations


def spoil_rows(frame, rows, where="prev"):
    """Copies of the frame's measurements with ``rows`` given no depth (zero disparity) in ``where``."""
    prev, curr = frame.prev.copy(), frame.curr.copy()
    target = prev if where == "prev" else curr
    target[rows, 2] = target[rows, 0]  # uR = uL: disparity 0
    return prev, curr
