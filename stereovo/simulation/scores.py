"""The match-score model: how a frame's scores are drawn, and what a score says about its match.

A score is ``Phi(latent)`` with ``latent ~ N(mu, 1)`` for an inlier and ``N(0, 1)`` for any outlier,
``mu = sqrt(2) Phi^-1(auc)``, so the ROC AUC of score vs inlier is ``auc`` in expectation. Only the
label moves the latent: a moving object's points score like any other outlier.

A raw score is not a probability (three in ten inliers score above 0.99 at AUC 0.9, one outlier in a
hundred does). Methods that read a prior as the chance that a match is correct (Guided-MLESAC's
``gamma_i``: Tordoff & Murray, "Guided-MLESAC: faster image transform estimation by using matching
priors", IEEE TPAMI 27(10), 2005, who learn the mapping from score to that chance on labelled
training matches) need the calibrated value, :func:`score_inlier_probability`: the posterior of
the score model. A matcher calibrated that way knows its own ROC (``auc``, like the pixel noise, a
known spec of the front end), not the contamination of the frame at hand, so the prior inlier share
is a setting (one half: uninformed).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.special import expit, ndtr, ndtri

from stereovo.options import Number

SCORE_AUC = Number(low=0.5, high=1.0, high_open=True)
"""A score's ROC AUC as an inlier detector: 0.5 says nothing, 1 would separate perfectly."""
INLIER_SHARE = Number(low=0.0, high=1.0, low_open=True, high_open=True)
_LOWEST, _HIGHEST = np.finfo(float).tiny, np.nextafter(1.0, 0.0)  # scores stay inside (0, 1): finite probits


def latent_shift(auc: float) -> float:
    """``mu = sqrt(2) Phi^-1(auc)``: the inliers' latent mean for a score of ROC AUC ``auc``."""
    return math.sqrt(2.0) * float(ndtri(SCORE_AUC.check("auc", auc, prefix="")))


def draw_scores(inlier: np.ndarray, auc: float, rng: np.random.Generator) -> np.ndarray:
    """``(N,)`` scores in ``(0, 1)`` for the rows' labels ``inlier (N,)`` bool, one standard normal each."""
    shift = _SHIFTS.get(auc) if type(auc) is float else None
    if shift is None:
        shift = latent_shift(auc)
        if type(auc) is float and len(_SHIFTS) < 64:
            _SHIFTS[auc] = shift  # a simulator asks for its one AUC every frame
    latent = rng.standard_normal(inlier.shape[0])
    if type(inlier) is np.ndarray and inlier.dtype == np.bool_ and inlier.ndim == 1:
        # `latent + shift * inlier` in place, then ndtr into the same array and np.clip's values
        # (a NaN stays NaN), each in one pass: numpy's values without its temporaries
        _shift_rows(latent, inlier, float(shift))
        ndtr(latent, out=latent)
        _clip_rows(latent, _LOWEST, _HIGHEST)  # returns nothing: boxing an array costs a dtype lookup
        return latent
    latent = latent + shift * inlier
    scores = ndtr(latent)
    return np.minimum(np.maximum(scores, _LOWEST, out=scores), _HIGHEST, out=scores)


@njit(cache=True, nogil=True)
def _shift_rows(latent, inlier, shift):
    """``latent += shift * inlier`` as numpy computes it (the label as 1.0 or 0.0, times the shift)."""
    for i in range(latent.shape[0]):
        latent[i] = latent[i] + shift * (1.0 if inlier[i] else 0.0)


@njit(cache=True, nogil=True)
def _clip_rows(values, low, high):
    """``np.minimum(np.maximum(values, low), high)`` in place (ordered bounds; a NaN stays NaN)."""
    for i in range(values.shape[0]):
        x = values[i]
        if x < low:
            x = low
        if x > high:
            x = high
        values[i] = x


_SHIFTS: dict[float, float] = {}  # latent_shift of the AUCs drawn with so far (checked ones only)


def score_inlier_probability(scores: np.ndarray, auc: float, inlier_share: float = 0.5) -> np.ndarray:
    """``(N,)`` ``P(inlier | score)`` under the score model: the calibrated inlier probability.

    With ``z = Phi^-1(score)`` the likelihood ratio of inlier to outlier is ``exp(mu z - mu^2 / 2)``;
    the posterior at a prior inlier share ``s`` is ``expit(mu z - mu^2 / 2 + log(s / (1 - s)))``,
    computed in log-odds so no score underflows or rounds to certainty. At ``auc = 0.5`` every match
    gets ``s``. Among many matches scored alike, a fraction ``p`` are inliers when the frame's inlier
    share is ``s`` (``tests/test_match_scores.py``).

    Args:
        scores: ``(N,)`` match scores in ``[0, 1]`` (as drawn by :func:`draw_scores`).
        auc: the score's ROC AUC in ``[0.5, 1)``.
        inlier_share: prior inlier share in ``(0, 1)``.

    Raises:
        ValueError: naming the argument, for scores outside ``[0, 1]`` or not finite, an ``auc`` or
            ``inlier_share`` out of range.
    """
    s = np.asarray(scores, dtype=float)
    if s.ndim != 1:
        raise ValueError(f"scores must be a 1-D array of numbers in [0, 1], got shape {s.shape}")
    bad = np.flatnonzero(~((s >= 0) & (s <= 1)))  # NaN fails both
    if bad.size:
        raise ValueError(f"scores must be a 1-D array of numbers in [0, 1], got {float(s[bad[0]])!r} at row {bad[0]}")
    mu = latent_shift(auc)
    share = INLIER_SHARE.check("inlier_share", inlier_share, prefix="")
    z = ndtri(np.clip(s, _LOWEST, _HIGHEST))
    return expit(mu * z - 0.5 * mu * mu + math.log(share / (1.0 - share)))
