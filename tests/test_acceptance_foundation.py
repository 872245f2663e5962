"""Acceptance figures of the foundation issue, on seeded simulated frames.

sigma = 0.5 px, N = 500, 200 frames per setting: success (rotation < 1 deg and
translation < max(5 cm, 5 %)) on >= 99 % of frames at epsilon 0.5 and >= 97 %
at epsilon 0.8, for `probabilistic` and for `ransac` with its own threshold.
Outliers are random and stereo mismatches: a moving object as large as the
static scene is a different motion, not noise (see the classical-family tests).
"""

import numpy as np
import pytest

from stereovo import estimate_motion
from stereovo.geometry import rotation_error
from stereovo.metrics import is_success
from stereovo.odometry import run_odometry
from stereovo.simulation import Sequence, SimulationConfig, simulate_frame

N_FRAMES = 200


def success_rate(method: str, epsilon: float) -> float:
    config = SimulationConfig(n_correspondences=500, outlier_ratio=epsilon, noise_sigma=0.5, outlier_mix=(0.8, 0.2, 0.0))
    seeds = np.random.SeedSequence(2024).spawn(N_FRAMES)
    ok = []
    for i, seed in enumerate(seeds):
        frame = simulate_frame(config, np.random.default_rng(seed))
        est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=i, noise_sigma=0.5)
        r_err = rotation_error(est.rotation, frame.truth.rotation)
        t_err = np.linalg.norm(est.translation - frame.truth.translation)
        ok.append(est.ok and bool(is_success(r_err, t_err, np.linalg.norm(frame.truth.translation))))
    return float(np.mean(ok))


@pytest.mark.slow
# The foundation's bar is for the project's recipes: "ransac" is now Fischler & Bolles' textbook
# loop (closed-form minimal fits, no polish or LM); its enhanced row is the recipe this bar was set on.
@pytest.mark.parametrize("method", ["probabilistic", "ransac+polish+refit+lm"])
@pytest.mark.parametrize("epsilon,required", [(0.5, 0.99), (0.8, 0.97)])
def test_success_rate_on_200_frames(method, epsilon, required):
    assert success_rate(method, epsilon) >= required


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
