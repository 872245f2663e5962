"""Helpers for the benchmark tests: a tiny grid, test estimators, hand-made summaries."""

from __future__ import annotations

import math
import zlib
from types import SimpleNamespace

import numpy as np

from stereovo import benchmark as bm
from stereovo.benchmark import BenchmarkGrid, BenchmarkSummary


TINY = BenchmarkGrid(epsilons=(0.2, 0.5), noise_sigmas=(0.5,), score_aucs=(0.75,), ns=(60,), frames_per_cell=2,
                     max_iterations=300)


def same_rows(a, b):
    """Row lists equal, NaN == NaN."""
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x.keys() == y.keys()
        for k in x:
            if isinstance(x[k], float) and math.isnan(x[k]):
                assert isinstance(y[k], float) and math.isnan(y[k]), k
            else:
                assert x[k] == y[k], (k, x[k], y[k])


class Fingerprint:
    """A fake estimator whose counters record what it saw: a hash of the frame and a draw of its rng."""

    def __call__(self, frame, rng):
        digest = zlib.crc32(np.ascontiguousarray(frame.prev).tobytes() + np.ascontiguousarray(frame.curr).tobytes())
        n = frame.prev.shape[0]
        return SimpleNamespace(
            rotation=frame.truth.rotation, translation=frame.truth.translation, inliers=frame.truth.inlier.copy(),
            status="ok", n_hypotheses=int(digest), n_scored=int(rng.integers(0, 2**31)), n_point_checks=n,
            time_s=0.0,
        )


class Raises:
    def __call__(self, frame, rng):
        raise RuntimeError("boom\nsecond line")


def summary_stats(**kw):
    base = {"frames": 10, "success_rate": 1.0, "median_rot_err_deg": 0.05, "median_trans_err_m": 0.01,
            "mean_hypotheses": 400.0, "median_hypotheses": 300.0, "mean_point_checks": 1e5, "median_time_ms": 50.0}
    return {**base, **kw}


def make_summary(overall, by_epsilon=None, by_n=None):
    return BenchmarkSummary(list(overall), overall, by_epsilon or {}, by_n or {})


def judge_claims(summary):
    return {c.key: c for c in bm.check_claims(summary)}
