"""Per-frame rewards of :class:`vo_gym.StereoVOEnv`, all bounded in ``[-1, 1]``.

Three modes (``reward_mode=``):

``"supervised"`` (needs ground truth)
    With ``e = max(rot_err / 1 deg, trans_err / max(0.05 m, 0.05 |t_true|))`` the
    pose error relative to the success bounds of :mod:`stereovo.metrics`
    (``e < 1`` and status ok is a success)::

        r = success_bonus * [success] + (1 - success_bonus) * (1 - e) / (1 + e)
            - hypothesis_cost * n_hypotheses

    ``(1 - e) / (1 + e)`` is +1 for an exact estimate, 0 on the success
    boundary and tends to -1 for a useless one, so the reward keeps improving
    below the success threshold. A failed estimate (status not ok) earns
    ``failure_reward``.

``"inliers"`` (self-supervised: no ground truth, works on real data)
    ``r = n_inliers / N - hypothesis_cost * n_hypotheses``, the inlier fraction of
    the chosen model under the estimator's own gate; ``failure_reward`` on failure.

``"msac"`` (self-supervised)
    ``r = mean_i max(0, 1 - e_i^2 / T^2) - hypothesis_cost * n_hypotheses``: the
    MSAC score of the chosen model (``1 + score / N`` with the core's
    ``TruncatedQuadratic``), ``e_i`` the stereo reprojection error of match i
    and ``T`` the estimator's reprojection gate; ``failure_reward`` on failure.

Every reward is finally clipped to ``[-1, 1]``. Under the environment's
default fixed hypothesis budget the hypothesis cost is a constant offset; it
matters with ``budget=None`` (adaptive termination).
"""

from __future__ import annotations

import math

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.estimation.roles.reprojection import reprojection_sq
from stereovo.estimation.roles.scoring import TruncatedQuadratic
from stereovo.metrics import FrameMetrics
from stereovo.metrics import pose_error_ratio as error_ratio

__all__ = [
    "REWARD_MODES",
    "REWARD_OPTIONS",
    "REWARD_RANGE",
    "pose_error_ratio",
    "supervised_reward",
    "inlier_reward",
    "msac_reward",
]

REWARD_MODES: tuple[str, ...] = ("supervised", "inliers", "msac")
"""``supervised`` reads the ground truth; ``inliers`` and ``msac`` do not."""

REWARD_OPTIONS: dict[str, str] = {"threshold_px": "msac"}
"""Estimator options a reward reads itself, each with the ``reward_mode`` that reads it: ``"msac"`` scores
the estimate under the stereo reprojection gate ``threshold_px`` (``T`` above) whatever gate the method
judges by, so there the option is the environment's where the method would not read it."""

REWARD_RANGE: tuple[float, float] = (-1.0, 1.0)


def _clip(value: float) -> float:
    return float(min(max(value, REWARD_RANGE[0]), REWARD_RANGE[1]))


def pose_error_ratio(metrics: FrameMetrics) -> float:
    """:func:`stereovo.metrics.pose_error_ratio` of a frame's errors: below 1 means within the success bounds."""
    return error_ratio(metrics.rot_err_deg, metrics.trans_err_m, metrics.t_true_norm_m)


def supervised_reward(
    metrics: FrameMetrics,
    success_bonus: float = 0.5,
    hypothesis_cost: float = 0.0,
    failure_reward: float = -1.0,
) -> float:
    """Reward from the frame's errors against ground truth (see the module doc)."""
    if metrics.status != "ok":
        return _clip(failure_reward)
    e = pose_error_ratio(metrics)
    accuracy = (1.0 - e) / (1.0 + e) if math.isfinite(e) else -1.0
    reward = success_bonus * float(metrics.success) + (1.0 - success_bonus) * accuracy
    return _clip(reward - hypothesis_cost * metrics.n_hypotheses)


def inlier_reward(
    ok: bool, n_inliers: int, n: int, n_hypotheses: int, hypothesis_cost: float = 0.0, failure_reward: float = -1.0
) -> float:
    """Inlier fraction of the chosen model, no ground truth needed."""
    if not ok:
        return _clip(failure_reward)
    return _clip(n_inliers / max(n, 1) - hypothesis_cost * n_hypotheses)


def msac_reward(
    ok: bool,
    rotation: np.ndarray,
    translation: np.ndarray,
    prev: np.ndarray,
    curr: np.ndarray,
    camera: StereoCamera,
    threshold_sq: float,
    n_hypotheses: int,
    hypothesis_cost: float = 0.0,
    failure_reward: float = -1.0,
) -> float:
    """Normalised MSAC score ``1 + score / N`` of the chosen model under a reprojection gate (px^2).

    A row without depth at k-1 (disparity at or below the camera's minimum, or no finite
    triangulation: the hostile preset's mismatches, a real front end's far points) cannot be
    reprojected; it counts as an outlier, at the full cost of the gate, as it would beyond it."""
    if not ok:
        return _clip(failure_reward)
    n = prev.shape[0]
    points, _, usable = camera.triangulate_usable(prev, 1.0)
    sq = np.full((1, n), np.inf)
    if usable.any():
        sq[0, usable] = reprojection_sq(camera, rotation[None], translation[None], points[usable], curr[usable])[0]
    score = float(TruncatedQuadratic().score(sq, threshold_sq)[0])
    return _clip(1.0 + score / max(n, 1) - hypothesis_cost * n_hypotheses)
