"""NG-RANSAC's task losses on values by hand, for the survivors of the mutmut run of ``agents/ngransac.py``
(docs/mutation-testing.md). The losses: minus the inlier fraction, plus half the change from the previous
motion in units of 25 cm and 1 degree, capped at 1 (Brachmann & Rother, "Neural-guided RANSAC", ICCV 2019,
for the self-supervised inlier loss).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from agents.ngransac import inlier_loss, smooth_inlier_loss
from stereovo.estimation import MotionEstimate


def _estimate(R, t, n_inliers, n=50):
    inliers = np.zeros(n, dtype=bool)
    inliers[:n_inliers] = True
    return MotionEstimate(R, np.asarray(t, float), inliers, "ok", 16, 16, 800, 0.0, "msac")


def _yaw(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def test_inlier_loss_of_a_single_correspondence_frame():
    assert inlier_loss(SimpleNamespace(n_inliers=1), SimpleNamespace(n=1)) == -1.0
    assert inlier_loss(SimpleNamespace(n_inliers=0), SimpleNamespace(n=0)) == 0.0


def test_smoothness_penalty_by_hand():
    frame = SimpleNamespace(n=50)
    previous = (np.eye(3), np.array([0.0, 0.0, -1.0]))
    # 5 cm and 0.2 degrees from the previous motion: change 0.05 / 0.25 + 0.2 / 1 = 0.4, penalty 0.2.
    loss = smooth_inlier_loss(_estimate(_yaw(0.2), [0.0, 0.05, -1.0], 20), frame, previous)
    assert loss == pytest.approx(-0.4 + 0.5 * 0.4, rel=1e-9)
    # 30 cm and 0.5 degrees: change 1.2 + 0.5 = 1.7, capped at 1: penalty 0.5.
    loss = smooth_inlier_loss(_estimate(_yaw(0.5), [0.3, 0.0, -1.0], 20), frame, previous)
    assert loss == pytest.approx(-0.4 + 0.5, rel=1e-12)
