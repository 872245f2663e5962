"""Match scores of the front end (stereovo/frontend/scores.py): range, ranking, and the ROC AUC."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.frontend import roc_auc
from stereovo.sequences import FRONTEND_SCORE_AUC


def test_scores_lie_in_the_open_interval_and_rank_inliers_first(street):
    scores, labels = [], []
    for k in (1, 2, 3):
        frame = street.frame(k)
        scores.append(frame.scores)
        labels.append(frame.truth.inlier)
    scores, labels = np.concatenate(scores), np.concatenate(labels)
    assert np.all((scores > 0) & (scores < 1))
    auc = roc_auc(scores, labels)
    assert auc > 0.6
    assert abs(auc - FRONTEND_SCORE_AUC) < 0.15


def test_roc_auc_counts_pairs_with_ties_as_halves():
    rng = np.random.default_rng(4)
    scores = rng.integers(0, 5, 200).astype(float)
    labels = rng.random(200) < 0.4
    pos, neg = scores[labels], scores[~labels]
    brute = (np.sum(pos[:, None] > neg[None, :]) + 0.5 * np.sum(pos[:, None] == neg[None, :])) / (pos.size * neg.size)
    assert roc_auc(scores, labels) == pytest.approx(brute)
    assert np.isnan(roc_auc(scores, np.ones(200, bool)))
