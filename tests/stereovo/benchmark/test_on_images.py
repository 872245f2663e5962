"""stereovo.benchmark.on_images: the classical family on a sequence's own frames, and its summary."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stereovo.benchmark import classical_estimators
from stereovo.benchmark.on_images import IMAGE_COLUMNS, plot_summary, run_on_frames, summarise, summary_markdown
from stereovo.reporting import wilson_interval
from stereovo.simulation import Sequence, SimulationConfig


@pytest.fixture(scope="module")
def frames():
    sequence = Sequence(SimulationConfig(n_frames=4, n_correspondences=150, outlier_ratio=0.5), seed=11)
    return [sequence.frame(k) for k in range(1, 5)]


def test_rows_follow_the_frames_and_a_methods_rows_do_not_depend_on_the_others(frames):
    both = run_on_frames(frames, classical_estimators(["ransac", "msac"]), seed=3)
    alone = run_on_frames(frames, classical_estimators(["msac"]), seed=3)
    assert [tuple(r) for r in both] == [IMAGE_COLUMNS] * 8
    assert [(r["frame"], r["method"]) for r in both] == [(k, m) for k in range(1, 5) for m in ("ransac", "msac")]
    strip = lambda rows: [{k: v for k, v in r.items() if k != "time_s"} for r in rows]  # noqa: E731
    assert strip([r for r in both if r["method"] == "msac"]) == strip(alone)
    assert strip(run_on_frames(frames, classical_estimators(["msac"]), seed=4)) != strip(alone)
    # poses against the truth (50 % outliers, N 150): every estimate within 1 deg, most within 1 deg / 5 cm
    assert all(r["status"] == "ok" and r["rot_err_deg"] < 1.0 for r in both)
    assert sum(r["success"] for r in both) >= 7
    assert all(r["outlier_ratio"] == pytest.approx(f.truth.outlier_ratio) for f in frames for r in both if r["frame"] == f.index)


def test_the_summary_counts_successes_with_wilson_intervals(tmp_path):
    rows = [{"method": "a", "success": s, "rot_err_deg": e, "trans_err_m": 0.01, "precision": 1.0, "recall": 0.5,
             "n_hypotheses": 10, "time_s": 0.002} for s, e in ((True, 0.1), (True, 0.3), (False, math.nan))]
    rows.append({**rows[0], "method": "b", "n_hypotheses": 4})
    summary = summarise(rows)
    assert [s["method"] for s in summary] == ["a", "b"]
    low, high = wilson_interval(2, 3)
    assert summary[0]["success"] == pytest.approx(2 / 3) and (summary[0]["ci_low"], summary[0]["ci_high"]) == (low, high)
    assert summary[0]["median_rot_err_deg"] == pytest.approx(0.2)  # the NaN of the failed frame left out
    assert summary[1]["frames"] == 1 and summary[1]["mean_hypotheses"] == 4 and summary[0]["median_ms"] == pytest.approx(2.0)
    table = summary_markdown(summary, "title")
    assert table.startswith("## title") and "| a | 3 | 66.7 %" in table
    assert plot_summary(tmp_path / "s.png", summary, "title").stat().st_size > 0
    assert np.isfinite(summary[0]["precision"])
