"""The simulator's outliers (stereovo/simulation/outliers.py): counts, kinds, and the compiled kernels."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from stereovo.camera import StereoCamera
from stereovo.simulation import Frame, OutlierKind, SimulationConfig, simulate_frame
from tests.support.simulation import NOISE_FREE, WORLD_CASES, predicted_curr


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
