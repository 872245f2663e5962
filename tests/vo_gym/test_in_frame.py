"""vo_gym.in_frame: the compiled observation block, the kept and compiled globals, the recorded masks and votes,
the selection and the normalised priors are the numpy formulation's, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

import vo_gym  # noqa: F401  (registers the ids)
from vo_gym.features import FEATURE_BOUND, N_FEATURES
from stereovo.estimation.loop import LoopState
from stereovo.estimation.methods.bansac import WeightedDraw
from vo_gym.action_box import exp_shifted
from vo_gym.in_frame import MASK_ROWS_START, LOOP_FEATURE_NAMES, AgentPriorSampler, normalised_priors, observation_rows


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
    if sampler.n_scored():
        masks = sampler.scored_masks
        g[6] = float(masks[int(np.argmax(masks @ search.weights))] @ search.weights)
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
        if search.best_residual is not None:  # the batch's row of the best model: its residuals computed alone
            loop = search.search
            alone = loop.ctx.residuals(loop.best_R[None], loop.best_t[None])[0]
            assert search.best_residual.tobytes() == alone.tobytes()
        if term or trunc:
            env.reset()


def test_recorded_masks_and_votes_are_numpys():
    rng = np.random.default_rng(3)
    for n in (1, 7, 500):
        sampler, masks = AgentPriorSampler(n), []
        for _ in range(40):  # past MASK_ROWS_START rows: the buffers grow
            batch = rng.random((int(rng.integers(1, 9)), n)) < rng.random()
            sampler.on_hypotheses(np.zeros((batch.shape[0], 3, 3)), np.zeros((batch.shape[0], 3)), batch, None,
                                  LoopState(0, 0.0, samples=np.zeros((batch.shape[0], 3), np.int64)))
            masks.append(batch)
            every = np.concatenate(masks)
            np.testing.assert_array_equal(sampler.scored_masks, every)
            np.testing.assert_array_equal(sampler.votes, np.count_nonzero(every, axis=0))
        assert sampler.n_scored() > MASK_ROWS_START
        # a mask of ints (no search's) takes numpy's count and copy
        sampler.on_hypotheses(None, None, np.ones((2, n), dtype=np.int64), None, LoopState(0, 0.0, samples=None))
        np.testing.assert_array_equal(sampler.votes, np.count_nonzero(every, axis=0) + 2)


def test_selection_is_the_product_of_the_bool_masks():
    rng = np.random.default_rng(4)
    for _ in range(300):
        n, h = int(rng.integers(3, 600)), int(rng.integers(1, 90))
        sampler = AgentPriorSampler(n)
        batch = rng.random((h, n)) < rng.random()
        sampler.on_hypotheses(None, None, batch, None, LoopState(0, 0.0, samples=None))
        weights = np.exp(rng.standard_normal(n) * rng.uniform(0, 10))
        weights /= weights.sum()
        product = batch @ weights
        chosen = sampler.select(weights)
        assert chosen == int(np.argmax(product))
        k = int(rng.integers(h))
        assert sampler.weighted_support(k, weights) == float(batch[k] @ weights)
    assert AgentPriorSampler(4).select(np.full(4, 0.25)) is None


def test_normalised_priors_are_numpys_weights_and_draw():
    rng = np.random.default_rng(6)
    for _ in range(300):
        n = int(rng.integers(1, 700))
        logits = np.clip(rng.standard_normal(n) * rng.uniform(0, 20), -10, 10)
        want = np.exp(logits - logits.max())
        want /= want.sum()
        weights = exp_shifted(logits)
        draw = normalised_priors(weights)
        assert weights.tobytes() == want.tobytes()
        reference = WeightedDraw(want)
        for ours, theirs in ((draw.w, reference.w), (draw.cdf, reference.cdf), (draw.before, reference.before)):
            assert ours.tobytes() == theirs.tobytes()
        if n >= 3:
            a, b = np.random.default_rng(n), np.random.default_rng(n)
            np.testing.assert_array_equal(draw.draw(8, a), reference.draw(8, b))
            assert a.random() == b.random()


@pytest.mark.parametrize("method", ["ransac", "probabilistic"])
def test_the_best_models_residuals_are_its_own_under_other_judges(method):
    import gymnasium as gym

    env = gym.make("vo_gym/StereoVOAdaptive-v0", n_frames=3, method=method)
    env.reset(seed=2)
    env.action_space.seed(2)
    checked = 0
    for _ in range(40):
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        search = env.unwrapped._search
        if search.best_residual is not None:
            loop = search.search
            alone = loop.ctx.residuals(loop.best_R[None], loop.best_t[None])[0]
            assert search.best_residual.tobytes() == alone.tobytes()
            checked += 1
        if term or trunc:
            env.reset()
    assert checked


def test_the_frame_ends_on_the_belief_weighted_not_the_largest_consensus():
    """``finish`` hands the loop the hypothesis of largest support weighted by the last step's
    ``softmax(logits)``: with logits that favour the points of a hypothesis other than the largest
    consensus, that hypothesis is refined, not the largest one."""
    from stereovo.estimation import EstimatorOptions, StereoProblem, method_spec
    from stereovo.simulation import SimulationConfig, simulate_frame
    from vo_gym.features import compute_features
    from vo_gym.in_frame import InFrameSearch

    frame = simulate_frame(SimulationConfig(n_correspondences=120, outlier_ratio=0.5), np.random.default_rng(3))
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    features = compute_features(frame.prev, frame.curr, frame.scores, frame.camera, frame.noise_sigma, None,
                                problem=problem)
    search = InFrameSearch(problem, features, method_spec("msac"), EstimatorOptions(noise_sigma=frame.noise_sigma),
                           64, None, np.random.default_rng(0))
    n = problem.n
    for _ in range(8):
        search.step(np.zeros(n), False, 4)
    masks = search.scored_inliers
    counts = masks.sum(axis=1)
    largest = int(np.argmax(counts))
    assert np.count_nonzero(counts == counts[largest]) == 1
    # the hypothesis with the most inliers outside the largest consensus becomes the favoured one
    target = int(np.argmax((masks & ~masks[largest]).sum(axis=1)))
    assert target != largest and (masks[target] & ~masks[largest]).any()
    logits = np.where(masks[target] & ~masks[largest], 8.0, 0.0)
    search.step(logits, True, 4)  # the stop: nothing drawn, the weights set
    weights = np.exp(logits - logits.max())
    weights /= weights.sum()
    support = masks.astype(np.float64) @ weights
    expected = int(np.argmax(support))
    assert expected != largest and np.count_nonzero(support >= support[expected] - 1e-12) == 1
    chosen = []
    choose = search.search.choose
    search.search.choose = lambda R, t, inliers, score: (chosen.append((R, t, inliers)), choose(R, t, inliers, score))
    search.finish("msac")
    (R, t, inliers), = chosen
    np.testing.assert_array_equal(inliers, masks[expected])
    R_h, t_h = search.sampler.hypothesis(expected)
    np.testing.assert_array_equal(R, R_h)
    np.testing.assert_array_equal(t, t_h)
