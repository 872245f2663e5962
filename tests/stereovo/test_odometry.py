"""Frame-to-frame odometry: accuracy on a short car run, drift, determinism, pose chaining, fallback,
covariances."""

from __future__ import annotations

import numpy as np
import pytest

import stereovo.odometry as odometry
from stereovo.estimation import MotionEstimate
from stereovo.metrics import trajectory_metrics
from stereovo.odometry import run_odometry
from stereovo.plotting import plot_odometry
from stereovo.simulation import Sequence, SimulationConfig


SHORT_LENGTHS = (5.0, 10.0, 20.0)  # a 30-frame car run covers ~30 m


@pytest.fixture(scope="module")
def sequence() -> Sequence:
    config = SimulationConfig(preset="car", n_frames=30, n_correspondences=300, outlier_ratio=0.5)
    return Sequence(config, seed=1)


@pytest.fixture(scope="module")
def result(sequence):
    return run_odometry(sequence, seed=0, kitti_lengths=SHORT_LENGTHS, kitti_step=5)


def oracle_estimate(frame, fail: bool = False) -> MotionEstimate:
    """What a perfect estimator would return for this frame (or a failure)."""
    truth = frame.truth
    if fail:
        return MotionEstimate(
            rotation=np.eye(3), translation=np.zeros(3), inliers=np.zeros(frame.n, bool),
            status="failed: no consensus", n_hypotheses=10, n_scored=10, n_point_checks=100,
            time_s=0.0, method="oracle",
        )
    return MotionEstimate(
        rotation=truth.rotation, translation=truth.translation, inliers=truth.inlier.copy(),
        status="ok", n_hypotheses=1, n_scored=1, n_point_checks=frame.n, time_s=0.0, method="oracle",
    )


class Recording:
    """A sequence that notes each frame under its ``prev`` array, so a fake estimator knows its frame."""

    def __init__(self, seq, frames_by_prev):
        self.seq, self.true_poses, self.frames_by_prev = seq, seq.true_poses, frames_by_prev

    def __len__(self):
        return len(self.seq)

    def __iter__(self):
        for frame in self.seq:
            self.frames_by_prev[id(frame.prev)] = frame
            yield frame


def patch_estimator(monkeypatch, fail_frames=(), calls=None):
    """Replace the estimator inside odometry by the oracle, failing on the given frame indices."""
    frames_by_prev = {}

    def fake(prev, curr, camera, **kwargs):
        frame = frames_by_prev[id(prev)]
        if calls is not None:
            calls.append((frame, kwargs))
        return oracle_estimate(frame, fail=frame.index in fail_frames)

    monkeypatch.setattr(odometry, "estimate_motion", fake)
    return lambda seq: Recording(seq, frames_by_prev)


def _roll(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def test_short_car_run_is_accurate(result, sequence):
    F = len(sequence)
    assert result.poses.shape == result.true_poses.shape == (F + 1, 4, 4)
    np.testing.assert_array_equal(result.true_poses, sequence.true_poses)
    np.testing.assert_array_equal(result.poses[0], np.eye(4))
    assert result.n_frames == F and result.frame_indices.tolist() == list(range(1, F + 1))
    success = result.column("success")
    assert success.mean() >= 0.9
    assert result.n_failed <= 2
    assert np.median(result.column("rot_err_deg")) < 0.2
    assert np.median(result.column("trans_err_m")) < 0.05
    assert result.column("precision").mean() > 0.9  # outliers at eps 0.5 are rejected
    traj = result.trajectory
    assert traj.kitti_segments > 0
    assert traj.kitti_t_percent < 2.0 and traj.kitti_r_deg_per_m < 0.05
    assert traj.ate_aligned_m < 0.2 and traj.ate_aligned_m <= traj.ate_raw_m + 1e-12
    assert 20 < traj.path_length_m < 45


def test_same_seed_identical_other_seed_differs(result, sequence):
    again = run_odometry(sequence, seed=0, kitti_lengths=SHORT_LENGTHS, kitti_step=5)
    np.testing.assert_array_equal(again.poses, result.poses)
    assert [m.n_hypotheses for m in again.frames] == [m.n_hypotheses for m in result.frames]
    other = run_odometry(sequence, seed=7, kitti_lengths=SHORT_LENGTHS, kitti_step=5)
    assert not np.array_equal(other.poses, result.poses)


def test_perfect_motions_reproduce_true_trajectory(monkeypatch, sequence):
    # Checks the chaining convention: true motions must rebuild the true poses.
    recording = patch_estimator(monkeypatch)
    res = run_odometry(recording(sequence), method="oracle", kitti_lengths=SHORT_LENGTHS)
    np.testing.assert_allclose(res.poses, sequence.true_poses, atol=1e-9)
    assert res.n_failed == 0 and all(m.success for m in res.frames)
    assert all(m.precision == 1.0 and m.recall == 1.0 for m in res.frames)
    assert res.trajectory.ate_raw_m < 1e-9


def test_failed_frames_reuse_previous_motion(monkeypatch, sequence):
    recording = patch_estimator(monkeypatch, fail_frames={1, 5, 6})
    res = run_odometry(recording(sequence), method="oracle")
    true = sequence.true_poses
    assert res.n_failed == 3
    assert np.flatnonzero(res.fallback).tolist() == [0, 4, 5]
    # Frame 1 failed with no history: identity motion, the camera stays put.
    np.testing.assert_allclose(res.poses[1], res.poses[0], atol=1e-12)
    # Frames 5 and 6 repeat frame 4's (true) motion.
    step4 = np.linalg.inv(true[3]) @ true[4]
    np.testing.assert_allclose(np.linalg.inv(res.poses[4]) @ res.poses[5], step4, atol=1e-9)
    np.testing.assert_allclose(np.linalg.inv(res.poses[5]) @ res.poses[6], step4, atol=1e-9)
    # Frame metrics score the estimator's own (failed) output.
    assert not res.frames[4].success and res.frames[4].status.startswith("failed")
    rows = res.rows()
    assert len(rows) == len(sequence)
    assert [r["frame"] for r in rows[:3]] == [1, 2, 3]
    assert rows[4]["fallback"] is True and rows[3]["fallback"] is False
    assert {"rot_err_deg", "trans_err_m", "precision", "recall", "n_hypotheses", "status"} <= set(rows[0])
    assert res.summary()["failed_frames"] == 3


def test_priors_and_order_functions_reach_the_estimator(monkeypatch, sequence):
    calls = []
    recording = patch_estimator(monkeypatch, calls=calls)
    run_odometry(recording(sequence), method="oracle", priors_fn=lambda f: f.scores, budget=50)
    assert len(calls) == len(sequence)
    for frame, kwargs in calls:
        assert kwargs["priors"] is frame.scores and kwargs["order"] is None
        assert kwargs["budget"] == 50 and kwargs["noise_sigma"] == frame.noise_sigma
        assert isinstance(kwargs["rng"], np.random.Generator)
    # One stream for the whole run: every frame gets the same generator object.
    assert len({id(kwargs["rng"]) for _, kwargs in calls}) == 1
    calls.clear()
    run_odometry(recording(sequence), method="oracle", order_fn=lambda f: np.argsort(-f.scores), noise_sigma=1.0)
    assert all(kw["priors"] is None and kw["order"].shape == (f.n,) for f, kw in calls)
    assert all(kw["noise_sigma"] == 1.0 for _, kw in calls)
    with pytest.raises(ValueError, match="priors_fn"):
        run_odometry(sequence, priors=np.ones(300))


def test_guided_priors_with_real_estimator(sequence):
    res = run_odometry(sequence, seed=0, priors_fn=lambda f: f.scores, kitti_lengths=SHORT_LENGTHS)
    assert res.column("success").mean() >= 0.9


def test_trajectory_metrics_of_a_biased_straight_run_match_hand_values():
    # True run: 20 steps of 1 m along x, no rotation (21 poses, path 20 m). The estimate
    # over-shoots every step by 0.1 m along x and rolls 0.5 deg about x per step (a roll
    # about the direction of travel leaves the positions on the x axis): positions 1.1 k.
    theta = np.deg2rad(0.5)
    F = 21
    true = np.tile(np.eye(4), (F, 1, 1))
    est = np.tile(np.eye(4), (F, 1, 1))
    for k in range(F):
        true[k, 0, 3] = 1.0 * k
        est[k, 0, 3] = 1.1 * k
        est[k, :3, :3] = _roll(k * theta)
    m = trajectory_metrics(est, true, kitti_lengths=(5.0, 10.0), kitti_step=5)
    assert m.n_poses == 21 and m.path_length_m == pytest.approx(20.0)
    # Raw ATE: errors 0.1 k, k = 0..20: 0.1 sqrt(sum k^2 / 21) = 0.1 sqrt(2870 / 21).
    assert m.ate_raw_m == pytest.approx(0.1 * np.sqrt(2870 / 21), rel=1e-9)  # 1.16905 m
    # Aligned: the best rigid shift removes the mean error, leaving 0.1 (k - 10):
    # 0.1 sqrt((21^2 - 1) / 12) (a rotation cannot undo a scale).
    assert m.ate_aligned_m == pytest.approx(0.1 * np.sqrt(440 / 12), rel=1e-6)  # 0.60553 m
    # RPE per step: inv(true step) @ est step = (roll 0.5 deg, 0.1 m along x) for every pair.
    assert m.rpe_trans_m == pytest.approx(0.1, rel=1e-9)
    assert m.rpe_rot_deg == pytest.approx(0.5, rel=1e-9)
    # KITTI segments: starts 0, 5, 10, 15 for 5 m and 0, 5, 10 for 10 m (the last must end by
    # frame 20): 7 segments; each has an error of 0.1 L m over L m (10 %) and L x 0.5 deg over L m.
    assert m.kitti_segments == 7
    assert m.kitti_t_percent == pytest.approx(10.0, rel=1e-9)
    assert m.kitti_r_deg_per_m == pytest.approx(0.5, rel=1e-9)


def test_result_trajectory_scores_the_chained_estimate(monkeypatch, sequence):
    # An estimator that returns the true rotation and 1.1 x the true translation of each frame:
    # every relative-pose error is then a pure translation of 0.1 |t_k|, so the run's RPE is
    # 0.1 sqrt(mean |t_k|^2) and its rotation RPE 0, numbers taken from the frames' truth only.
    frames_by_prev = {}

    def biased(prev, curr, camera, **kwargs):
        frame = frames_by_prev[id(prev)]
        truth = frame.truth
        return MotionEstimate(
            rotation=truth.rotation, translation=1.1 * truth.translation, inliers=truth.inlier.copy(),
            status="ok", n_hypotheses=1, n_scored=1, n_point_checks=frame.n, time_s=0.0, method="biased")

    monkeypatch.setattr(odometry, "estimate_motion", biased)
    res = run_odometry(Recording(sequence, frames_by_prev), method="biased", kitti_lengths=SHORT_LENGTHS, kitti_step=5)
    steps = np.array([np.linalg.norm(frame.truth.translation) for frame in sequence])
    traj = res.trajectory
    assert traj.n_poses == len(sequence) + 1
    assert traj.path_length_m == pytest.approx(steps.sum(), rel=1e-9)
    assert traj.rpe_trans_m == pytest.approx(0.1 * np.sqrt(np.mean(steps ** 2)), rel=1e-6)
    assert traj.rpe_rot_deg == pytest.approx(0.0, abs=1e-6)
    assert traj.ate_raw_m > 0.05 * steps.sum() / 2  # the 10 % over-shoot accumulates


def test_plot_odometry_writes_png(result, tmp_path):
    path = plot_odometry(result, tmp_path / "plots" / "odometry.png")
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


@pytest.mark.slow
def test_car_sequence_drift_below_two_percent():
    config = SimulationConfig(preset="car", n_frames=500, n_correspondences=500, outlier_ratio=0.5, noise_sigma=0.5)
    result = run_odometry(Sequence(config, seed=7), method="probabilistic", seed=7)
    t_err_percent, r_err_deg_per_m, n_segments = (
        result.trajectory.kitti_t_percent,
        result.trajectory.kitti_r_deg_per_m,
        result.trajectory.kitti_segments,
    )
    assert n_segments > 0
    assert t_err_percent < 2.0
    assert r_err_deg_per_m < 0.01


def test_odometry_result_carries_the_covariances_nan_on_failed_frames():
    from stereovo.odometry import run_odometry
    from stereovo.simulation import Sequence

    sequence = Sequence(SimulationConfig(n_frames=4, n_correspondences=150, outlier_ratio=0.3), seed=1)
    result = run_odometry(sequence, min_inliers=150)  # cannot be met: every frame fails
    assert result.covariances.shape == (4, 6, 6) and np.all(np.isnan(result.covariances))
    good = run_odometry(sequence)
    assert np.all(np.isfinite(good.covariances))


def test_summary_medians_of_a_skewed_set_of_frames():
    # Hand-made frames whose errors are skewed by one bad frame: the summary's medians are medians
    # (0.25 deg, 0.025 m), not the means the outlier drags up (2.575 deg, 0.265 m).
    from stereovo.metrics import FrameMetrics

    rot = [0.1, 0.2, 0.3, 9.7]  # median 0.25, mean 2.575
    trans = [0.01, 0.02, 0.03, 1.0]  # median 0.025, mean 0.265
    hyps = [10, 20, 30, 1000]  # median 25
    frames = [FrameMetrics(rot_err_deg=r, trans_err_m=t, t_true_norm_m=1.0, success=r < 1.0, precision=1.0,
                           recall=0.5, n_inliers=100, n_hypotheses=h, n_scored=h, n_point_checks=100 * h,
                           time_s=1e-3 * h, status="ok")
              for r, t, h in zip(rot, trans, hyps)]
    poses = np.tile(np.eye(4), (5, 1, 1))
    res = odometry.OdometryResult(method="ransac", seed=0, poses=poses, true_poses=poses, frames=frames,
                                  fallback=np.zeros(4, bool), trajectory=trajectory_metrics(poses, poses),
                                  frame_indices=np.arange(1, 5))
    s = res.summary()
    assert s["frames"] == 4 and s["failed_frames"] == 0 and s["success_rate"] == pytest.approx(0.75)
    assert s["median_rot_err_deg"] == pytest.approx(0.25)
    assert s["median_trans_err_m"] == pytest.approx(0.025)
    assert s["median_hypotheses"] == pytest.approx(25.0)
    assert s["median_time_s"] == pytest.approx(0.025)
