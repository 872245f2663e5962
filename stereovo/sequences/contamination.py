"""Raising an image frame's contamination to a chosen epsilon with wrong temporal matches.

A front end on rendered images makes 15-30 % outliers (:mod:`stereovo.sequences.labels`); the
transfer matrix and the contamination sweeps need the same frames at eps 0.5, 0.8 and 0.9.
:func:`contaminate` turns labelled inliers into outliers the way a temporal matcher errs: it
re-pairs them, so that a feature of image k-1 is matched to another real feature of image k. The
rows keep their real stereo geometry at both frames (a resolvable depth, pixels on features the
detector found); only the temporal link is wrong. Nothing is added or dropped: N stays the front
end's.

The re-paired rows' scores are redrawn from the frame's own labelled outliers' scores, so the
score keeps the front end's separation between its inliers and its outliers (the front end's score
of the original row belonged to a correct match; keeping it would make the new outliers look
like inliers to every score-guided sampler).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from stereovo.sequences.labels import PIXEL_TOLERANCE
from stereovo.simulation import Frame, OutlierKind

MIN_OUTLIER_SCORES = 5
"""Fewer labelled outliers than this in a frame: re-paired rows draw their scores from all rows."""


def contaminate(frame: Frame, epsilon: float, rng: np.random.Generator) -> Frame:
    """``frame`` with at least ``round(epsilon * N)`` labelled outliers.

    Args:
        frame: a frame with labels (``frame.truth.inlier``), e.g. from a rendered sequence.
        epsilon: the wanted outlier fraction in [0, 1).
        rng: the draws (which inliers, their new partners, their scores).

    Returns:
        A new frame: ``max(0, round(epsilon * N) - outliers)`` inliers, chosen at random, have
        their ``curr`` rows cyclically exchanged among themselves (each gets another chosen
        row's measurement at k), are labelled ``RANDOM_MISMATCH`` and get a score drawn from the
        frame's labelled outliers. A re-paired row whose new left pixel at k lies within the
        labels' tolerance (:data:`~stereovo.sequences.labels.PIXEL_TOLERANCE`) of its old one is
        still a correct match and keeps its label. A frame already at or above ``epsilon`` is
        returned unchanged (the same object).

    Raises:
        ValueError: ``epsilon`` outside [0, 1), or ``rng`` not a ``numpy.random.Generator``.
    """
    if isinstance(epsilon, (bool, np.bool_)) or not isinstance(epsilon, (int, float, np.integer, np.floating)) \
            or not 0.0 <= float(epsilon) < 1.0:
        raise ValueError(f"epsilon must be an outlier fraction in [0, 1), got {epsilon!r}")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    truth = frame.truth
    inlier = np.asarray(truth.inlier, dtype=bool)
    n = inlier.size
    wanted = int(round(float(epsilon) * n)) - int(np.count_nonzero(~inlier))
    candidates = np.flatnonzero(inlier)
    if wanted <= 0 or candidates.size < 2:
        return frame
    chosen = rng.choice(candidates, size=min(max(wanted, 2), candidates.size), replace=False)
    # each chosen row takes the next chosen row's measurement at k: no row keeps its own
    curr = frame.curr.copy()
    curr[chosen] = frame.curr[np.roll(chosen, 1)]
    moved = np.any(np.abs(curr[chosen, :2] - frame.curr[chosen, :2]) > PIXEL_TOLERANCE, axis=1)
    wrong = chosen[moved]
    pool = frame.scores[~inlier] if np.count_nonzero(~inlier) >= MIN_OUTLIER_SCORES else frame.scores
    scores = frame.scores.copy()
    scores[wrong] = rng.choice(pool, size=wrong.size, replace=True)
    new_inlier = inlier.copy()
    new_inlier[wrong] = False
    kind = np.asarray(truth.outlier_kind).copy()
    kind[wrong] = int(OutlierKind.RANDOM_MISMATCH)
    new_truth = dataclasses.replace(truth, inlier=new_inlier, outlier_kind=kind,
                                    outlier_ratio=float(1.0 - new_inlier.mean()))
    return dataclasses.replace(frame, curr=curr, scores=scores, truth=new_truth)
