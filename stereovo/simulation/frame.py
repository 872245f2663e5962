"""What a simulated frame pair holds: the matches a method sees and the truth only benchmarks read.

:class:`Frame` carries the putative stereo matches, their scores and the camera;
:class:`FrameTruth` the true motion, poses and the label of every row
(:class:`OutlierKind`). How they are made: :mod:`stereovo.simulation.pair`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.simulation.scores import score_inlier_probability


class OutlierKind(enum.IntEnum):
    """Ground-truth label of a correspondence (stored as int8 in :class:`FrameTruth`)."""

    INLIER = 0
    RANDOM_MISMATCH = 1
    STEREO_MISMATCH = 2
    MOVING_OBJECT = 3
    INDEPENDENT_MISMATCH = 4  # left and right pixels at k moved independently (hostile)
    DUPLICATE_MATCH = 5  # a frame k-1 point matched a second time, to another landmark (hostile)
    FAR_CLUTTER = 6  # a drifting sky-like point at very large depth (hostile)
    REPETITIVE_TEXTURE = 7  # a cluster consistent with a wrong motion at a wrong depth (hostile)


@dataclass(frozen=True, eq=False)
class FrameTruth:
    """Ground truth of one frame pair. No estimator, feature or agent may read it.

    Attributes:
        rotation: ``(3, 3)`` true motion R with ``x_k = R x_{k-1} + t``.
        translation: ``(3,)`` true t (m); ``(R, t) = relative_motion(pose_prev, pose_curr)``.
        inlier: ``(N,)`` bool.
        outlier_kind: ``(N,)`` int8 values of :class:`OutlierKind`.
        pose_prev: ``(4, 4)`` camera-to-world pose of frame k-1.
        pose_curr: ``(4, 4)`` camera-to-world pose of frame k.
        outlier_ratio: the contamination epsilon drawn for this frame.
    """

    rotation: np.ndarray
    translation: np.ndarray
    inlier: np.ndarray
    outlier_kind: np.ndarray
    pose_prev: np.ndarray
    pose_curr: np.ndarray
    outlier_ratio: float


@dataclass(frozen=True, eq=False)
class Frame:
    """One frame pair ``(k-1, k)`` of putative stereo matches.

    Attributes:
        index: k, 1-based within a :class:`Sequence`.
        prev: ``(N, 4)`` float64 measurements ``(uL, vL, uR, vR)`` (px) at k-1.
        curr: ``(N, 4)`` at k; row i of ``prev`` and ``curr`` is one putative match.
        scores: ``(N,)`` float64 match scores in (0, 1), higher = more likely an inlier.
        camera: the stereo rig.
        noise_sigma: the sensor's pixel noise std (px), a known sensor spec.
        score_auc: the match score's ROC AUC as an inlier detector, a known spec of the matcher
            (:mod:`stereovo.simulation.scores`).
        truth: ground truth; for benchmarks only.
    """

    index: int
    prev: np.ndarray
    curr: np.ndarray
    scores: np.ndarray
    camera: StereoCamera
    noise_sigma: float
    score_auc: float
    truth: FrameTruth

    def __post_init__(self) -> None:
        prev, curr, scores = self.prev, self.curr, self.scores
        if type(prev) is np.ndarray and type(curr) is np.ndarray and type(scores) is np.ndarray:
            # the simulator's frames: the shapes read directly (np.shape and np.ndim cost more than the test)
            if prev.ndim == 2 and prev.shape[1] == 4 and curr.shape == prev.shape and scores.shape == prev.shape[:1]:
                return
        n = np.shape(self.prev)[0] if np.ndim(self.prev) == 2 else -1
        if np.shape(self.prev) != (n, 4) or np.shape(self.curr) != (n, 4):
            raise ValueError(
                "Frame.prev and Frame.curr must both be (N, 4), "
                f"got {np.shape(self.prev)} and {np.shape(self.curr)}"
            )
        if np.shape(self.scores) != (n,):
            raise ValueError(f"Frame.scores must be ({n},), got {np.shape(self.scores)}")

    @property
    def n(self) -> int:
        """Number of putative matches N."""
        return int(self.prev.shape[0])

    @property
    def match_probabilities(self) -> np.ndarray:
        """``(N,)`` the scores as calibrated inlier probabilities, ``P(inlier | score)`` at an
        uninformed prior inlier share of one half: what a matcher calibrated on labelled matches
        reports, and what Guided-MLESAC's ``gamma_i`` means (:func:`~stereovo.simulation.scores.score_inlier_probability`)."""
        return score_inlier_probability(self.scores, self.score_auc)

    def __repr__(self) -> str:
        return (
            f"Frame(index={self.index}, n={self.n}, noise_sigma={self.noise_sigma}, "
            f"outlier_ratio={self.truth.outlier_ratio:.3f})"
        )

