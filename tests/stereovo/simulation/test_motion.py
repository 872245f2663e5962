"""The simulator's motion models (stereovo/simulation/motion.py): car and free motion, speed override."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.geometry import rotation_angle, so3_log
from stereovo.simulation import Sequence, SimulationConfig


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
