"""Helpers for the stop-calibration tests: the calibration confidence and its cached runs."""

from __future__ import annotations

import functools

from stereovo.estimation.problem import StereoProblem
from stereovo.simulation import SimulationConfig, simulate_frame


CALIBRATION_CONFIDENCE = 0.9  # misses allowed in one run of ten: frequent enough to count in 1000 runs


@functools.cache
def calibration_frames(frames: int = 1000) -> tuple:
    """1000 seeded frames at eps 0.8 (N 40, 8 inliers) with their problems, simulated once."""
    config = SimulationConfig(n_correspondences=40, outlier_ratio=0.8)
    out = []
    for seed in range(frames):
        frame = simulate_frame(config, 5000 + seed)
        out.append((frame, StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)))
    return tuple(out)
