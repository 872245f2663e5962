"""A learned sampler's features of raw stereo matches, with or without match scores.

Both kinds of sampler read the columns of :func:`vo_gym.features.compute_features`. A user's
matcher may give no scores; then every row gets :data:`UNINFORMATIVE_SCORE` and the mid
``score_rank`` 0.5 (a rank of equal scores would otherwise still order the rows by index). The
samplers were trained with scores of ROC AUC 0.6-0.75, so without them they rely on geometry alone.
:meth:`agents.checkpoint.LearnedPolicy.priors` and :class:`agents.LearnedEstimator` share this one
recipe, so the priors a user computes are the ones the estimator samples from.

The score column is the score itself, so a score on another scale (a descriptor distance, a ratio
test's raw ratio, 0-255) would reach the networks as values they never saw, and a distance would
even point the wrong way: scores outside [0, 1] are refused rather than silently misread.
"""

from __future__ import annotations

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.estimation.problem import StereoProblem, as_measurements
from vo_gym.features import compute_features, feature_index

__all__ = ["UNINFORMATIVE_SCORE", "match_features"]

UNINFORMATIVE_SCORE = 0.5
"""The match score every row gets when ``scores`` is None (and a mid rank, 0.5, for all)."""

RANK = feature_index("score_rank")


def match_features(prev: np.ndarray, curr: np.ndarray, camera: StereoCamera, scores: np.ndarray | None,
                   noise_sigma: float, previous_motion: tuple[np.ndarray, np.ndarray] | None = None,
                   problem: StereoProblem | None = None) -> np.ndarray:
    """Features ``(N, F)`` float32 of N matches, as :func:`vo_gym.features.compute_features`.

    Args:
        prev, curr: ``(N, 4)`` measurements ``(uL, vL, uR, vR)`` in pixels at k-1 and k.
        camera: the rectified :class:`stereovo.StereoCamera`.
        scores: ``(N,)`` match scores in [0, 1], higher = better (the samplers were trained on
            scores in (0, 1)); None: unknown (the module doc).
        noise_sigma: the pixel noise (px) the features assume.
        previous_motion: ``(R (3, 3), t (3,) m)`` of the previous frame pair, or None.
        problem: the frame's :class:`StereoProblem` if already built (its points are reused).

    Raises:
        ValueError: malformed input (as :func:`vo_gym.features.compute_features`), or scores
            outside [0, 1] (naming how many and their range).
    """
    given = scores
    if scores is None:
        n = problem.n if problem is not None else as_measurements("prev", prev).shape[0]
        given = np.full(n, UNINFORMATIVE_SCORE)
    features = compute_features(prev, curr, given, camera, noise_sigma, previous_motion, problem=problem)
    if scores is None:
        features[:, RANK] = 0.5
    else:  # validated as N finite numbers by compute_features
        _check_score_range(np.asarray(scores, dtype=np.float64))
    return features


def _check_score_range(scores: np.ndarray) -> None:
    """Refuse ``scores`` (N,) outside [0, 1]; :func:`compute_features` has already refused every
    malformed array, so this sees N finite real numbers."""
    outside = (scores < 0.0) | (scores > 1.0)
    count = int(np.count_nonzero(outside))
    if count:
        raise ValueError(
            f"scores must lie in [0, 1], higher = better (the samplers were trained on scores in (0, 1)); got "
            f"{count} of {scores.size} outside, from {scores.min():.6g} to {scores.max():.6g}: map them first "
            "(e.g. a ratio test's ratio r to 1 - r), or pass scores=None"
        )
