"""Per-frame and trajectory metrics on hand-built cases with known answers."""

from __future__ import annotations

from types import SimpleNamespace

import math

import numpy as np
import pytest

from stereovo.geometry import make_transform, pose_update, so3_exp
from stereovo.metrics import (
    SUCCESS_ROT_DEG,
    SUCCESS_TRANS_M,
    SUCCESS_TRANS_REL,
    align_se3,
    ate,
    frame_metrics,
    inlier_precision_recall,
    is_success,
    kitti_drift,
    path_lengths,
    rpe,
    trajectory_metrics,
)


def car_trajectory(n: int, seed: int = 0, step: float = 1.0, yaw_sigma: float = 0.02) -> np.ndarray:
    """(n+1, 4, 4) camera-to-world poses driving forward (+z) with gentle random yaw."""
    rng = np.random.default_rng(seed)
    poses = [np.eye(4)]
    for _ in range(n):
        R = so3_exp(np.array([0.0, rng.normal(0, yaw_sigma), 0.0]))
        # The camera moves forward by `step`, so points move backwards in its frame.
        poses.append(pose_update(poses[-1], R, np.array([0.0, 0.0, -step])))
    return np.stack(poses)


def rigidly_moved(poses: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    return make_transform(R, t) @ poses


def estimate(R, t, inliers, status="ok"):
    return SimpleNamespace(
        rotation=R, translation=t, inliers=np.asarray(inliers, bool), status=status,
        n_hypotheses=7, n_scored=5, n_point_checks=1234, time_s=0.01,
    )


def truth(R, t, inlier):
    return SimpleNamespace(rotation=R, translation=t, inlier=np.asarray(inlier, bool))


# ----------------------------------------------------------------------------- per frame


def test_precision_recall_hand_built_masks():
    pred = np.array([1, 1, 1, 0, 0, 1], bool)
    true = np.array([1, 0, 1, 1, 0, 1], bool)
    p, r = inlier_precision_recall(pred, true)
    assert p == pytest.approx(3 / 4)
    assert r == pytest.approx(3 / 4)
    assert inlier_precision_recall(np.zeros(4, bool), np.ones(4, bool)) == (0.0, 0.0)
    assert inlier_precision_recall(np.ones(4, bool), np.zeros(4, bool)) == (0.0, 0.0)
    assert inlier_precision_recall(true, true) == (1.0, 1.0)
    with pytest.raises(ValueError, match=r"inlier masks differ in shape: \(3,\) vs \(4,\)"):
        inlier_precision_recall(np.ones(3, bool), np.ones(4, bool))


def test_success_thresholds():
    rot_lim = np.deg2rad(SUCCESS_ROT_DEG)
    # Absolute floor applies for small motions, relative bound for large ones.
    assert is_success(0.5 * rot_lim, 0.049, 0.1)
    assert not is_success(0.5 * rot_lim, 0.051, 0.1)
    assert is_success(0.5 * rot_lim, 0.09, 2.0)  # 0.05 * 2 m = 0.1 m
    assert not is_success(0.5 * rot_lim, 0.11, 2.0)
    assert not is_success(1.01 * rot_lim, 0.0, 1.0)
    assert not is_success(np.nan, 0.0, 1.0)
    vec = is_success(np.array([0.0, 2 * rot_lim, 0.0]), np.array([0.0, 0.0, 1.0]), 1.0)
    assert vec.tolist() == [True, False, False]
    assert SUCCESS_TRANS_M == 0.05 and SUCCESS_TRANS_REL == 0.05


def test_frame_metrics_values_and_status():
    R_true = so3_exp(np.array([0.0, 0.1, 0.0]))
    t_true = np.array([0.0, 0.0, -1.0])
    R_est = so3_exp(np.array([0.0, 0.1 + np.deg2rad(0.5), 0.0]))
    t_est = t_true + np.array([0.03, 0.0, 0.0])
    tr = truth(R_true, t_true, [1, 1, 0, 0])
    m = frame_metrics(estimate(R_est, t_est, [1, 0, 1, 0]), tr)
    assert m.rot_err_deg == pytest.approx(0.5, abs=1e-9)
    assert m.trans_err_m == pytest.approx(0.03)
    assert m.t_true_norm_m == pytest.approx(1.0)
    assert m.success
    assert (m.precision, m.recall, m.n_inliers) == (0.5, 0.5, 2)
    # Asymmetric: 3 returned inliers, 2 of them true, of 4 true: precision 2/3, recall 1/2.
    tr4 = truth(R_true, t_true, [1, 1, 1, 1, 0])
    m = frame_metrics(estimate(R_est, t_est, [1, 1, 0, 0, 1]), tr4)
    assert (m.precision, m.recall, m.n_inliers) == (pytest.approx(2 / 3), 0.5, 3)
    assert (m.n_hypotheses, m.n_scored, m.n_point_checks, m.status) == (7, 5, 1234, "ok")
    # A failed status is never a success, even with a perfect motion.
    failed = frame_metrics(estimate(R_true, t_true, [0, 0, 0, 0], status="no consensus"), tr)
    assert not failed.success and failed.precision == 0.0 and failed.status == "no consensus"
    # 0.06 m off on a 1 m motion exceeds max(0.05, 0.05 * 1).
    assert not frame_metrics(estimate(R_true, t_true + [0.06, 0, 0], [1, 1, 0, 0]), tr).success


# ----------------------------------------------------------------------------- trajectories


def test_align_se3_recovers_rigid_transform():
    rng = np.random.default_rng(1)
    P = rng.normal(size=(50, 3))
    R = so3_exp(np.array([0.3, -0.5, 1.1]))
    t = np.array([1.0, -2.0, 3.0])
    R_hat, t_hat = align_se3(P, P @ R.T + t)
    np.testing.assert_allclose(R_hat, R, atol=1e-12)
    np.testing.assert_allclose(t_hat, t, atol=1e-12)
    assert np.linalg.det(R_hat) == pytest.approx(1.0)


def test_ate_rigid_offset_aligned_zero_raw_positive():
    true = car_trajectory(80)
    est = rigidly_moved(true, so3_exp(np.array([0.0, 0.2, 0.05])), np.array([2.0, 0.5, -1.0]))
    assert ate(est, true, align=True) < 1e-9
    assert ate(est, true, align=False) > 1.0
    assert ate(true, true, align=False) == 0.0


def test_ate_known_value_constant_offset():
    true = car_trajectory(20)
    est = true.copy()
    est[:, 0, 3] += 0.3  # a translation offset, removed by alignment
    assert ate(est, true, align=False) == pytest.approx(0.3)
    assert ate(est, true, align=True) == pytest.approx(0.0, abs=1e-9)


def test_rpe_identical_zero_and_known_step_error():
    true = car_trajectory(50)
    t_err, r_err = rpe(true, true)
    # arccos near 1 resolves angles only to ~1e-8 rad, hence the rotation tolerance.
    assert t_err < 1e-12 and r_err < 1e-5
    # Rigidly moved trajectories have the same relative poses.
    moved = rigidly_moved(true, so3_exp(np.array([0.1, 0.2, 0.3])), np.ones(3))
    t_err, r_err = rpe(moved, true)
    assert t_err < 1e-9 and r_err < 1e-5
    # Every estimated step 10 % too long -> relative translation error 0.1 m per 1 m step.
    est = true.copy()
    est[:, :3, 3] *= 1.1
    t_err, r_err = rpe(est, true)
    assert t_err == pytest.approx(0.1, rel=1e-9)
    assert r_err == pytest.approx(0.0, abs=1e-5)
    assert np.isnan(rpe(true[:1], true[:1])[0])


def test_kitti_drift_one_percent_scale_error():
    # A straight drive: chord = path length, so a 1 % scale error is 1 % drift.
    true = car_trajectory(300, yaw_sigma=0.0)
    est = true.copy()
    est[:, :3, 3] *= 1.01
    t_pct, r_deg_m, n = kitti_drift(est, true)
    assert t_pct == pytest.approx(1.0, rel=1e-9)
    assert r_deg_m == pytest.approx(0.0, abs=1e-9)
    # Starts every 10 frames; 100 m segments end 100 frames later, etc.
    expected = sum(len(range(0, 301 - L, 10)) for L in (100, 200, 300))
    assert n == expected
    # With gentle turns the scale error still shows as ~1 % (chords ~ path lengths).
    curvy = car_trajectory(300, seed=3, yaw_sigma=0.01)
    est_c = curvy.copy()
    est_c[:, :3, 3] *= 1.01
    t_pct_c, _, _ = kitti_drift(est_c, curvy)
    assert 0.9 < t_pct_c <= 1.0 + 1e-9


def test_kitti_drift_rotational_error_units():
    # A constant yaw bias of b rad per frame on a straight 1 m/frame drive:
    # a segment of L metres accumulates L*b rad, i.e. b rad/m.
    n, bias = 250, np.deg2rad(0.01)
    true = car_trajectory(n, yaw_sigma=0.0)
    est = [np.eye(4)]
    for _ in range(n):
        est.append(pose_update(est[-1], so3_exp(np.array([0.0, bias, 0.0])), np.array([0.0, 0.0, -1.0])))
    _, r_deg_m, n_seg = kitti_drift(np.stack(est), true, lengths=(100, 200))
    assert n_seg > 0
    assert r_deg_m == pytest.approx(0.01, rel=1e-6)


def test_kitti_drift_short_trajectory_and_custom_lengths():
    true = car_trajectory(30, yaw_sigma=0.0)
    est = true.copy()
    est[:, :3, 3] *= 1.02
    t_pct, r_deg_m, n = kitti_drift(est, true)
    assert n == 0 and np.isnan(t_pct) and np.isnan(r_deg_m)
    t_pct, _, n = kitti_drift(est, true, lengths=(5, 10, 20), step=5)
    assert n > 0 and t_pct == pytest.approx(2.0, rel=1e-9)
    with pytest.raises(ValueError, match=r"segment lengths must be positive metres, got \(0\.0,\)"):
        kitti_drift(est, true, lengths=(0.0,))
    with pytest.raises(ValueError, match=r"^step must be a positive number of frames, got 0$"):
        kitti_drift(est, true, step=0)
    unequal = r"two \(F, 4, 4\) pose arrays of equal length, got \(31, 4, 4\) and \(30, 4, 4\)"
    with pytest.raises(ValueError, match=unequal):
        kitti_drift(est, true[:-1])


def test_trajectory_metrics_bundle():
    true = car_trajectory(120, yaw_sigma=0.0)
    est = true.copy()
    est[:, :3, 3] *= 1.01
    m = trajectory_metrics(est, true)
    assert m.n_poses == 121
    assert m.path_length_m == pytest.approx(120.0)
    assert path_lengths(true)[-1] == pytest.approx(120.0)
    # Frame k is 0.01 k m ahead of the truth along the straight path: RMS over k = 0..120 is
    # 0.01 sqrt(sum k^2 / 121) = 0.01 sqrt(120 * 241 / 6) = 0.6943 m; the best rigid alignment shifts by the
    # mean error, leaving 0.01 sqrt(mean (k - 60)^2) = 0.01 sqrt((121^2 - 1) / 12) = 0.3493 m.
    assert m.ate_raw_m == pytest.approx(0.01 * np.sqrt(120 * 241 / 6), rel=1e-9)
    assert m.ate_aligned_m == pytest.approx(0.01 * np.sqrt((121**2 - 1) / 12), rel=1e-6)
    assert m.rpe_trans_m == pytest.approx(0.01)
    assert m.rpe_rot_deg == pytest.approx(0.0, abs=1e-9)
    assert m.kitti_segments == 3  # 100 m segments from frames 0, 10, 20
    assert m.kitti_t_percent == pytest.approx(1.0)
    assert set(m.as_dict()) >= {"ate_raw_m", "kitti_t_percent", "kitti_r_deg_per_m"}


def test_frame_metrics_scalar_success_test_is_is_success():
    """frame_metrics decides success on floats: the same as the vectorised is_success, bounds and NaN included."""
    import itertools
    import math

    from stereovo.metrics import SUCCESS_TRANS_M, SUCCESS_TRANS_REL, _is_success_scalar, is_success

    rot = [0.0, math.radians(1.0), np.nextafter(math.radians(1.0), 0.0), 0.5, math.nan, math.inf]
    trans = [0.0, SUCCESS_TRANS_M, np.nextafter(SUCCESS_TRANS_M, 0.0), 0.06, 0.1, math.nan, math.inf]
    norms = [0.0, 1.0, SUCCESS_TRANS_M / SUCCESS_TRANS_REL, 2.0, 1e6, math.nan, math.inf, -1.0]
    for r, t, n in itertools.product(rot, trans, norms):
        assert _is_success_scalar(float(r), float(t), float(n)) == bool(is_success(r, t, n)), (r, t, n)


def test_mask_counts_are_numpys_counts():
    from stereovo.metrics import _mask_counts, inlier_precision_recall

    rng = np.random.default_rng(2)
    for _ in range(300):
        n = int(rng.integers(0, 700))
        p, a = rng.random(n) < rng.random(), rng.random(n) < rng.random()
        want = (int(np.count_nonzero(p & a)), int(np.count_nonzero(p)), int(np.count_nonzero(a)))
        assert _mask_counts(p, a) == want
        assert _mask_counts(p.astype(np.int64) * 3, a.tolist()) == want  # other types: numpy's reading
        assert _mask_counts(p[::-1], a[::-1]) == want  # strided
    assert inlier_precision_recall(np.zeros(4, bool), np.zeros(4, bool)) == (0.0, 0.0)
    with pytest.raises(ValueError, match="differ in shape"):
        _mask_counts(np.zeros(3, bool), np.zeros(4, bool))


def test_the_truths_norm_is_numpys():
    from stereovo.metrics import _norm

    rng = np.random.default_rng(3)
    for _ in range(20000):
        t = rng.standard_normal(3) * 10.0 ** rng.integers(-8, 8, 3)
        assert _norm(t) == float(np.linalg.norm(t))
    for t in (np.zeros(3), np.array([-0.0, 0.0, -0.0]), np.array([np.nan, 1.0, 0.0]), np.array([np.inf, 1.0, 0.0]),
              np.array([1e200, 1e200, 0.0]), np.arange(6.0)[::2], [3.0, 4.0, 0.0], np.array([3, 4, 0])):
        with np.errstate(over="ignore"):  # 1e200 squared: both warn alike
            ours, want = _norm(t), float(np.linalg.norm(t))
        assert ours == want or (math.isnan(ours) and math.isnan(want))


def test_frame_metrics_names_the_argument_that_is_not_an_estimate_or_a_truth():
    from stereovo.metrics import frame_metrics
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=50), 1)
    from stereovo import estimate_motion

    est = estimate_motion(frame.prev, frame.curr, frame.camera, rng=0)
    with pytest.raises(ValueError, match=r"frame_metrics: truth must have rotation, translation, inlier; "
                                         r"NoneType lacks rotation, translation, inlier"):
        frame_metrics(est, None)
    with pytest.raises(ValueError, match=r"frame_metrics: estimate must have .*; FrameTruth lacks inliers, status"):
        frame_metrics(frame.truth, frame.truth)


# ----------------------------------------------------------------------------- closed-form trajectory cases


def _straight_drive(steps, yaws=None) -> np.ndarray:
    """Camera-to-world poses of a drive along +z with per-frame step lengths ``steps`` (m) and per-frame
    yaw motions ``yaws`` (rad, about the camera's y axis; none by default)."""
    yaws = np.zeros(len(steps)) if yaws is None else yaws
    poses = [np.eye(4)]
    for step, yaw in zip(steps, yaws):
        poses.append(pose_update(poses[-1], so3_exp(np.array([0.0, yaw, 0.0])), np.array([0.0, 0.0, -step])))
    return np.stack(poses)


def test_kitti_drift_divides_by_the_nominal_segment_length():
    # 3 m a frame: a 100 m segment ends at the first frame whose path length reaches 100 m, 34 frames
    # (102 m) on. The devkit divides the segment's error by the nominal length L = 100 m, not by 102 m.
    n = 60
    true = _straight_drive(np.full(n, 3.0))
    est = true.copy()
    est[:, :3, 3] *= 1.01  # 1 % too long: 1.02 m of error over every 102 m segment
    t_pct, r_deg_m, n_seg = kitti_drift(est, true, lengths=(100.0,), step=1)
    assert n_seg == n + 1 - 34  # starts 0 .. 26 (start + 34 <= 60)
    assert t_pct == pytest.approx(100 * 0.01 * 102 / 100, rel=1e-9)  # 1.02 %, not 1.00 %
    assert r_deg_m == pytest.approx(0.0, abs=1e-9)
    # A constant yaw bias b per frame: 34 b over the segment, per nominal metre: 0.34 b.
    bias = np.deg2rad(0.01)
    est_yaw = _straight_drive(np.full(n, 3.0), np.full(n, bias))
    _, r_deg_m, _ = kitti_drift(est_yaw, true, lengths=(100.0,), step=1)
    assert r_deg_m == pytest.approx(0.01 * 34 / 100, rel=1e-6)


def test_kitti_drift_segment_ends_by_path_length_not_chord():
    # A zigzag: every frame moves 1 m along z and alternately +-1 m along x, so each step is sqrt(2) m of path
    # but the chord grows ~1 m a frame. A 10 m segment by path length ends ceil(10 / sqrt 2) = 8 frames on.
    n = 20
    true = np.tile(np.eye(4), (n + 1, 1, 1))
    true[:, 2, 3] = np.arange(n + 1)
    true[1::2, 0, 3] = 1.0
    est = true.copy()
    est[:, 2, 3] *= 1.01  # 1 % too long along z only: 0.08 m of error over an 8-frame segment
    t_pct, _, n_seg = kitti_drift(est, true, lengths=(10.0,), step=1)
    assert n_seg == n + 1 - 8
    assert t_pct == pytest.approx(100 * 0.01 * 8 / 10, rel=1e-9)


def test_rpe_rotation_is_the_rms_of_known_per_step_errors():
    # Straight 1 m steps; the estimate adds a yaw of 1, 2, 2, 4 degrees to steps 1-4. Each pair's error
    # pose rotates by that angle, and its translation is (I - R^T) t with t perpendicular to the axis:
    # 2 sin(theta / 2) metres. RMS rotation sqrt((1 + 4 + 4 + 16) / 4) = 2.5 deg (the mean would be 2.25).
    theta = np.deg2rad([1.0, 2.0, 2.0, 4.0])
    true = _straight_drive(np.ones(4))
    est = _straight_drive(np.ones(4), theta)
    t_err, r_err = rpe(est, true)
    assert r_err == pytest.approx(2.5, rel=1e-6)
    assert t_err == pytest.approx(np.sqrt(np.mean((2 * np.sin(theta / 2)) ** 2)), rel=1e-9)
    # delta = 2: pairs (0, 2), (1, 3), (2, 4) accumulate 3, 4 and 6 degrees: RMS sqrt(61 / 3).
    _, r_err2 = rpe(est, true, delta=2)
    assert r_err2 == pytest.approx(np.sqrt(61 / 3), rel=1e-6)


def test_align_se3_never_returns_a_reflection():
    # The estimate is the truth mirrored in x. Points on the axes at +-3, +-2, +-1 m: the best orthogonal
    # map would be the mirror diag(-1, 1, 1) (det -1, residual 0); the best rotation (Umeyama's guard flips
    # the weakest axis, z) is diag(-1, 1, -1), a half turn about y, leaving each z coordinate negated.
    a, b, c = 3.0, 2.0, 1.0
    true_p = np.array([[a, 0, 0], [-a, 0, 0], [0, b, 0], [0, -b, 0], [0, 0, c], [0, 0, -c]])
    est_p = true_p * np.array([-1.0, 1.0, 1.0])
    R, t = align_se3(est_p, true_p)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R, np.diag([-1.0, 1.0, -1.0]), atol=1e-12)
    np.testing.assert_allclose(t, np.zeros(3), atol=1e-12)
    # Residual: the two z points land 2c from their truth: RMSE sqrt(2 (2c)^2 / 6) = 2c / sqrt(3).
    true = np.tile(np.eye(4), (6, 1, 1))
    true[:, :3, 3] = true_p
    est = true.copy()
    est[:, :3, 3] = est_p
    assert ate(est, true, align=True) == pytest.approx(2 * c / np.sqrt(3), rel=1e-9)
    # No rotation does better (random rotations, checked by brute force).
    rots = so3_exp(np.random.default_rng(0).normal(size=(2000, 3)) * 2.0)
    residuals = np.sqrt(np.mean(np.sum((est_p @ rots.transpose(0, 2, 1) - true_p) ** 2, axis=2), axis=1))
    assert residuals.min() >= 2 * c / np.sqrt(3) - 1e-12
