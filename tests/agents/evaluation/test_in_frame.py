"""agents.evaluation.in_frame.summarise on hand-made rows: the stop's miss rate is the share of the stopped frames
(the policy's own stop, not the cap) without an all-inlier sample among their scored hypotheses; rows without
that record (PROSAC's, run outside the environment) and frames that ran to the cap are left out of it."""

from __future__ import annotations

import pytest

from agents.evaluation.in_frame import summarise


def _row(success: bool, stopped: bool, all_inlier_drawn: bool | None, n_hypotheses: int = 8) -> dict:
    return {"seed": 0, "frame": 1, "success": success, "n_hypotheses": n_hypotheses, "stopped": stopped,
            "all_inlier_drawn": all_inlier_drawn, "rot_err_deg": 0.1, "trans_err_m": 0.01}


def test_the_miss_rate_is_the_share_of_stopped_frames_without_an_all_inlier_sample():
    rows = [
        _row(True, True, True, 4), _row(False, True, False, 4), _row(True, True, True, 12),  # stopped: 1 miss of 3
        _row(False, False, False, 64), _row(True, False, True, 64),  # ran to the cap: not the stop's doing
        _row(True, True, None, 20),  # no all-inlier record (PROSAC's row)
    ]
    summary = summarise(rows)
    assert summary["stopped"] == 3 and summary["miss_rate"] == pytest.approx(1 / 3, abs=1e-15)
    assert summary["frames"] == 6 and summary["successes"] == 4 and summary["success"] == pytest.approx(4 / 6)
    assert summary["mean_hypotheses"] == pytest.approx((4 + 4 + 12 + 64 + 64 + 20) / 6)
    # Every stop drew an all-inlier sample: no miss; every stop missed: all of them.
    assert summarise([_row(True, True, True), _row(False, True, True)])["miss_rate"] == 0.0
    assert summarise([_row(False, True, False), _row(True, True, False), _row(True, False, True)])["miss_rate"] == 1.0


def test_without_a_stopped_frame_the_miss_rate_is_none():
    summary = summarise([_row(True, False, False), _row(True, True, None)])
    assert summary["stopped"] == 0 and summary["miss_rate"] is None
