"""Hand-built frames shared by the estimator and environment tests: the default camera, noise-free pairs,
belief frames, simulated frames with rows that lost their depth."""

from __future__ import annotations

import numpy as np

from stereovo import StereoCamera
from stereovo.simulation import Sequence, SimulationConfig, simulate_frame


CAMERA = StereoCamera()


def noise_free_pair(rng, R, t, n=80):
    """Points visible in both frames under the motion x_k = R x_{k-1} + t, measured exactly."""
    X = np.c_[rng.uniform(-20, 20, 40 * n), rng.uniform(-3, 3, 40 * n), rng.uniform(3, 50, 40 * n)]
    Y = X @ R.T + t
    ok = CAMERA.is_visible(X, z_min=3) & CAMERA.is_visible(Y, z_min=1)
    X, Y = X[ok][:n], Y[ok][:n]
    return CAMERA.project(X), CAMERA.project(Y)


def belief_frames(eps: float, count: int, n: int = 300):
    return [simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=eps), rng=s) for s in range(count)]


def frames_without_depth(monkeypatch, rows) -> None:
    """Every frame pair a simulated :class:`~stereovo.simulation.Sequence` hands out loses the depth of ``rows``
    (zero disparity at k-1), before an environment builds its observation from it and checks actions
    against it (through ``monkeypatch``, undone with it)."""
    frame_of = Sequence.frame

    def frame(self, k):
        pair = frame_of(self, k)
        pair.prev[rows, 2] = pair.prev[rows, 0]
        return pair

    monkeypatch.setattr(Sequence, "frame", frame)
