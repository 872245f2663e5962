"""Inlier detection by maximum clique (ALGORITHMS.md section 8)."""

from __future__ import annotations

import itertools

import numpy as np

from stereovo import estimate_motion
from stereovo.estimation.clique import consistency_matrix, exact_clique, greedy_clique, maximum_consistent_set
from stereovo.estimation.problem import StereoProblem
from stereovo.geometry import rotation_error
from stereovo.simulation import OutlierKind, SimulationConfig, simulate_frame


def is_clique(W, members):
    sub = W[np.ix_(members, members)]
    return bool(np.all(sub | np.eye(len(members), dtype=bool)))


def random_graph(rng, n, p):
    upper = np.triu(rng.random((n, n)) < p, 1)
    return upper | upper.T


def brute_force_clique_size(W):
    n = W.shape[0]
    for size in range(n, 0, -1):
        for members in itertools.combinations(range(n), size):
            if is_clique(W, list(members)):
                return size
    return 0


def detect(frame):
    return estimate_motion(frame.prev, frame.curr, frame.camera, method="inlier-detection", noise_sigma=frame.noise_sigma)


def test_exact_clique_is_maximum_and_greedy_is_a_clique():
    rng = np.random.default_rng(0)
    for _ in range(15):
        W = random_graph(rng, 11, rng.uniform(0.3, 0.8))
        exact, proven = exact_clique(W, time_limit_s=5.0)
        greedy = greedy_clique(W)
        assert proven and is_clique(W, exact) and is_clique(W, greedy)
        assert len(exact) == brute_force_clique_size(W) >= len(greedy)


def test_exact_search_respects_its_time_cap():
    W = random_graph(np.random.default_rng(1), 300, 0.9)  # far too hard to finish
    members, proven = exact_clique(W, time_limit_s=0.05)
    assert not proven and is_clique(W, members)


def test_consistency_matrix_is_symmetric_and_links_true_inliers():
    frame = simulate_frame(SimulationConfig(n_correspondences=120, outlier_ratio=0.5, outlier_mix=(1, 0, 0)), 31)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    W = consistency_matrix(problem)
    assert np.array_equal(W, W.T) and not W.diagonal().any()
    inlier = frame.truth.inlier
    assert W[np.ix_(inlier, inlier)].mean() > 0.97  # depth-aware 3-sigma threshold
    assert W[np.ix_(~inlier, ~inlier)].mean() < 0.6


def test_clique_finds_the_inliers_among_random_outliers():
    # ~100 inliers and 100 random mismatches: the greedy clique (N > 60) and the final inlier set.
    frame = simulate_frame(SimulationConfig(n_correspondences=200, outlier_ratio=0.5, outlier_mix=(1, 0, 0)), 32)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    clique, W, proven = maximum_consistent_set(problem)
    assert not proven and is_clique(W, clique)
    inlier = frame.truth.inlier
    est = detect(frame)
    assert est.ok and np.degrees(rotation_error(est.rotation, frame.truth.rotation)) < 1.0
    tp = np.count_nonzero(est.inliers & inlier)
    assert tp / est.n_inliers >= 0.9 and tp / inlier.sum() >= 0.9
    assert np.count_nonzero(inlier[clique]) / inlier.sum() >= 0.9  # the clique itself already has them
    assert est.n_hypotheses == 1


def test_small_problems_use_the_exact_clique():
    frame = simulate_frame(SimulationConfig(n_correspondences=50, outlier_ratio=0.5, outlier_mix=(1, 0, 0)), 33)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    clique, W, proven = maximum_consistent_set(problem, exact_max=60)
    assert proven and is_clique(W, clique) and len(clique) >= len(greedy_clique(W))
    est = detect(frame)
    assert est.ok and np.degrees(rotation_error(est.rotation, frame.truth.rotation)) < 1.0


def test_a_large_moving_object_wins_the_clique():
    # Documented limitation: 60 static inliers, 90 points on one rigidly moving object.
    frame = simulate_frame(SimulationConfig(n_correspondences=150, outlier_ratio=0.6, outlier_mix=(0, 0, 1)), 34)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    moving = frame.truth.outlier_kind == OutlierKind.MOVING_OBJECT
    clique, W, _ = maximum_consistent_set(problem)
    assert is_clique(W, clique)
    assert np.count_nonzero(moving[clique]) > np.count_nonzero(frame.truth.inlier[clique])
    est = detect(frame)
    assert np.count_nonzero(est.inliers & moving) > 0.8 * est.n_inliers  # it tracks the object
    assert np.degrees(rotation_error(est.rotation, frame.truth.rotation)) > 1.0 or np.linalg.norm(
        est.translation - frame.truth.translation
    ) > 0.2
