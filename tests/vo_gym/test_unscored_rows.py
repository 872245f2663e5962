"""A match whose score is NaN or inf (a front end's failed match) is a row without depth, as a row with a
NaN coordinate is: masked, never sampled, an outlier of every reward; a frame left with too few usable
rows fails (status failed, the failure reward). Such a frame crashed reset with "scores must be finite"
from vo_gym/features.py."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence

import vo_gym  # noqa: F401  (registers the ids)
from stereovo.simulation import Sequence, SimulationConfig
from vo_gym.images_env import ReplayedFrames

N = 30


def _source(change=None) -> ReplayedFrames:
    """Three simulated frames served as an image source (the audit's reproduction), the first changed."""
    sequence = Sequence(SimulationConfig(n_frames=3, n_correspondences=N), 0)
    frames = [sequence.frame(k) for k in (1, 2, 3)]
    if change is not None:
        frames[0] = change(frames[0])
    return ReplayedFrames(frames, frames[0].camera, sequence.true_poses[:4], 0.5)


def _make(source, **kwargs):
    return gym.make("vo_gym/StereoVOImages-v0", source=source, n_frames=2, max_correspondences=40, **kwargs)


@pytest.mark.parametrize("sampling", ["guided", "prosac"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_frame_of_non_finite_scores_is_a_failed_frame_not_a_crash(sampling, bad):
    env = _make(_source(lambda f: dataclasses.replace(f, scores=np.full(N, bad))), sampling=sampling,
                render_mode="rgb_array")
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs) and not obs["mask"].any()
    obs, reward, terminated, truncated, info = env.step(np.zeros(40, np.float32))
    assert reward == -1.0 and not info["success"] and info["fallback"]
    assert info["status"] == f"failed: too few usable correspondences (0 of {N} usable, need 6)"
    assert env.render().shape[2] == 3
    assert obs["mask"].sum() == N  # the next, untouched frame runs as ever
    obs, reward, terminated, truncated, info = env.step(np.zeros(40, np.float32))
    assert info["status"] == "ok" and truncated


def test_rows_with_non_finite_scores_are_the_rows_of_a_frame_whose_coordinates_are_nan_there():
    rows = np.array([0, 4, 17])

    def unscored(frame):
        scores = frame.scores.copy()
        scores[rows] = [np.nan, np.inf, -np.inf]
        return dataclasses.replace(frame, scores=scores)

    def failed_matches(frame):
        prev, curr, scores = frame.prev.copy(), frame.curr.copy(), frame.scores.copy()
        prev[rows] = curr[rows] = np.nan
        scores[rows] = 0.0
        return dataclasses.replace(frame, prev=prev, curr=curr, scores=scores)

    for kwargs in ({}, {"sampling": "prosac"}, {"reward_mode": "msac"}, {"reward_mode": "inliers"}):
        a, b = _make(_source(unscored), **kwargs), _make(_source(failed_matches), **kwargs)
        obs_a, obs_b = a.reset(seed=1)[0], b.reset(seed=1)[0]
        assert data_equivalence(obs_a, obs_b)
        assert not obs_a["mask"][rows].any() and obs_a["mask"][:N].sum() == N - 3
        action = np.random.default_rng(0).normal(size=40).astype(np.float32)
        step_a, step_b = a.step(action), b.step(action)
        assert data_equivalence(step_a, step_b) and step_a[4]["status"] == "ok", kwargs
        assert not step_a[4]["fallback"]


def test_the_sequence_keeps_the_sources_frame_and_current_frame_is_what_the_agent_saw():
    env = _make(_source(lambda f: dataclasses.replace(f, scores=np.where(np.arange(N) == 2, np.nan, f.scores))))
    env.reset(seed=0)
    seen = env.unwrapped.current_frame
    assert np.isnan(seen.prev[2]).all() and seen.scores[2] == 0.0 and np.isfinite(seen.prev[3]).all()
    assert np.isfinite(env.unwrapped.sequence.frame(1).prev).all()  # the source's frame is left as it is
