"""Per-frame and trajectory accuracy metrics.

Per frame: rotation / translation error of an estimated motion against the
simulator's truth, the success criterion every report shares, and inlier
precision / recall. Per trajectory, on ``(F, 4, 4)`` camera-to-world poses:
ATE (raw and SE(3)-aligned), RPE, and the KITTI segment drift that evo lacks.

Units: errors are computed in metres and radians; fields whose name ends in
``_deg`` (or ``_deg_per_m``, ``_percent``) are converted for reports.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, Sequence

import numpy as np
from numba import njit

from stereovo.geometry import invert_transform, rotation_angle, rotation_error, translation_error

# Success thresholds shared by every consumer (odometry, gym env, baselines):
# a frame succeeds when its status is ok, its rotation error is below
# SUCCESS_ROT_DEG and its translation error below
# max(SUCCESS_TRANS_M, SUCCESS_TRANS_REL * ||t_true||).
SUCCESS_ROT_DEG = 1.0
SUCCESS_TRANS_M = 0.05
SUCCESS_TRANS_REL = 0.05

# KITTI odometry benchmark segment lengths in metres.
KITTI_LENGTHS: tuple[float, ...] = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
KITTI_STEP = 10


def is_success(rot_err_rad: Any, trans_err: Any, t_true_norm: Any) -> np.ndarray:
    """Vectorised success test (status not included: AND it with ``status == "ok"``).

    Args:
        rot_err_rad: rotation errors in radians, any shape.
        trans_err: translation errors in metres, broadcastable.
        t_true_norm: norms of the true translations in metres, broadcastable.

    Returns:
        Boolean array of the broadcast shape (a 0-d array for scalars).
        NaN errors count as failures.
    """
    rot = np.asarray(rot_err_rad, dtype=float)
    trans = np.asarray(trans_err, dtype=float)
    bound = np.maximum(SUCCESS_TRANS_M, SUCCESS_TRANS_REL * np.asarray(t_true_norm, dtype=float))
    return (rot < np.deg2rad(SUCCESS_ROT_DEG)) & (trans < bound)


_SUCCESS_ROT_RAD = float(np.deg2rad(SUCCESS_ROT_DEG))


def _is_success_scalar(rot_err_rad: float, trans_err: float, t_true_norm: float) -> bool:
    """:func:`is_success` of three Python floats, without numpy's per-call cost: the same bound
    (``np.maximum`` passes a NaN on, and a NaN bound fails) and the same comparisons."""
    relative = SUCCESS_TRANS_REL * t_true_norm
    bound = relative if (relative > SUCCESS_TRANS_M or relative != relative) else SUCCESS_TRANS_M
    return rot_err_rad < _SUCCESS_ROT_RAD and trans_err < bound


def pose_error_ratio(rot_err_deg: float, trans_err_m: float, t_true_norm_m: float) -> float:
    """A pose error in units of the success bounds: below 1 (with status ok) is a success.

    ``max(rot_err_deg / SUCCESS_ROT_DEG, trans_err_m / max(SUCCESS_TRANS_M, SUCCESS_TRANS_REL * t_true_norm_m))``
    for a rotation error in degrees, a translation error in metres and the norm of the true
    translation in metres. The environment's supervised reward and the NG-RANSAC trainer's
    supervised loss are both built on it.
    """
    trans_bound = max(SUCCESS_TRANS_M, SUCCESS_TRANS_REL * t_true_norm_m)
    return float(max(rot_err_deg / SUCCESS_ROT_DEG, trans_err_m / trans_bound))


def inlier_precision_recall(predicted: np.ndarray, actual: np.ndarray) -> tuple[float, float]:
    """Precision and recall of a predicted inlier mask against the true one.

    NaN-free by definition: precision is 0 when nothing is predicted, recall is
    0 when there are no true inliers.
    """
    tp, n_pred, n_true = _mask_counts(predicted, actual)
    return (tp / n_pred if n_pred else 0.0), (tp / n_true if n_true else 0.0)


def _mask_counts(predicted: np.ndarray, actual: np.ndarray) -> tuple[int, int, int]:
    """``(|predicted & actual|, |predicted|, |actual|)`` of two inlier masks (read as bool); one
    compiled pass for two 1-D bool arrays (a frame's), numpy's counts otherwise."""
    if (type(predicted) is np.ndarray and type(actual) is np.ndarray and predicted.dtype == np.bool_
            and actual.dtype == np.bool_ and predicted.ndim == 1 and predicted.shape == actual.shape):
        tp, n_pred, n_true = _bool_counts(predicted, actual)
        return int(tp), int(n_pred), int(n_true)
    predicted = np.asarray(predicted, dtype=bool)
    actual = np.asarray(actual, dtype=bool)
    if predicted.shape != actual.shape:
        raise ValueError(f"inlier masks differ in shape: {predicted.shape} vs {actual.shape}")
    return int(np.count_nonzero(predicted & actual)), int(np.count_nonzero(predicted)), int(np.count_nonzero(actual))


@njit(cache=True, nogil=True)
def _bool_counts(predicted, actual):
    tp = n_pred = n_true = 0
    for i in range(predicted.shape[0]):
        p, a = predicted[i], actual[i]
        tp += p and a
        n_pred += p
        n_true += a
    return tp, n_pred, n_true


@dataclass(frozen=True)
class FrameMetrics:
    """Accuracy and cost of one frame's motion estimate.

    Attributes:
        rot_err_deg: geodesic rotation error in degrees.
        trans_err_m: translation error in metres.
        t_true_norm_m: norm of the true translation in metres.
        success: status ok and both errors under the module thresholds.
        precision, recall: of the estimated inlier mask against the labels.
        n_inliers: number of correspondences the estimate marks as inliers.
        n_hypotheses, n_scored, n_point_checks: estimator effort counters.
        time_s: estimator wall time in seconds.
        status: ``"ok"`` or the estimator's failure reason.
    """

    rot_err_deg: float
    trans_err_m: float
    t_true_norm_m: float
    success: bool
    precision: float
    recall: float
    n_inliers: int
    n_hypotheses: int
    n_scored: int
    n_point_checks: int
    time_s: float
    status: str

    def as_dict(self) -> dict[str, Any]:
        # Every field is a scalar: a shallow dict equals asdict() without its recursive copying; the
        # names are the class's fields, read once (dataclasses.fields() costs as much as the dict).
        names = type(self).__dict__.get("_field_names")
        if names is None:
            names = tuple(f.name for f in fields(self))
            setattr(type(self), "_field_names", names)
        return {name: getattr(self, name) for name in names}


def _norm(t: Any) -> float:
    """``float(np.linalg.norm(t))``; for a contiguous 1-D float64 array without its wrapper: the norm
    is then ``sqrt(t.dot(t))`` (the same dot, and a correctly rounded root in both)."""
    if type(t) is np.ndarray and t.dtype == np.float64 and t.ndim == 1 and t.flags.c_contiguous:
        return math.sqrt(float(t.dot(t)))
    return float(np.linalg.norm(t))


def frame_metrics(estimate: Any, truth: Any) -> FrameMetrics:
    """Compare a ``MotionEstimate`` with a ``FrameTruth``.

    ``estimate`` needs ``rotation (3,3)``, ``translation (3,)``, ``inliers (N,)``,
    ``status`` and the effort counters; ``truth`` needs ``rotation``,
    ``translation`` and ``inlier (N,)``.

    Raises:
        ValueError: ``estimate`` or ``truth`` lacks one of those attributes (naming the argument).
    """
    try:
        return _frame_metrics(estimate, truth)
    except AttributeError:
        for name, value, fields in (("estimate", estimate, _ESTIMATE_FIELDS), ("truth", truth, _TRUTH_FIELDS)):
            missing = [f for f in fields if not hasattr(value, f)]
            if missing:
                raise ValueError(f"frame_metrics: {name} must have {', '.join(fields)}; "
                                 f"{type(value).__name__} lacks {', '.join(missing)}") from None
        raise


_ESTIMATE_FIELDS = ("rotation", "translation", "inliers", "status", "n_hypotheses", "n_scored", "n_point_checks",
                    "time_s")
_TRUTH_FIELDS = ("rotation", "translation", "inlier")


def _frame_metrics(estimate: Any, truth: Any) -> FrameMetrics:
    rot_err = float(rotation_error(estimate.rotation, truth.rotation))
    trans_err = float(translation_error(estimate.translation, truth.translation))
    t_norm = _norm(truth.translation)
    status = str(estimate.status)
    tp, n_pred, n_true = _mask_counts(estimate.inliers, truth.inlier)
    precision, recall = (tp / n_pred if n_pred else 0.0), (tp / n_true if n_true else 0.0)  # inlier_precision_recall
    return FrameMetrics(
        rot_err_deg=math.degrees(rot_err),  # np.rad2deg's product by 180 / pi, on a float
        trans_err_m=trans_err,
        t_true_norm_m=t_norm,
        success=bool(status == "ok" and _is_success_scalar(rot_err, trans_err, t_norm)),
        precision=precision,
        recall=recall,
        n_inliers=n_pred,  # np.count_nonzero(estimate.inliers): nonzero is True as bool
        n_hypotheses=int(estimate.n_hypotheses),
        n_scored=int(estimate.n_scored),
        n_point_checks=int(estimate.n_point_checks),
        time_s=float(estimate.time_s),
        status=status,
    )


# --------------------------------------------------------------------------- trajectories


def _check_poses(est: np.ndarray, true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    est = np.asarray(est, dtype=float)
    true = np.asarray(true, dtype=float)
    if est.ndim != 3 or est.shape[1:] != (4, 4) or est.shape != true.shape:
        raise ValueError(f"expected two (F, 4, 4) pose arrays of equal length, got {est.shape} and {true.shape}")
    return est, true


def align_se3(est_positions: np.ndarray, true_positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid alignment (no scale) of estimated onto true positions (Horn / Umeyama).

    Args:
        est_positions, true_positions: ``(F, 3)`` in metres, ``F >= 1``.

    Returns:
        ``(R (3, 3), t (3,))`` minimising ``sum ||R p_est + t - p_true||^2``, det R = +1.
    """
    P = np.asarray(est_positions, dtype=float)
    Q = np.asarray(true_positions, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or P.shape != Q.shape or len(P) == 0:
        raise ValueError(f"expected two non-empty (F, 3) position arrays, got {P.shape} and {Q.shape}")
    mu_p, mu_q = P.mean(axis=0), Q.mean(axis=0)
    H = (Q - mu_q).T @ (P - mu_p) / len(P)
    U, _, Vt = np.linalg.svd(H)
    # Reflection guard: flip the weakest axis so that det R = +1.
    S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0])
    R = U @ S @ Vt
    return R, mu_q - R @ mu_p


def ate(est: np.ndarray, true: np.ndarray, align: bool = True) -> float:
    """Absolute trajectory error: RMSE in metres of camera positions.

    Args:
        est, true: ``(F, 4, 4)`` camera-to-world poses.
        align: first align ``est`` onto ``true`` with :func:`align_se3` (as
            ``evo_ape --align``); otherwise compare raw positions (both
            trajectories start at the same pose in this project).
    """
    est, true = _check_poses(est, true)
    p_est, p_true = est[:, :3, 3], true[:, :3, 3]
    if align:
        R, t = align_se3(p_est, p_true)
        p_est = p_est @ R.T + t
    return float(np.sqrt(np.mean(np.sum((p_est - p_true) ** 2, axis=1))))


def _relative(poses: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Relative poses ``inv(P_i) @ P_j`` ``(S, 4, 4)``."""
    return invert_transform(poses[i]) @ poses[j]


def rpe(est: np.ndarray, true: np.ndarray, delta: int = 1) -> tuple[float, float]:
    """Relative pose error over frame pairs ``(i, i + delta)`` (evo's RPE definition).

    The error pose is ``inv(inv(Q_i) Q_j) @ inv(P_i) P_j`` for true ``Q`` and estimated ``P``.

    Returns:
        ``(translation RMSE in metres, rotation RMSE in degrees)``; NaN when
        the trajectory has no pair ``delta`` frames apart.
    """
    est, true = _check_poses(est, true)
    if delta < 1:
        raise ValueError(f"delta must be a positive number of frames, got {delta}")
    if len(est) <= delta:
        return float("nan"), float("nan")
    i = np.arange(len(est) - delta)
    E = invert_transform(_relative(true, i, i + delta)) @ _relative(est, i, i + delta)
    t_rmse = np.sqrt(np.mean(np.sum(E[:, :3, 3] ** 2, axis=1)))
    r_rmse = np.sqrt(np.mean(rotation_angle(E[:, :3, :3]) ** 2))
    return float(t_rmse), float(np.rad2deg(r_rmse))


def path_lengths(poses: np.ndarray) -> np.ndarray:
    """Cumulative travelled distance ``(F,)`` in metres along camera positions, 0 at frame 0."""
    p = np.asarray(poses, dtype=float)[:, :3, 3]
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def kitti_drift(
    est: np.ndarray,
    true: np.ndarray,
    lengths: Sequence[float] = KITTI_LENGTHS,
    step: int = KITTI_STEP,
) -> tuple[float, float, int]:
    """KITTI odometry-benchmark segment drift.

    For every start frame ``0, step, 2 step, ...`` and every length ``L``, the
    segment ends at the first frame whose true path length from the start
    reaches ``L`` (>=; the devkit's strict > differs only on exact ties); its error pose is
    ``inv(inv(P_s) P_e) @ inv(Q_s) Q_e`` for estimated ``P`` and true ``Q``, in the devkit's order;
    :func:`rpe` follows evo and inverts the true segment instead. An error pose and its inverse have
    the same translation length and angle, so the order changes neither metric.
    Segments that would run past the end are skipped. Errors are averaged
    over all segments (all lengths pooled, as the devkit does per sequence).

    Returns:
        ``(translational error in % of segment length, rotational error in
        deg/m, number of segments)``; ``(nan, nan, 0)`` when no segment fits
        (the trajectory is shorter than the shortest length). Many papers quote
        rotation in deg/100 m: multiply by 100.
    """
    est, true = _check_poses(est, true)
    if step < 1:
        raise ValueError(f"step must be a positive number of frames, got {step}")
    lengths_arr = np.asarray(lengths, dtype=float).ravel()
    if lengths_arr.size == 0 or np.any(~(lengths_arr > 0)):
        raise ValueError(f"segment lengths must be positive metres, got {lengths!r}")
    dist = path_lengths(true)
    starts = np.arange(0, len(true), step)
    # One row per (start, length): first frame whose distance reaches start + length.
    s = np.repeat(starts, lengths_arr.size)
    L = np.tile(lengths_arr, starts.size)
    e = np.searchsorted(dist, dist[s] + L, side="left")
    valid = e < len(true)
    if not np.any(valid):
        return float("nan"), float("nan"), 0
    s, e, L = s[valid], e[valid], L[valid]
    E = invert_transform(_relative(est, s, e)) @ _relative(true, s, e)
    t_err = np.linalg.norm(E[:, :3, 3], axis=1) / L
    r_err = rotation_angle(E[:, :3, :3]) / L
    return float(100.0 * t_err.mean()), float(np.rad2deg(r_err.mean())), int(s.size)


@dataclass(frozen=True)
class TrajectoryMetrics:
    """Whole-trajectory accuracy.

    Attributes:
        n_poses: number of poses compared (frames + 1).
        path_length_m: true travelled distance in metres.
        ate_raw_m, ate_aligned_m: position RMSE in metres without / with SE(3) alignment.
        rpe_trans_m, rpe_rot_deg: frame-to-frame relative pose RMSE (m, deg).
        kitti_t_percent, kitti_r_deg_per_m: KITTI segment drift (NaN if too short).
        kitti_segments: number of KITTI segments averaged.
    """

    n_poses: int
    path_length_m: float
    ate_raw_m: float
    ate_aligned_m: float
    rpe_trans_m: float
    rpe_rot_deg: float
    kitti_t_percent: float
    kitti_r_deg_per_m: float
    kitti_segments: int

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def trajectory_metrics(
    est: np.ndarray,
    true: np.ndarray,
    kitti_lengths: Sequence[float] = KITTI_LENGTHS,
    kitti_step: int = KITTI_STEP,
) -> TrajectoryMetrics:
    """All trajectory metrics of ``(F, 4, 4)`` estimated vs true camera-to-world poses."""
    est, true = _check_poses(est, true)
    rpe_t, rpe_r = rpe(est, true, delta=1)
    kt, kr, ks = kitti_drift(est, true, lengths=kitti_lengths, step=kitti_step)
    return TrajectoryMetrics(
        n_poses=len(est),
        path_length_m=float(path_lengths(true)[-1]),
        ate_raw_m=ate(est, true, align=False),
        ate_aligned_m=ate(est, true, align=True),
        rpe_trans_m=rpe_t,
        rpe_rot_deg=rpe_r,
        kitti_t_percent=kt,
        kitti_r_deg_per_m=kr,
        kitti_segments=ks,
    )
