"""The reprojection residual (stereovo/estimation/roles/reprojection.py)."""

import numpy as np

from stereovo.geometry import random_rotation
from tests.support.frames import CAMERA


def test_reprojection_residual_matches_projection_and_is_inf_behind_the_camera():
    from stereovo.estimation.kernels.base import MIN_DEPTH
    from stereovo.estimation.roles.reprojection import reprojection_sq

    rng = np.random.default_rng(4)
    X = np.column_stack([rng.uniform(-8, 8, 300), rng.uniform(-2, 2, 300), rng.uniform(2, 60, 300)])
    meas = rng.uniform(0, 500, (300, 4))
    Rs = np.stack([random_rotation(rng, 0.1) for _ in range(5)])
    ts = rng.normal(0, 0.5, (5, 3))
    ts[4] = [0.0, 0.0, -30.0]  # moves the nearer half of the points behind the camera
    got = reprojection_sq(CAMERA, Rs, ts, X, meas)
    for h in range(5):
        moved = X @ Rs[h].T + ts[h]
        behind = moved[:, 2] <= MIN_DEPTH
        expected = np.sum((CAMERA.project(np.where(behind[:, None], 1.0, moved)) - meas) ** 2, axis=1)
        np.testing.assert_allclose(got[h][~behind], expected[~behind], rtol=1e-12)
        assert np.all(np.isinf(got[h][behind]))
        assert behind.any() == (h == 4)
