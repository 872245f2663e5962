"""Two statements of the step environment's docstring, checked against the behaviour: the simulator's frames
do have rows without depth (mask 0), seldom with the default outliers and often with the hostile ones (the
docstring said they had none); and the info's ``outlier_ratio`` is the contamination epsilon drawn for the
frame, not the realised share of outlier rows (0.99 at N = 3, where all three rows are outliers), whereas the
images environment reports the realised share."""

from __future__ import annotations

import numpy as np
import pytest

from vo_gym.adaptive_env import StereoVOAdaptiveEnv
from vo_gym.env import StereoVOEnv
from vo_gym.images_env import StereoVOImagesEnv


def _doc(cls) -> str:
    return " ".join(cls.__doc__.split())


def _mask_zero_rows(outliers: str) -> tuple[int, int]:
    """Rows with mask 0 over the 21 observations of the docstring's episode, and how many of them are inliers."""
    env = StereoVOEnv(n_frames=20, n_correspondences=200, outlier_ratio=0.8, outliers=outliers)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    zeros = inliers = 0
    for step in range(21):
        masked = obs["mask"] == 0
        zeros += int(masked.sum())
        inliers += int((masked & env.current_frame.truth.inlier).sum())
        if step < 20:
            obs, *_ = env.step(rng.uniform(-1, 1, 200).astype(np.float32))
    return zeros, inliers


def test_the_simulators_frames_have_rows_without_depth_as_documented():
    doc = _doc(StereoVOEnv)
    assert "The simulator's own frames have none" not in doc
    assert "1 such row of 4200 with the default outliers, 554 with the hostile ones" in doc
    assert _mask_zero_rows("default") == (1, 0)
    assert _mask_zero_rows("hostile") == (554, 0)  # all outliers: the default depths give every inlier a depth


@pytest.mark.parametrize("cls", [StereoVOEnv, StereoVOAdaptiveEnv])
def test_outlier_ratio_is_the_drawn_epsilon_in_the_simulated_environments(cls):
    for n, epsilon, realised in ((3, 0.99, 1.0), (5, 0.5, 0.4)):
        env = cls(n_frames=1, n_correspondences=n, outlier_ratio=epsilon)
        env.reset(seed=0)
        truth = env.current_frame.truth
        info = {}
        while "outlier_ratio" not in info:
            action = np.zeros(env.action_space.shape, np.float32)
            action[-1] = 1.0  # the adaptive env's stop (the step env's last logit: any value does)
            info = env.step(action)[4]
        assert info["outlier_ratio"] == epsilon
        assert 1.0 - truth.inlier.mean() == realised == round(epsilon * n) / n
    assert "the contamination epsilon the simulator drew for the frame" in _doc(cls)
    assert "``round(epsilon N)`` outlier rows" in _doc(cls)


def test_the_images_environment_documents_the_realised_share():
    assert "``outlier_ratio`` is the realised share of the frame's rows that its labels mark as outliers" in (
        _doc(StereoVOImagesEnv))
