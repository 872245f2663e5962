"""Synthetic stereo visual-odometry frames: motion, world, matches, outliers and match scores.

A :class:`Frame` is one frame pair ``(k-1, k)``: ``N`` putative stereo matches
``prev[i] <-> curr[i]`` (each row ``(uL, vL, uR, vR)`` in pixels), a match score
per row, and a :class:`FrameTruth` that only benchmarks may read.

How a frame is made:

1. Motion. Body-frame linear and angular velocities (a twist ``(v, w)`` in
   m/frame and rad/frame) follow a mean-reverting AR(1) process, the exact
   discretisation of an Ornstein-Uhlenbeck process, per :class:`MotionPreset`.
   The camera moves by ``exp(twist)`` in its own frame, so the point transform
   is ``T = exp(-twist)`` and the pose update is ``geometry.pose_update``.
2. World. Landmarks are drawn procedurally, per frame pair, in a window
   anchored at the camera k-1 (a street: ground plane, two facades, clutter;
   or an open volume), stored in world coordinates, and kept only when both
   stereo pairs see them within ``[z_min, z_max]``. Nothing persists between
   frames: each frame pair is a fresh, seeded world patch.
3. Correspondences. Exactly ``N`` rows: ``round(epsilon N)`` outliers split
   by ``outlier_mix`` (random mismatches, stereo mismatches, one moving
   object; with ``outliers="hostile"`` also the hostile kinds), the rest
   inliers; Gaussian (or Student-t) pixel noise with one ``v`` noise shared
   by both images; rows shuffled.
4. Scores. ``score = Phi(latent)`` with ``latent ~ N(mu, 1)`` for inliers and
   ``N(0, 1)`` for outliers, ``mu = sqrt(2) Phi^-1(auc)``: the ROC AUC of score
   vs inlier is ``auc`` exactly in expectation. A raw score is not a probability:
   :attr:`Frame.match_probabilities` is the calibrated ``P(inlier | score)``
   (:func:`score_inlier_probability`), what Guided-MLESAC's priors mean.

Every outlier is a *detectable* outlier: its noise-free measurement at k lies
at least ``max(4 px, 8 sigma)`` (norm over ``uL, v, uR``) from where the true
motion would put it, so labels mean what they say; stereo mismatches
additionally carry a relative depth error of at least 20 %.

Randomness: a frame's generator is split into independent streams (landmarks,
outliers, noise, scores, row order). With one seed, changing only
``noise_sigma`` leaves the inlier geometry and the standard-normal noise draws
unchanged, and changing only ``score_auc`` leaves everything but the scores
unchanged: benchmark grids get common random numbers across those axes.

Where each part lives (this package re-exports the public names):

- :mod:`~stereovo.simulation.frame`: :class:`Frame`, :class:`FrameTruth`, :class:`OutlierKind`;
- :mod:`~stereovo.simulation.motion`: the velocity process, :class:`MotionPreset`, :data:`PRESETS`;
- :mod:`~stereovo.simulation.config`: :class:`SimulationConfig`, :data:`WORLDS`, :data:`OUTLIER_KINDS`, :data:`OUTLIER_PRESETS`,
  :class:`InfeasibleSettingsError` (valid settings the simulator could not draw a frame for);
- :mod:`~stereovo.simulation.world`: the landmarks (step 2);
- :mod:`~stereovo.simulation.outliers`: the three default kinds of outliers (step 3);
- :mod:`~stereovo.simulation.hostile`: the hostile kinds (``outliers="hostile"``): independent
  left/right mismatches, duplicate matches, far clutter, repetitive texture; Student-t noise;
- :mod:`~stereovo.simulation.scores`: the match-score model and its calibrated inlier probability;
- :mod:`~stereovo.simulation.pair`: one frame pair from two poses: noise, scores, row order;
- :mod:`~stereovo.simulation.sequence`: :func:`simulate_frame` and :class:`Sequence`.
"""

from __future__ import annotations

from stereovo.simulation.config import (
    MAX_FRAMES,
    MAX_NOISE_SIGMA_PX,
    OUTLIER_KINDS,
    OUTLIER_PRESETS,
    WORLDS,
    InfeasibleSettingsError,
    SimulationConfig,
)
from stereovo.simulation.frame import Frame, FrameTruth, OutlierKind
from stereovo.simulation.motion import PRESETS, MotionPreset
from stereovo.simulation.scores import score_inlier_probability
from stereovo.simulation.sequence import Sequence, simulate_frame

__all__ = [
    "OutlierKind",
    "MotionPreset",
    "PRESETS",
    "WORLDS",
    "OUTLIER_KINDS",
    "OUTLIER_PRESETS",
    "SimulationConfig",
    "InfeasibleSettingsError",
    "FrameTruth",
    "Frame",
    "simulate_frame",
    "Sequence",
    "score_inlier_probability",
]
