"""A learned sampler's features of raw stereo matches, with or without match scores.

Both kinds of sampler read the columns of :func:`vo_gym.features.compute_features`. A user's
matcher may give no scores; then every row gets :data:`UNINFORMATIVE_SCORE` and the mid
``score_rank`` 0.5 (a rank of equal scores would otherwise still order the rows by index). The
samplers were trained with scores of ROC AUC 0.6-0.75, so without them they rely on geometry alone.
:meth:`agents.checkpoint.LearnedPolicy.priors` and :class:`agents.LearnedEstimator` share this one
recipe, so the priors a user computes are the ones the estimator samples from.
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
        scores: ``(N,)`` match scores, higher = better; None: unknown (the module doc).
        noise_sigma: the pixel noise (px) the features assume.
        previous_motion: ``(R (3, 3), t (3,) m)`` of the previous frame pair, or None.
        problem: the frame's :class:`StereoProblem` if already built (its points are reused).

    Raises:
        ValueError: malformed input (as :func:`vo_gym.features.compute_features`).
    """
    given = scores
    if scores is None:
        n = problem.n if problem is not None else as_measurements("prev", prev).shape[0]
        given = np.full(n, UNINFORMATIVE_SCORE)
    features = compute_features(prev, curr, given, camera, noise_sigma, previous_motion, problem=problem)
    if scores is None:
        features[:, RANK] = 0.5
    return features
