"""Inlier detection by maximum clique (docs/algorithms.md, `inlier-detection`)."""

from __future__ import annotations

import itertools

import numpy as np

from stereovo import estimate_motion
from stereovo.estimation.methods.clique import (
    consistency_matrix,
    exact_clique,
    greedy_clique,
    maximum_consistent_set,
)
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.solvers import SAMPLE_SIZE
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


def random_outlier_frames(epsilon, n, count, seed):
    config = SimulationConfig(n_correspondences=n, outlier_ratio=epsilon, outlier_mix=(1, 0, 0))
    return [simulate_frame(config, seed + i) for i in range(count)]


def test_the_fit_on_the_clique_succeeds_at_heavy_contamination():
    # Target: >= 95 % success at eps 0.8, N 500, random outliers (success as the benchmark's).
    from stereovo.metrics import frame_metrics

    frames = random_outlier_frames(0.8, 500, 30, 5000)
    ok = [frame_metrics(estimate_motion(f.prev, f.curr, f.camera, method="inlier-detection", rng=i,
                                        noise_sigma=f.noise_sigma), f.truth).success for i, f in enumerate(frames)]
    assert np.mean(ok) >= 0.95, np.mean(ok)


def test_robust_clique_fit_ignores_far_outliers_inside_the_set():
    # A "clique" of the true inliers plus five far outliers, each a few metres off: the least-squares
    # fit on all of it is pulled away, the robust fit (RANSAC inside, then reprojection) is not.
    from stereovo.estimation.methods.clique import robust_clique_fit
    from stereovo.estimation.roles.solvers import fit_rigid

    frame = simulate_frame(SimulationConfig(n_correspondences=200, outlier_ratio=0.5, outlier_mix=(1, 0, 0)), 36)
    camera = frame.camera
    rng = np.random.default_rng(0)
    far_prev = np.column_stack([rng.uniform(-20, 20, 5), rng.uniform(-2, 2, 5), rng.uniform(50, 70, 5)])
    far_curr = far_prev + rng.normal(0, 6.0, (5, 3))  # not the motion: metres off, as far depth errors allow
    prev = np.vstack([frame.prev, camera.project(far_prev)])
    curr = np.vstack([frame.curr, camera.project(far_curr)])
    problem = StereoProblem.build(prev, curr, camera, frame.noise_sigma)
    members = np.concatenate([np.flatnonzero(frame.truth.inlier), frame.prev.shape[0] + np.arange(5)])
    R_ls, _ = fit_rigid(problem.points_prev[members], problem.points_curr[members])
    assert np.degrees(rotation_error(R_ls, frame.truth.rotation)) > 0.5
    R, t, inner, _ = robust_clique_fit(problem, members, (6 * frame.noise_sigma) ** 2, np.random.default_rng(1))
    assert inner.status == "ok"
    assert np.degrees(rotation_error(R, frame.truth.rotation)) < 0.1
    assert np.linalg.norm(t - frame.truth.translation) < 0.05


def test_one_far_point_changes_nothing():
    # A usable point at disparity 0.2 px (some 1.7 km away) once gave "clique fit has 0 inliers".
    frame = random_outlier_frames(0.5, 300, 1, 40)[0]
    far_prev = np.array([[600.0, 200.0, 599.8, 200.0]])
    far_curr = np.array([[601.0, 200.0, 600.8, 200.0]])
    plain = estimate_motion(frame.prev, frame.curr, frame.camera, method="inlier-detection", rng=1,
                            noise_sigma=frame.noise_sigma)
    extra = estimate_motion(np.vstack([frame.prev, far_prev]), np.vstack([frame.curr, far_curr]), frame.camera,
                            method="inlier-detection", rng=1, noise_sigma=frame.noise_sigma)
    assert plain.ok and extra.ok, extra.status
    assert np.degrees(rotation_error(extra.rotation, plain.rotation)) < 0.01
    assert np.linalg.norm(extra.translation - plain.translation) < 0.01
    assert np.count_nonzero(extra.inliers[:-1] != plain.inliers) <= 3


def test_counters_describe_the_graph_the_clique_and_its_fit():
    frame = random_outlier_frames(0.5, 200, 1, 37)[0]
    est = detect(frame)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    clique, W, exact = maximum_consistent_set(problem)
    c = est.counters
    assert c["clique_graph_nodes"] == 200 and c["clique_subsampled"] == 0
    assert c["clique_graph_edges"] == np.count_nonzero(W) // 2
    assert c["clique_size"] == clique.size and c["clique_exact"] == int(exact)
    assert 1 <= c["clique_fit_hypotheses"] <= 1000
    assert SAMPLE_SIZE <= c["clique_fit_inliers"] <= clique.size


def test_large_frames_build_the_graph_on_a_subset_in_bounded_memory():
    # Above clique_graph_max the graph is built on that many random matches: memory O(M^2 + N),
    # never N x N (here N^2 = 400 MB as bools, 3.2 GB as floats), and the inliers come from all N.
    import tracemalloc

    frame = random_outlier_frames(0.5, 20_000, 1, 38)[0]
    tracemalloc.start()
    try:
        est = estimate_motion(frame.prev, frame.curr, frame.camera, method="inlier-detection", rng=3,
                              noise_sigma=frame.noise_sigma, clique_graph_max=1000)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100e6, peak
    assert est.ok and est.counters["clique_subsampled"] == 1 and est.counters["clique_graph_nodes"] == 1000
    assert np.degrees(rotation_error(est.rotation, frame.truth.rotation)) < 0.1
    tp = np.count_nonzero(est.inliers & frame.truth.inlier)
    assert tp >= 0.9 * np.count_nonzero(frame.truth.inlier)  # inliers found among all N, not the subset
    again = estimate_motion(frame.prev, frame.curr, frame.camera, method="inlier-detection", rng=3,
                            noise_sigma=frame.noise_sigma, clique_graph_max=1000)
    np.testing.assert_array_equal(again.inliers, est.inliers)  # the subset comes from the passed generator
