"""Helpers for the simulator tests: noise-free configurations, world cases, predicted points."""

from __future__ import annotations

import numpy as np

from stereovo.geometry import transform_points
from stereovo.simulation import Frame, SimulationConfig


NOISE_FREE = SimulationConfig(noise_sigma=0.0)
WORLD_CASES = [("car", "street"), ("car", "open"), ("free", "open"), ("free", "street")]


def predicted_curr(frame: Frame, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points at k moved by the true motion from the triangulated k-1 points, and their projections."""
    X = transform_points(frame.truth.rotation, frame.truth.translation, frame.camera.triangulate(frame.prev[rows]))
    return X, frame.camera.project(X)
