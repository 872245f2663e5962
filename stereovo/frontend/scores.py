"""Match scores from descriptor distances and ratios, and their ROC AUC.

A match ``k-1 -> k`` rests on three descriptor comparisons: the stereo match at k-1, the stereo
match at k and the temporal match of the left keypoints. Each has a distance ``d`` (a fraction of
the descriptor's largest) and Lowe's ratio ``r = d / d_2`` to the second-best candidate of its
search window (0 when there is none). Each comparison's confidence is

    ``q = (1 - d / max_distance) * (1 - r)``   (clipped to [0, 1])

-- a near descriptor with no close rival scores near 1 -- and the score of the match is their
geometric mean, clipped into the open interval:

    ``score = clip((q_stereo_prev * q_stereo_curr * q_temporal) ** (1/3), 1e-3, 1 - 1e-3)``.

A score ranks matches; it is not a probability. Its ROC AUC as an inlier detector is measured on
rendered sequences with ground-truth labels (:func:`roc_auc`, docs/images.md).
"""

from __future__ import annotations

import numpy as np

SCORE_CLIP = 1e-3
"""Scores lie in ``[SCORE_CLIP, 1 - SCORE_CLIP]``, strictly inside (0, 1)."""


def comparison_confidence(distance: np.ndarray, ratio: np.ndarray, max_distance: float) -> np.ndarray:
    """``(1 - d / max_distance) * (1 - r)`` clipped to [0, 1], elementwise."""
    d = np.clip(np.asarray(distance, dtype=float) / max_distance, 0.0, 1.0)
    r = np.clip(np.asarray(ratio, dtype=float), 0.0, 1.0)
    return (1.0 - d) * (1.0 - r)


def match_scores(confidences: list[np.ndarray]) -> np.ndarray:
    """The geometric mean of per-comparison confidences ``(N,)`` each, clipped into (0, 1)."""
    product = np.ones_like(np.asarray(confidences[0], dtype=float))
    for q in confidences:
        product = product * q
    return np.clip(product ** (1.0 / len(confidences)), SCORE_CLIP, 1.0 - SCORE_CLIP)


def roc_auc(scores: np.ndarray, labels: np.ndarray) -> float:
    """Area under the ROC curve of ``scores`` as a detector of ``labels`` (the Mann-Whitney U
    statistic over the positive-negative pairs, ties counting half); NaN without both classes."""
    scores = np.asarray(scores, dtype=float).ravel()
    labels = np.asarray(labels, dtype=bool).ravel()
    if scores.shape != labels.shape:
        raise ValueError(f"scores and labels differ in shape: {scores.shape} vs {labels.shape}")
    n_pos = int(labels.sum())
    n_neg = labels.size - n_pos
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    order = np.argsort(scores, kind="mergesort")
    ranks = np.empty(scores.size)
    sorted_scores = scores[order]
    # average ranks over ties
    boundaries = np.flatnonzero(np.diff(sorted_scores)) + 1
    starts = np.concatenate([[0], boundaries])
    stops = np.concatenate([boundaries, [scores.size]])
    mean_rank = (starts + stops - 1) / 2.0 + 1.0
    ranks[order] = np.repeat(mean_rank, stops - starts)
    u = ranks[labels].sum() - n_pos * (n_pos + 1) / 2.0
    return float(u / (n_pos * n_neg))
