"""The simulator's worlds (stereovo/simulation/world.py): where the street's landmarks lie."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from stereovo.simulation import simulate_frame
from tests.support.simulation import NOISE_FREE


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
