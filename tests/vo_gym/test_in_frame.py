"""vo_gym.in_frame: the compiled observation block and the kept globals are the numpy formulation's, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

import vo_gym  # noqa: F401  (registers the ids)
from vo_gym.features import FEATURE_BOUND, N_FEATURES
from vo_gym.in_frame import LOOP_FEATURE_NAMES, observation_rows


def _reference_rows(features, best_column, best_inliers, votes, scored, rows):
    """The observation's feature block as numpy computed it before it was compiled."""
    n = features.shape[0]
    loop = np.zeros((n, len(LOOP_FEATURE_NAMES)), dtype=np.float64)
    if best_column is not None:
        loop[:, 0] = best_column
        loop[:, 3] = best_inliers
    loop[:, 1] = votes / max(scored, 1)
    loop[:, 2] = np.log1p(votes)
    out = np.zeros((rows, N_FEATURES + len(LOOP_FEATURE_NAMES)), dtype=np.float32)
    out[:n, :N_FEATURES] = features
    out[:n, N_FEATURES:] = np.minimum(np.maximum(loop, -FEATURE_BOUND, out=loop), FEATURE_BOUND, out=loop)
    return out


def _reference_globals(search, max_hypotheses):
    """The globals as computed on every step before the best model's distance was kept between steps."""
    import math

    loop, sampler = search.search, search.sampler
    g = np.zeros(7)
    g[0] = loop.drawn / max_hypotheses
    g[1] = np.count_nonzero(loop.best_inliers) / search.problem.n
    g[2] = float(sampler.n_scored() > 0)
    if search.previous_motion is not None:
        g[5] = 1.0
        if sampler.n_scored():
            R_prev, t_prev = search.previous_motion
            cos = (np.trace(loop.best_R @ R_prev.T) - 1) / 2
            g[3] = math.log1p(math.degrees(math.acos(min(max(cos, -1.0), 1.0))) / 0.1)
            g[4] = math.log1p(float(np.linalg.norm(loop.best_t - t_prev)) / 0.05)
    chosen = sampler.select(search.weights)
    if chosen is not None:
        g[6] = float(sampler.scored_masks[chosen] @ search.weights)
    return np.minimum(np.maximum(g, -FEATURE_BOUND), FEATURE_BOUND).astype(np.float32)


def test_observation_rows_are_numpys_on_random_inputs():
    rng = np.random.default_rng(12)
    for trial in range(400):
        n = int(rng.integers(1, 300))
        rows = n + int(rng.integers(0, 3)) * int(rng.integers(0, 50))
        scored = int(rng.integers(0, 300)) if trial % 4 else int(rng.integers(0, 3))
        votes = rng.integers(0, scored + 1, n).astype(np.int64)
        features = (rng.standard_normal((n, N_FEATURES)) * 4).astype(np.float32)
        best_inliers = rng.random(n) < 0.5
        best_column = None
        if trial % 3:
            best_column = np.log1p(rng.exponential(10.0, n) * 10.0 ** rng.integers(-3, 3, n))
            best_column[rng.random(n) < 0.05] = rng.choice([0.0, -0.0, np.inf, np.nan, 9.999999, 10.0, 10.000001])
        ours = observation_rows(features, best_column, best_inliers, votes, scored, rows)
        want = _reference_rows(features, best_column, best_inliers, votes, scored, rows)
        assert ours.dtype == want.dtype and ours.shape == want.shape
        assert ours.tobytes() == want.tobytes()


def test_counts_outside_the_table_take_numpys_columns():
    rng = np.random.default_rng(1)
    features = rng.standard_normal((6, N_FEATURES)).astype(np.float32)
    best, inliers = rng.standard_normal(6), rng.random(6) < 0.5
    for votes in (np.array([0, 1, 2, 10**6, 3, 0]), np.array([0, -1, 2, 1, 3, 0])):
        with np.errstate(divide="ignore", invalid="ignore"):
            want = _reference_rows(features, best, inliers, votes, 5, 8)
            ours = observation_rows(features, best, inliers, votes, 5, 8)
        assert ours.tobytes() == want.tobytes()


def test_the_log1p_table_is_numpys_log1p_of_counts_anywhere_in_an_array():
    rng = np.random.default_rng(5)
    observation_rows(np.zeros((1, N_FEATURES), np.float32), None, np.zeros(1, bool), np.zeros(1, np.int64), 4000, 1)
    table = np.log1p(np.arange(4001, dtype=np.float64))
    for _ in range(200):
        votes = rng.integers(0, 4001, int(rng.integers(1, 600)))
        np.testing.assert_array_equal(np.log1p(votes), table[votes])
        start = int(rng.integers(0, 7))  # an offset start (numpy's vector loops and their tails)
        np.testing.assert_array_equal(np.log1p(votes.astype(np.float64))[start:], np.log1p(votes[start:]))


@pytest.mark.parametrize("kwargs", [
    {},
    {"max_correspondences": 540, "outliers": "hostile"},
    {"max_hypotheses": 200, "batch_size": 16, "n_correspondences": 150},
    {"batch_size": None, "world": "open"},
])
def test_adaptive_observations_equal_the_numpy_formulation(kwargs):
    import gymnasium as gym

    env = gym.make("vo_gym/StereoVOAdaptive-v0", n_frames=4, **kwargs)
    env.reset(seed=2)
    env.action_space.seed(2)
    for _ in range(60):
        obs, _, term, trunc, _ = env.step(env.action_space.sample())
        search = env.unwrapped._search
        best = None if search.best_residual is None else np.log1p(
            search.best_residual / search.search.components.threshold_sq)
        want = _reference_rows(search.features, best, search.search.best_inliers, search.sampler.votes,
                               search.sampler.n_scored(), env.unwrapped.max_correspondences)
        assert obs["features"].tobytes() == want.tobytes()
        assert obs["globals"].tobytes() == _reference_globals(search, env.unwrapped.max_hypotheses).tobytes()
        if term or trunc:
            env.reset()
