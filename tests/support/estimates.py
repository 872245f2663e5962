"""Comparing two estimates bit for bit: a compiled search against the loop's steps it replaces."""

from __future__ import annotations

import numpy as np

REPORT_FIELDS = ("score", "status", "n_hypotheses", "n_scored", "n_point_checks", "n_degenerate",
                 "n_local_optimizations", "best_found_at", "n_rejected_samples", "counters")
"""The loop report's fields two runs of the same search must agree on."""


def assert_same_estimate(a, b) -> None:
    """``a`` and ``b`` (:class:`~stereovo.estimation.MotionEstimate`) are the same estimate: pose, inliers,
    status, counts, counters and the loop's report, exactly."""
    np.testing.assert_array_equal(a.rotation, b.rotation)
    np.testing.assert_array_equal(a.translation, b.translation)
    np.testing.assert_array_equal(a.inliers, b.inliers)
    for name in ("status", "n_hypotheses", "n_scored", "n_point_checks", "score", "counters"):
        assert getattr(a, name) == getattr(b, name), name
    assert (a.report is None) == (b.report is None)
    if a.report is not None:
        for name in REPORT_FIELDS:
            assert getattr(a.report, name) == getattr(b.report, name), name
