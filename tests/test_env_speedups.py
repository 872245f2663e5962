"""The environments' faster paths against the formulations they replaced (the same draws and masks,
bit for bit), and the compiled consistency counts against their numpy formulation."""

from __future__ import annotations

import numpy as np

from stereovo.estimation.methods.bansac import WeightedDraw
from stereovo.estimation.loop import LoopState
from stereovo.estimation.roles.samplers import WeightedSampler
from stereovo.estimation.kernels.rigidity import distance_change_sq, rigid_distance_consistent
from vo_gym.adaptive_env import AgentPriorSampler
from vo_gym.features import MAX_ANCHORS, rigid_consistency_degree


def test_weighted_draw_gives_weighted_samplers_samples():
    rng = np.random.default_rng(0)
    for n in (3, 7, 500):
        for scale in (1.0, 30.0, 300.0):  # softmax of logits within +-scale, as the adaptive env bounds them
            logits = rng.uniform(-scale, scale, n)
            weights = np.exp(logits - logits.max())
            weights /= weights.sum()
            a, b = np.random.default_rng(n), np.random.default_rng(n)
            np.testing.assert_array_equal(WeightedDraw(weights).draw(300, a), WeightedSampler(weights).draw(300, b))
            assert a.random() == b.random()  # the same generator state afterwards


def test_agent_sampler_keeps_every_scored_mask_in_order_across_its_buffer_growth():
    sampler = AgentPriorSampler(5)
    rng = np.random.default_rng(1)
    masks = [rng.random((k, 5)) < 0.5 for k in (40, 30, 7)]  # 77 rows: the 64-row buffer doubles
    for m in masks:
        sampler.on_hypotheses(None, None, m, None, LoopState(0, 0.0, samples=np.zeros((m.shape[0], 3), dtype=np.int64)))
    np.testing.assert_array_equal(sampler.scored_masks, np.concatenate(masks))
    w = rng.random(5)
    assert sampler.select(w) == int(np.argmax(np.concatenate(masks) @ w)) and sampler.n_scored() == 77


def _full_counts(P, Q, s2, anchors, gate_sq):
    """Every match against every anchor, in numpy: the formulation the compiled kernel replaced."""
    d = distance_change_sq(*(P[anchors][None, :, c] - P[:, None, c] for c in range(3)),
                           *(Q[anchors][None, :, c] - Q[:, None, c] for c in range(3)))
    return rigid_distance_consistent(d, s2[:, None] + s2[anchors][None, :], gate_sq).sum(axis=1)


def test_consistency_degree_equals_the_numpy_formulation():
    rng = np.random.default_rng(2)
    for n in (2, 40, MAX_ANCHORS + 1, 600):
        P = rng.normal(0, 10, (n, 3))
        Q = P + rng.normal(0, 0.05, (n, 3))
        Q[: n // 3] += rng.normal(0, 1.0, (n // 3, 3))  # some matches that do not keep their distances
        spread = rng.uniform(0.01, 0.2, n)
        scores = rng.random(n)
        got = rigid_consistency_degree(P, Q, spread, priority=scores)
        order = np.argsort(-scores, kind="stable")
        anchors = np.arange(n) if n <= MAX_ANCHORS else np.sort(order[:MAX_ANCHORS])
        counts = _full_counts(P, Q, np.square(spread), anchors, 9.0)
        is_anchor = np.isin(np.arange(n), anchors)
        expected = ((counts - is_anchor) / (anchors.size - is_anchor)).astype(np.float32)
        np.testing.assert_array_equal(got, expected)
        assert n < 40 or 0.2 < got.mean() < 0.9  # the test separates the disturbed matches
