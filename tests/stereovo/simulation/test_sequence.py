"""simulate_frame and Sequence (stereovo/simulation/sequence.py): shapes, the true motion, noise,
labels, determinism and the per-frame seeds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import mannwhitneyu

from stereovo.camera import StereoCamera
from stereovo.geometry import pose_update, relative_motion
from stereovo.simulation import Frame, FrameTruth, OutlierKind, Sequence, SimulationConfig, simulate_frame
from tests.support.simulation import NOISE_FREE, WORLD_CASES, predicted_curr


def assert_frames_identical(a: Frame, b: Frame) -> None:
    assert a.index == b.index
    for name in ("prev", "curr", "scores"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for field in dataclasses.fields(FrameTruth):
        assert np.array_equal(getattr(a.truth, field.name), getattr(b.truth, field.name)), field.name


SMALL = SimulationConfig(n_frames=6, n_correspondences=60)


@pytest.mark.parametrize("n", [3, 57, 500])
def test_frame_has_exactly_n_rows_with_documented_shapes(n: int) -> None:
    frame = simulate_frame(SimulationConfig(n_correspondences=n), 1)
    assert frame.n == n and frame.index == 1
    assert frame.prev.shape == frame.curr.shape == (n, 4)
    assert frame.prev.dtype == frame.curr.dtype == frame.scores.dtype == np.float64
    assert frame.scores.shape == (n,)
    truth = frame.truth
    assert truth.inlier.shape == (n,) and truth.inlier.dtype == bool
    assert truth.outlier_kind.shape == (n,) and truth.outlier_kind.dtype == np.int8
    assert truth.rotation.shape == (3, 3) and truth.translation.shape == (3,)
    assert truth.pose_prev.shape == truth.pose_curr.shape == (4, 4)
    assert np.array_equal(truth.inlier, truth.outlier_kind == OutlierKind.INLIER)
    assert frame.noise_sigma == 0.5 and frame.camera == StereoCamera()


@pytest.mark.parametrize("n", [3, 57, 500])
def test_each_inlier_row_is_one_point_seen_twice_under_the_true_motion(n: int) -> None:
    # Noise-free: row i of prev, triangulated, moved by the true (R, t) and projected, is row i of curr
    # exactly for an inlier, and far from it for a random mismatch; the rows are rectified (vL = vR).
    frame = simulate_frame(SimulationConfig(n_correspondences=n, noise_sigma=0.0, outlier_ratio=0.5,
                                            outlier_mix=(1.0, 0.0, 0.0)), 1)
    cam, truth = frame.camera, frame.truth
    assert int(np.count_nonzero(~truth.inlier)) == round(0.5 * n)
    moved = cam.triangulate(frame.prev) @ truth.rotation.T + truth.translation
    error = np.linalg.norm(cam.project(moved) - frame.curr, axis=1)  # px
    assert np.all(error[truth.inlier] < 1e-6)
    assert np.median(error[~truth.inlier]) > 10.0
    np.testing.assert_allclose(frame.prev[:, 1], frame.prev[:, 3], atol=1e-9)
    np.testing.assert_allclose(frame.curr[:, 1], frame.curr[:, 3], atol=1e-9)


def test_epsilon_range_is_drawn_per_frame_within_bounds() -> None:
    config = SimulationConfig(outlier_ratio=(0.2, 0.6), n_frames=8, n_correspondences=200)
    epsilons = []
    for frame in Sequence(config, seed=3):
        eps = frame.truth.outlier_ratio
        assert 0.2 <= eps <= 0.6
        assert np.count_nonzero(~frame.truth.inlier) == round(eps * 200)
        epsilons.append(eps)
    assert len(set(epsilons)) == len(epsilons)


@pytest.mark.parametrize("preset, world", WORLD_CASES)
def test_noise_free_inliers_follow_the_true_motion(preset: str, world: str) -> None:
    frame = simulate_frame(dataclasses.replace(NOISE_FREE, preset=preset, world=world), 4)
    inl = frame.truth.inlier
    X_pred, _ = predicted_curr(frame, inl)
    X_curr = frame.camera.triangulate(frame.curr[inl])
    assert np.max(np.abs(X_curr - X_pred)) < 1e-9
    depths = frame.camera.triangulate(frame.prev[inl])[:, 2]
    assert depths.min() >= 3.0 - 1e-9 and depths.max() <= 60.0 + 1e-9


def test_noise_free_inliers_of_a_sequence_follow_the_true_motion() -> None:
    frame = Sequence(dataclasses.replace(NOISE_FREE, n_frames=30), seed=5).frame(30)
    inl = frame.truth.inlier
    X_pred, _ = predicted_curr(frame, inl)
    assert np.max(np.abs(frame.camera.triangulate(frame.curr[inl]) - X_pred)) < 1e-9


@pytest.mark.parametrize("sigma", [0.5, 3.0])
@pytest.mark.parametrize("world", ["street", "open"])
def test_measurements_are_rectified_in_image_with_valid_disparity(sigma: float, world: str) -> None:
    config = SimulationConfig(noise_sigma=sigma, world=world, outlier_ratio=0.6)
    for seed in range(3):
        frame = simulate_frame(config, seed)
        cam = frame.camera
        for z in (frame.prev, frame.curr):
            assert np.array_equal(z[:, 1], z[:, 3])
            assert cam.in_image(z).all()
            assert np.all(cam.disparity(z) > cam.min_disparity)
        assert np.all((frame.scores > 0) & (frame.scores < 1))


def test_noise_is_gaussian_independent_on_u_and_shared_on_v() -> None:
    # Only the noise level changes: same geometry and standard-normal draws (common random numbers).
    clean = simulate_frame(dataclasses.replace(NOISE_FREE, n_correspondences=1000), 8)
    noisy = simulate_frame(SimulationConfig(noise_sigma=1.0, n_correspondences=1000), 8)
    assert np.array_equal(clean.truth.inlier, noisy.truth.inlier)
    inl = clean.truth.inlier
    diff = np.concatenate([noisy.prev[inl] - clean.prev[inl], noisy.curr[inl] - clean.curr[inl]])
    assert np.array_equal(diff[:, 1], diff[:, 3])
    assert np.std(diff[:, :3], axis=0) == pytest.approx(np.ones(3), abs=0.1)
    assert np.abs(np.mean(diff[:, :3], axis=0)).max() < 0.1
    assert abs(np.corrcoef(diff[:, 0], diff[:, 2])[0, 1]) < 0.1


def test_labels_are_shuffled() -> None:
    frame = simulate_frame(SimulationConfig(), 9)
    inl = frame.truth.inlier
    assert not inl[:250].all()
    assert 0.35 < inl[:250].mean() < 0.65
    assert not np.all(np.diff(frame.truth.outlier_kind) >= 0)


@pytest.mark.parametrize("auc", [0.5, 0.75, 0.95])
def test_match_score_auc_matches_the_config(auc: float) -> None:
    config = SimulationConfig(score_auc=auc, n_correspondences=500)
    frames = [simulate_frame(config, seed) for seed in range(20)]
    scores = np.concatenate([f.scores for f in frames])
    inlier = np.concatenate([f.truth.inlier for f in frames])
    u = mannwhitneyu(scores[inlier], scores[~inlier]).statistic
    assert u / (inlier.sum() * (~inlier).sum()) == pytest.approx(auc, abs=0.02)


def test_simulate_frame_accepts_generator_int_or_none() -> None:
    config = SimulationConfig(n_correspondences=50)
    assert_frames_identical(simulate_frame(config, 5), simulate_frame(config, 5))
    assert_frames_identical(simulate_frame(config, np.random.default_rng(5)), simulate_frame(config, 5))
    assert not np.array_equal(simulate_frame(config, 5).prev, simulate_frame(config, 6).prev)
    assert simulate_frame(config, None).n == 50
    truth = simulate_frame(config, 5).truth
    rotation, translation = relative_motion(truth.pose_prev, truth.pose_curr)
    assert np.allclose(rotation, truth.rotation, atol=1e-12)
    assert np.allclose(translation, truth.translation, atol=1e-12)


def test_sequence_is_lazy_and_random_access_equals_iteration() -> None:
    seq = Sequence(SMALL, seed=7)
    assert len(seq) == 6
    frames = list(seq)
    assert [f.index for f in frames] == [1, 2, 3, 4, 5, 6]
    for k in (6, 2, 4, 1):
        assert_frames_identical(seq.frame(k), frames[k - 1])
    for first, second in zip(frames, seq):
        assert_frames_identical(first, second)
    for bad in (0, 7, -1):
        with pytest.raises(IndexError):
            seq.frame(bad)


def test_sequence_poses_are_consistent_with_frame_truth() -> None:
    seq = Sequence(SMALL, seed=8)
    poses = seq.true_poses
    assert poses.shape == (7, 4, 4)
    assert np.array_equal(poses[0], np.eye(4))
    with pytest.raises(ValueError, match="read-only"):
        poses[1, 0, 0] = 2.0  # read-only: frames are generated from these poses
    for k, frame in enumerate(seq, start=1):
        truth = frame.truth
        assert np.array_equal(truth.pose_prev, poses[k - 1]) and np.array_equal(truth.pose_curr, poses[k])
        R, t = relative_motion(truth.pose_prev, truth.pose_curr)
        assert np.allclose(truth.rotation, R, atol=1e-12) and np.allclose(truth.translation, t, atol=1e-12)
        assert np.max(np.abs(pose_update(poses[k - 1], truth.rotation, truth.translation) - poses[k])) < 1e-9


def test_sequence_determinism() -> None:
    a, b, c = Sequence(SMALL, seed=11), Sequence(SMALL, seed=11), Sequence(SMALL, seed=12)
    assert np.array_equal(a.true_poses, b.true_poses)
    assert not np.array_equal(a.true_poses, c.true_poses)
    assert_frames_identical(a.frame(3), b.frame(3))
    assert not np.array_equal(a.frame(3).prev, c.frame(3).prev)
    assert not np.array_equal(a.frame(3).prev, a.frame(4).prev)
    ss = np.random.SeedSequence(99)
    again = np.random.SeedSequence(99)
    assert_frames_identical(Sequence(SMALL, seed=ss).frame(2), Sequence(SMALL, seed=again).frame(2))
    fresh = Sequence(SMALL)
    assert_frames_identical(fresh.frame(1), Sequence(SMALL, seed=fresh.seed_sequence).frame(1))


def test_longer_sequence_extends_a_shorter_one_with_the_same_seed() -> None:
    short, long = Sequence(SMALL, seed=13), Sequence(dataclasses.replace(SMALL, n_frames=12), seed=13)
    assert np.array_equal(long.true_poses[:7], short.true_poses)
    assert_frames_identical(long.frame(5), short.frame(5))


def test_sequence_frames_use_the_documented_child_seed_sequence():
    """Frame k's generator is SeedSequence(root entropy, spawn_key=(..., namespace, k)), numpy's hashing."""
    from stereovo.simulation.pair import simulate_pair as _simulate_pair
    from stereovo.simulation.sequence import _SEQUENCE_NAMESPACE

    config = SimulationConfig(n_correspondences=60, n_frames=3)
    seq = Sequence(config, seed=2**90 + 17)
    child = np.random.SeedSequence(2**90 + 17, spawn_key=(_SEQUENCE_NAMESPACE, 2))
    expected = _simulate_pair(config, seq.true_poses[1], seq.true_poses[2], 2, np.random.default_rng(child))
    assert_frames_identical(seq.frame(2), expected)


@pytest.mark.parametrize("seed", [0, 7, 2**100 + 5, None, "child", "array"])
def test_sequence_frames_draw_from_their_spawned_seed_sequences(seed):
    """A Sequence seeds every frame's generator ahead (seed_words) as numpy's SeedSequence would, one at a time."""
    from stereovo.simulation import Sequence, SimulationConfig
    from stereovo.simulation.sequence import _SEQUENCE_NAMESPACE

    if seed == "child":
        seed = np.random.SeedSequence(12345).spawn(3)[2]
    elif seed == "array":
        seed = np.random.SeedSequence(np.array([1, 2, 3], dtype=np.uint32))  # numpy's own path
    sequence = Sequence(SimulationConfig(n_frames=6, n_correspondences=30), seed)
    root = sequence.seed_sequence
    for k in (0, 1, 6, 3):
        expected = np.random.default_rng(np.random.SeedSequence(
            root.entropy, spawn_key=(*root.spawn_key, _SEQUENCE_NAMESPACE, k), pool_size=root.pool_size))
        assert sequence._child_rng(k).bit_generator.state == expected.bit_generator.state
