"""Hypothesis settings and strategies shared by the fuzz tests."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, settings, strategies as st

from stereovo.simulation import SimulationConfig, simulate_frame


FUZZ = settings(max_examples=30, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])

WEIRD_NUMBERS = st.sampled_from([0, 1, -1, 2, 3, 0.5, -0.5, 1.5, 1e-300, 1e300, math.nan, math.inf, -math.inf,
                                 True, False, "0.9", "no", None, complex(1, 1), np.int64(7), np.float32(0.3),
                                 np.bool_(True), [1, 2], 10**30])


def fuzz_frame(seed: int, n: int, eps: float):
    return simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=eps), np.random.default_rng(seed))


MALFORMED_KINDS = ("shape", "rows", "complex")
""":func:`corrupted`'s kinds that an estimate refuses (docs/algorithms.md: only wrong shapes, non-numeric
or complex arrays, a wrong camera and bad options raise)."""

WELL_FORMED_KINDS = ("none", "nan", "inf", "huge", "zero-disparity", "negative-disparity", "fortran", "strided",
                     "float32", "int", "list", "duplicate", "constant", "empty")
"""The others: NaN, inf and depthless rows are unusable rows, not malformed input; the rest are valid layouts."""


@st.composite
def measurements(draw):
    """prev, curr, scores: a simulated frame, sometimes corrupted the ways callers get it wrong."""
    n = draw(st.integers(3, 60))
    frame = fuzz_frame(draw(st.integers(0, 2**16)), n, draw(st.sampled_from([0.0, 0.3, 0.7, 0.95])))
    prev, curr, scores = frame.prev.copy(), frame.curr.copy(), frame.scores.copy()
    kind = draw(st.sampled_from(["none", "none", "nan", "inf", "huge", "zero-disparity", "negative-disparity",
                                 "shape", "rows", "complex", "fortran", "strided", "float32", "int", "list",
                                 "duplicate", "constant", "empty"]))
    row = draw(st.integers(0, n - 1))
    column = draw(st.integers(0, 3)) if kind == "nan" else 0
    prev, curr, scores = corrupted(prev, curr, scores, kind, row, column)
    return prev, curr, scores, kind


def corrupted(prev: np.ndarray, curr: np.ndarray, scores: np.ndarray, kind: str, row: int = 0,
              column: int = 0) -> tuple:
    """``prev, curr, scores`` (copies the caller may change) made into one of :func:`measurements`'
    kinds, at ``row`` (and ``column`` for "nan"): a NaN, an inf, a huge row, a disparity of zero or
    below, a wrong shape or row count, complex values, or a valid-but-unusual layout (fortran,
    strided, float32, int, list, duplicate rows, a constant frame) or no rows at all."""
    if kind == "nan":
        prev[row, column] = np.nan
    elif kind == "inf":
        curr[row, 0] = np.inf
    elif kind == "huge":
        curr[row] = 1e300
    elif kind == "zero-disparity":
        prev[row, 2] = prev[row, 0]
    elif kind == "negative-disparity":
        curr[row, 2] = curr[row, 0] + 5.0
    elif kind == "shape":
        prev = prev[:, :3]
    elif kind == "rows":
        curr = curr[:-1]
    elif kind == "complex":
        prev = prev.astype(complex)
    elif kind == "fortran":
        prev, curr = np.asfortranarray(prev), np.asfortranarray(curr)
    elif kind == "strided":
        prev = np.repeat(prev, 2, axis=0)[::2]
    elif kind == "float32":
        prev, curr = prev.astype(np.float32), curr.astype(np.float32)
    elif kind == "int":
        prev, curr = np.round(prev).astype(int), np.round(curr).astype(int)
    elif kind == "list":
        prev, curr = prev.tolist(), curr.tolist()
    elif kind == "duplicate":
        prev[:] = prev[0]
        curr[:] = curr[0]
    elif kind == "constant":
        curr = prev.copy()
    elif kind == "empty":
        prev, curr, scores = prev[:0], curr[:0], scores[:0]
    return prev, curr, scores


ARGUMENT_NAMES = ("prev", "curr", "priors", "order", "camera", "noise_sigma", "option", "method", "scores",
                  "previous_motion", "correspondences", "rows", "disparity", "depth")


def names_an_argument(err: Exception, extra: tuple[str, ...] = ()) -> bool:
    text = str(err)
    return "\n" not in text.strip() and any(name in text for name in ARGUMENT_NAMES + extra)
