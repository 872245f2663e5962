"""Tests of the synthetic stereo VO simulator (stereovo.simulation)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import mannwhitneyu

from stereovo.camera import StereoCamera
from stereovo.geometry import pose_update, relative_motion, rotation_angle, so3_log, transform_points
from stereovo.simulation import (
    PRESETS,
    Frame,
    FrameTruth,
    OutlierKind,
    Sequence,
    SimulationConfig,
    simulate_frame,
)

NOISE_FREE = SimulationConfig(noise_sigma=0.0)
WORLD_CASES = [("car", "street"), ("car", "open"), ("free", "open"), ("free", "street")]
MIN_OUTLIER_PX = 4.0  # the simulator's promise: outliers sit at least this far (px) from the truth


def kabsch(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rigid (R, t) with Q ~ R P + t."""
    mp, mq = P.mean(axis=0), Q.mean(axis=0)
    U, _, Vt = np.linalg.svd((P - mp).T @ (Q - mq))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, mq - R @ mp


def rows_of(frame: Frame, kind: OutlierKind) -> np.ndarray:
    return frame.truth.outlier_kind == kind


def predicted_curr(frame: Frame, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points at k moved by the true motion from the triangulated k-1 points, and their projections."""
    X = transform_points(frame.truth.rotation, frame.truth.translation, frame.camera.triangulate(frame.prev[rows]))
    return X, frame.camera.project(X)


def assert_frames_identical(a: Frame, b: Frame) -> None:
    assert a.index == b.index
    for name in ("prev", "curr", "scores"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for field in dataclasses.fields(FrameTruth):
        assert np.array_equal(getattr(a.truth, field.name), getattr(b.truth, field.name)), field.name


# --------------------------------------------------------------------------- configuration


def test_invalid_noise_message_names_field_and_value() -> None:
    with pytest.raises(ValueError, match=r"^SimulationConfig\.noise_sigma must be a finite number in \[0, 1000\] \(px\), got -1$"):
        SimulationConfig(noise_sigma=-1)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"noise_sigma": float("nan")}, "noise_sigma"),
        ({"outlier_ratio": 1.0}, "outlier_ratio"),
        ({"outlier_ratio": -0.1}, "outlier_ratio"),
        ({"outlier_ratio": (0.6, 0.2)}, "outlier_ratio"),
        ({"outlier_ratio": (0.2, 1.0)}, "outlier_ratio"),
        ({"preset": "boat"}, "preset"),
        ({"world": "moon"}, "world"),
        ({"n_correspondences": 2}, "n_correspondences"),
        ({"n_correspondences": 10.5}, "n_correspondences"),
        ({"n_frames": 0}, "n_frames"),
        ({"outlier_mix": (0.0, 0.0, 0.0)}, "outlier_mix"),
        ({"outlier_mix": (1.0, -1.0, 1.0)}, "outlier_mix"),
        ({"outlier_mix": (1.0, 1.0)}, "outlier_mix"),
        ({"score_auc": 1.0}, "score_auc"),
        ({"score_auc": 0.4}, "score_auc"),
        ({"z_min": 0.0}, "z_min"),
        ({"z_min": 10.0, "z_max": 5.0}, "z_max"),
        ({"speed": -1.0}, "speed"),
        ({"camera": "kitti"}, "camera"),
    ],
)
def test_invalid_config_raises_naming_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=rf"SimulationConfig\.{field} must"):
        SimulationConfig(**kwargs)


def test_camera_with_empty_image_is_rejected() -> None:
    with pytest.raises(ValueError, match="width"):
        SimulationConfig(camera=StereoCamera(width=0))


def test_config_is_frozen_and_variants_use_replace() -> None:
    config = SimulationConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.noise_sigma = 1.0  # type: ignore[misc]
    variant = dataclasses.replace(config, preset="free", outlier_ratio=(0.1, 0.4))
    assert variant.resolved_world == "open" and config.resolved_world == "street"
    assert variant.epsilon_range == (0.1, 0.4) and config.epsilon_range == (0.5, 0.5)
    assert hash(config) == hash(SimulationConfig())
    with pytest.raises(ValueError, match="outlier_ratio"):
        dataclasses.replace(config, outlier_ratio=1.0)


def test_presets_describe_car_and_free_motion() -> None:
    car, free = PRESETS["car"], PRESETS["free"]
    assert car.speed == pytest.approx(1.0) and free.speed < car.speed
    pitch, yaw, roll = car.angular_std
    assert yaw > 5 * max(pitch, roll)  # camera y points down: yaw is about y
    assert min(free.angular_std) > 0.2 * max(free.angular_std)
    assert SimulationConfig(speed=2.0).motion.speed == 2.0


# --------------------------------------------------------------------------- one frame


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


@pytest.mark.parametrize("epsilon", [0.0, 0.3, 0.5, 0.97])
def test_outlier_count_is_round_epsilon_n_and_kinds_follow_the_mix(epsilon: float) -> None:
    frame = simulate_frame(SimulationConfig(outlier_ratio=epsilon), 2)
    n_out = round(epsilon * 500)
    assert np.count_nonzero(~frame.truth.inlier) == n_out
    counts = np.bincount(frame.truth.outlier_kind, minlength=4)
    assert counts[0] == 500 - n_out
    assert np.all(np.abs(counts[1:] - np.array([0.6, 0.2, 0.2]) * n_out) <= 1)
    assert frame.truth.outlier_ratio == epsilon


def test_zero_weight_kinds_never_appear() -> None:
    frame = simulate_frame(SimulationConfig(outlier_mix=(0.0, 0.0, 1.0), outlier_ratio=0.3), 3)
    assert set(np.unique(frame.truth.outlier_kind)) == {OutlierKind.INLIER, OutlierKind.MOVING_OBJECT}


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


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_street_landmarks_lie_on_the_ground_the_two_facades_or_the_clutter_between(seed: int) -> None:
    frame = simulate_frame(dataclasses.replace(NOISE_FREE, n_correspondences=600, outlier_ratio=0.0), seed)
    X = frame.camera.triangulate(frame.prev)  # camera k-1 frame: y points down, the ground is 1.65 m below
    x, y = X[:, 0], X[:, 1]
    ground = np.abs(y - 1.65) < 0.1  # 2 cm roughness
    high = y < 1.65 - 3.1  # above any clutter: only facades reach there
    left_wall, right_wall = np.median(x[high & (x < 0)]), np.median(x[high & (x > 0)])
    for wall in (x[high & (x < 0)], x[high & (x > 0)]):
        assert np.ptp(wall) < 1.0  # 10 cm relief on a plane
    facade = (np.abs(x - left_wall) < 0.6) | (np.abs(x - right_wall) < 0.6)
    clutter = (y >= 1.65 - 3.0 - 1e-9) & (y <= 1.65 + 1e-9) & (x > left_wall + 0.3) & (x < right_wall - 0.3)
    assert np.all(ground | facade | clutter)
    assert ground.sum() > 30 and np.count_nonzero(facade & ~ground) > 30 and np.count_nonzero(clutter & ~ground & ~facade) > 10
    assert -10.5 < left_wall < -3.5 and 3.5 < right_wall < 10.5  # streets 8-20 m wide


def test_noise_free_inliers_of_a_sequence_follow_the_true_motion() -> None:
    frame = Sequence(dataclasses.replace(NOISE_FREE, n_frames=30), seed=5).frame(30)
    inl = frame.truth.inlier
    X_pred, _ = predicted_curr(frame, inl)
    assert np.max(np.abs(frame.camera.triangulate(frame.curr[inl]) - X_pred)) < 1e-9


@pytest.mark.parametrize("preset, world", WORLD_CASES[:3])
@pytest.mark.parametrize("seed", [0, 1])
def test_moving_object_agrees_on_its_own_rigid_motion(preset: str, world: str, seed: int) -> None:
    frame = simulate_frame(dataclasses.replace(NOISE_FREE, preset=preset, world=world), seed)
    rows = rows_of(frame, OutlierKind.MOVING_OBJECT)
    assert np.count_nonzero(rows) == 50
    X_prev = frame.camera.triangulate(frame.prev[rows])
    X_curr = frame.camera.triangulate(frame.curr[rows])
    # Not explained by the camera motion ...
    X_pred, z_pred = predicted_curr(frame, rows)
    assert np.min(np.linalg.norm(frame.curr[rows, :3] - z_pred[:, :3], axis=1)) >= MIN_OUTLIER_PX - 1e-6
    assert np.median(np.linalg.norm(X_curr - X_pred, axis=1)) > 0.3
    # ... but by one common rigid motion of the object.
    R, t = kabsch(X_prev, X_curr)
    assert np.max(np.linalg.norm(X_curr - (X_prev @ R.T + t), axis=1)) < 1e-9
    # A compact object: its points span a few metres, not the scene.
    assert np.max(np.ptp(X_prev, axis=0)) < 8.0


def test_stereo_mismatches_keep_the_left_point_but_not_the_depth() -> None:
    for seed in range(3):
        frame = simulate_frame(NOISE_FREE, seed)
        rows = rows_of(frame, OutlierKind.STEREO_MISMATCH)
        X_true, z_true = predicted_curr(frame, rows)
        assert np.max(np.abs(frame.curr[rows, :2] - z_true[:, :2])) < 1e-6
        depth = frame.camera.triangulate(frame.curr[rows])[:, 2]
        assert np.min(np.abs(depth / X_true[:, 2] - 1.0)) >= 0.2 - 1e-9
        assert np.min(np.abs(frame.curr[rows, 2] - z_true[:, 2])) >= MIN_OUTLIER_PX - 1e-6


def test_random_mismatches_are_far_from_where_the_landmark_went() -> None:
    for seed in range(3):
        frame = simulate_frame(NOISE_FREE, seed)
        rows = rows_of(frame, OutlierKind.RANDOM_MISMATCH)
        _, z_true = predicted_curr(frame, rows)
        assert np.min(np.linalg.norm(frame.curr[rows, :3] - z_true[:, :3], axis=1)) >= MIN_OUTLIER_PX - 1e-6


@pytest.mark.parametrize("sigma", [0.5, 4.0])
def test_compiled_mismatches_equal_their_numpy_formulas(sigma: float) -> None:
    """The compiled outlier kernels draw what they always drew and compute it in the same order,
    so frames (and the checkpoints trained on them) do not change: checked against the formulas."""
    from stereovo.simulation.outliers import _STEREO_FACTOR, outlier_threshold
    from stereovo.simulation.outliers import random_mismatches as _random_mismatches
    from stereovo.simulation.outliers import stereo_mismatches as _stereo_mismatches

    config = SimulationConfig(noise_sigma=sigma, camera=StereoCamera(width=200, height=120))
    cam, tau = config.camera, outlier_threshold(sigma)
    rng = np.random.default_rng(3)
    d = rng.uniform(0.5, 150.0, 400)
    uL = rng.uniform(0.0, cam.width - 1, 400)
    meas = np.column_stack([uL, rng.uniform(0, cam.height - 1, 400), uL - d, np.zeros(400)])
    d = cam.disparity(meas)

    draws = np.random.default_rng(5)
    factor = np.exp(draws.uniform(*np.log(_STEREO_FACTOR), 400))
    want_up = draws.random(400) < 0.5
    d_up, d_down = np.maximum(d * factor, d + tau), np.minimum(d / factor, d - tau)
    floor = cam.min_disparity + max(0.5, 3.0 * sigma)
    up_ok, down_ok = uL - d_up >= 0, d_down >= floor
    use_up = up_ok & (want_up | ~down_ok)
    d_new = np.where(use_up, d_up, np.where(~use_up & down_ok, d_down, np.maximum(uL, floor)))
    expected = meas.copy()
    expected[:, 2] = uL - d_new
    np.testing.assert_array_equal(_stereo_mismatches(meas, config, np.random.default_rng(5)), expected)

    # a tight cluster: a borrowed measurement lands near the true one and is redrawn
    rows, pool = np.arange(100, 300), np.array([100.0, 60.0, 80.0, 60.0]) + rng.uniform(-1, 1, (400, 4))
    draws = np.random.default_rng(6)
    other = draws.random(200) < 0.5
    j = (rows + draws.integers(1, len(pool), size=200)) % len(pool)
    z = config.z_min * np.exp(draws.random(200) * np.log(config.z_max / config.z_min))
    dd = np.clip(cam.fx * cam.baseline / z, cam.min_disparity * 1.5, 0.9 * (cam.width - 1))
    u = dd + (cam.width - 1 - dd) * draws.random(200)
    v = (cam.height - 1) * draws.random(200)
    first = np.where(other[:, None], pool[j], np.stack([u, v, u - dd, v], axis=1))
    fake = _random_mismatches(rows, pool, config, np.random.default_rng(6))
    far = np.linalg.norm(first[:, :3] - pool[rows, :3], axis=1) >= tau
    assert 0 < far.sum() < 200  # some first draws were too near and were redrawn
    np.testing.assert_array_equal(fake[far], first[far])
    assert np.all(np.linalg.norm(fake[:, :3] - pool[rows, :3], axis=1) >= tau)


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


# --------------------------------------------------------------------------- sequences

SMALL = SimulationConfig(n_frames=6, n_correspondences=60)


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
    with pytest.raises(ValueError):
        poses[1, 0, 0] = 2.0  # read-only: frames are generated from these poses
    for k, frame in enumerate(seq, start=1):
        truth = frame.truth
        assert np.array_equal(truth.pose_prev, poses[k - 1]) and np.array_equal(truth.pose_curr, poses[k])
        R, t = relative_motion(truth.pose_prev, truth.pose_curr)
        assert np.allclose(truth.rotation, R, atol=1e-12) and np.allclose(truth.translation, t, atol=1e-12)
        assert np.max(np.abs(pose_update(poses[k - 1], truth.rotation, truth.translation) - poses[k])) < 1e-9


def body_steps(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera displacement (m) and rotation vector (rad) of each step, in the camera k-1 frame."""
    steps = np.linalg.inv(poses[:-1]) @ poses[1:]
    return steps[:, :3, 3], so3_log(steps[:, :3, :3])


def test_car_moves_about_one_metre_per_frame_forward_with_yaw_turns() -> None:
    seq = Sequence(SimulationConfig(n_frames=400, n_correspondences=3), seed=10)
    move, turn = body_steps(seq.true_poses)
    assert np.mean(move[:, 2]) == pytest.approx(1.0, abs=0.15)
    assert np.mean(np.linalg.norm(move[:, :2], axis=1)) < 0.1 * np.mean(move[:, 2])
    rms = np.sqrt(np.mean(turn**2, axis=0))
    assert rms[1] > 5 * max(rms[0], rms[2])
    assert np.degrees(rotation_angle(np.linalg.inv(seq.true_poses[:-1]) @ seq.true_poses[1:])).max() < 10
    # Smooth, mean-reverting velocities: consecutive speeds are strongly correlated.
    assert np.corrcoef(move[:-1, 2], move[1:, 2])[0, 1] > 0.6


def test_free_motion_is_slower_and_rotates_about_all_axes() -> None:
    seq = Sequence(SimulationConfig(preset="free", n_frames=400, n_correspondences=3), seed=11)
    move, turn = body_steps(seq.true_poses)
    assert np.mean(move[:, 2]) == pytest.approx(0.3, abs=0.1)
    rms_deg = np.degrees(np.sqrt(np.mean(turn**2, axis=0)))
    assert np.all((rms_deg > 0.5) & (rms_deg < 5.0))


def test_speed_override_scales_the_motion() -> None:
    seq = Sequence(SimulationConfig(speed=2.0, n_frames=200, n_correspondences=3), seed=12)
    move, _ = body_steps(seq.true_poses)
    assert np.mean(move[:, 2]) == pytest.approx(2.0, abs=0.3)


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


@pytest.mark.parametrize(
    "entropy",
    [[2**62 + 5, 2**40, 2**33 + 7, 2**63 - 1], [3, 2**40, 2**50, 2**60], [2**40, 0, 2**50, 2**32 - 1], [2**32] * 4],
)
def test_frame_streams_are_the_spawned_seed_sequences_of_the_entropy(entropy):
    """A frame's five streams are numpy's spawned children of its four entropy draws, small ints included."""
    from stereovo.simulation.pair import _stream_generators

    ours = _stream_generators(np.array(entropy, dtype=np.int64), 5)
    reference = [np.random.default_rng(s) for s in np.random.SeedSequence(list(entropy)).spawn(5)]
    for a, b in zip(ours, reference):
        np.testing.assert_array_equal(a.integers(0, 2**62, 8), b.integers(0, 2**62, 8))


@pytest.mark.parametrize(
    "entropy",
    [0, 7, 2**32, 2**100 + 5, 2**127 + 3, np.int64(12345), [3, 2**40, 0], [2**62 + 5, 2**40, 2**33 + 7, 2**63 - 1]],
)
@pytest.mark.parametrize("pool_size", [4, 8])
def test_seeded_generators_are_numpys_seed_sequence_generators(entropy, pool_size):
    """The compiled hash must give numpy's own PCG64 states, for every entropy and spawn key shape."""
    from stereovo.seeding import seeded_generators

    keys = [(), (0,), (5,), (2**40 + 1, 7), (1, 2, 3, 4, 5), (0x9E3779B9, 2**64 + 9, 0)]
    ours = seeded_generators(entropy, keys, pool_size)
    reference = [np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=k, pool_size=pool_size)) for k in keys]
    for a, b in zip(ours, reference):
        assert a.bit_generator.state == b.bit_generator.state
        np.testing.assert_array_equal(a.random(4), b.random(4))


def test_seeded_generators_leave_other_entropy_to_numpy():
    from stereovo.seeding import seeded_generators

    words = np.array([1, 2, 3], dtype=np.uint32)  # an array entropy: numpy's SeedSequence path
    (ours,) = seeded_generators(words, [(4,)])
    assert ours.bit_generator.state == np.random.default_rng(np.random.SeedSequence(words, spawn_key=(4,))).bit_generator.state
    with pytest.raises(ValueError, match="non-negative"):
        seeded_generators(-1, [(0,)])  # numpy's own error for negative entropy
    assert seeded_generators(5, []) == []


def test_sequence_frames_use_the_documented_child_seed_sequence():
    """Frame k's generator is SeedSequence(root entropy, spawn_key=(..., namespace, k)), numpy's hashing."""
    from stereovo.simulation.pair import simulate_pair as _simulate_pair
    from stereovo.simulation.sequence import _SEQUENCE_NAMESPACE

    config = SimulationConfig(n_correspondences=60, n_frames=3)
    seq = Sequence(config, seed=2**90 + 17)
    child = np.random.SeedSequence(2**90 + 17, spawn_key=(_SEQUENCE_NAMESPACE, 2))
    expected = _simulate_pair(config, seq.true_poses[1], seq.true_poses[2], 2, np.random.default_rng(child))
    assert_frames_identical(seq.frame(2), expected)


def test_validity_mask_is_in_image_and_has_depth():
    from stereovo.simulation.pair import _valid

    cam = StereoCamera()
    rng = np.random.default_rng(0)
    meas = np.column_stack([
        rng.uniform(-5, cam.width + 5, 4000), rng.uniform(-5, cam.height + 5, 4000),
        rng.uniform(-5, cam.width + 5, 4000), rng.uniform(-5, cam.height + 5, 4000),
    ])
    meas[:8] = [[0, 0, -1e-9, 0], [cam.width - 1, cam.height - 1, cam.width - 1 - cam.min_disparity, cam.height - 1],
                [cam.width - 1, 0, 0, 0], [10, 5, 10 - cam.min_disparity - 1e-9, 5], [np.nan, 1, 0, 1],
                [5, np.inf, 1, 1], [cam.width - 1 + 1e-9, 0, 3, 0], [7, 0, 3, cam.height - 1]]
    expected = cam.in_image(meas) & cam.has_depth(meas)
    np.testing.assert_array_equal(_valid(meas, cam), expected)
    assert 0 < expected.sum() < len(expected)
