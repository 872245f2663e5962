"""The rigidity check of minimal samples (stereovo/estimation/roles/sample_check.py)."""

import numpy as np
import pytest

from stereovo import estimate_motion
from stereovo.estimation.problem import StereoProblem
from stereovo.geometry import rotation_error


def _pairwise_rigidity_reference(problem, samples):
    """Largest squared standardised change of a sample's three pairwise distances (numpy)."""
    worst = np.zeros(len(samples))
    for a, b in ((0, 1), (0, 2), (1, 2)):
        dX = problem.points_prev[samples[:, a]] - problem.points_prev[samples[:, b]]
        dY = problem.points_curr[samples[:, a]] - problem.points_curr[samples[:, b]]
        lX, lY = np.linalg.norm(dX, axis=1), np.linalg.norm(dY, axis=1)
        uX, uY = dX / lX[:, None], dY / lY[:, None]
        var = np.einsum("hi,hij,hj->h", uX, problem.cov_prev[samples[:, a]] + problem.cov_prev[samples[:, b]], uX)
        var += np.einsum("hi,hij,hj->h", uY, problem.cov_curr[samples[:, a]] + problem.cov_curr[samples[:, b]], uY)
        worst = np.maximum(worst, (lY - lX) ** 2 / var)
    return worst


def test_rigidity_check_keeps_inlier_triplets_and_drops_most_with_an_outlier():
    from scipy.stats import chi2

    from stereovo.estimation.roles.sample_check import RigidityCheck
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=400, outlier_ratio=0.6), np.random.default_rng(2))
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    rng = np.random.default_rng(0)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(6000)])
    check = RigidityCheck(chi2.ppf(0.999, 1))
    keep = check.accept(problem, samples)
    np.testing.assert_array_equal(keep, _pairwise_rigidity_reference(problem, samples) <= check.threshold_sq)
    all_inlier = frame.truth.inlier[samples].all(axis=1)
    assert all_inlier.sum() > 300
    assert keep[all_inlier].mean() > 0.99  # three tests at 0.999 each
    assert keep[~all_inlier].mean() < 0.3  # an outlier breaks two of the three distances


def test_probabilistic_fits_only_rigid_samples_and_still_finds_the_motion():
    from stereovo.simulation import SimulationConfig, simulate_frame

    # random mismatches only: a moving object's rigid cluster may win at eps 0.8 with or without the check
    config = SimulationConfig(n_correspondences=300, outlier_ratio=0.8, outlier_mix=(1.0, 0.0, 0.0))
    frame = simulate_frame(config, np.random.default_rng(4))
    kwargs = dict(rng=0, noise_sigma=frame.noise_sigma)
    checked = estimate_motion(frame.prev, frame.curr, frame.camera, **kwargs)
    unchecked = estimate_motion(frame.prev, frame.curr, frame.camera, rigidity_gate_probability=None, **kwargs)
    for est in (checked, unchecked):
        assert est.ok
        assert np.degrees(rotation_error(est.rotation, frame.truth.rotation)) < 0.2
        assert np.linalg.norm(est.translation - frame.truth.translation) < 0.05
    report = checked.report
    assert report.n_rejected_samples > 0.6 * checked.n_hypotheses
    assert report.n_scored + report.n_degenerate + report.n_rejected_samples == checked.n_hypotheses
    assert unchecked.report.n_rejected_samples == 0
    assert unchecked.report.n_scored + unchecked.report.n_degenerate == unchecked.n_hypotheses
    # Frames where no triplet is rigid fail with a reason, without raising.
    rng = np.random.default_rng(1)
    shuffled = frame.curr[rng.permutation(frame.n)]
    est = estimate_motion(frame.prev, shuffled, frame.camera, budget=20, **kwargs)
    assert not est.ok and est.status.startswith("failed: ")


def _pairs_with_a_lenient_anchor(problem, pairs):
    """``(problem', samples)``: ``problem`` with one extra point whose covariance is so large that
    every distance to it passes any gate, and the samples ``(a, b, anchor)``; such a triplet is kept
    exactly when its pair ``(a, b)`` passes, so ``accept`` reports the single pairwise checks."""
    import dataclasses

    huge = 1e12 * np.eye(3)[None]
    anchor = np.array([[0.0, 0.0, 1000.0]])
    extended = dataclasses.replace(
        problem,
        points_prev=np.ascontiguousarray(np.vstack([problem.points_prev, anchor])),
        points_curr=np.ascontiguousarray(np.vstack([problem.points_curr, anchor])),
        cov_prev=np.ascontiguousarray(np.concatenate([problem.cov_prev, huge])),
        cov_curr=np.ascontiguousarray(np.concatenate([problem.cov_curr, huge])),
    )
    samples = np.column_stack([pairs, np.full(len(pairs), problem.n)])
    return extended, samples


def test_rigidity_gate_passes_its_probability_of_inlier_distances():
    """The check built from ``rigidity_gate_probability`` gates each pairwise distance change at the
    chi-square(1) quantile of that probability: on inlier-only frames (Gaussian pixel noise, the
    true motion) the fraction of disjoint pairs passed matches the probability within a binomial
    tolerance, and the probability moves the gate as the chi-square(1) quantiles predict."""
    from scipy.stats import chi2

    from stereovo.estimation import recipes
    from stereovo.estimation.estimator_options import EstimatorOptions
    from stereovo.simulation import SimulationConfig, simulate_frame

    cases = []
    for seed in range(10):
        frame = simulate_frame(SimulationConfig(n_correspondences=400, outlier_ratio=0.0), np.random.default_rng(seed))
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
        assert problem.usable is None
        order = np.random.default_rng(100 + seed).permutation(problem.n)
        pairs = order[: 2 * (problem.n // 2)].reshape(-1, 2)  # disjoint pairs: independent trials
        cases.append(_pairs_with_a_lenient_anchor(problem, pairs))
    n_pairs = sum(len(samples) for _, samples in cases)
    assert n_pairs >= 1900
    rates = {}
    for p in (0.5, 0.9, 0.999):
        check = recipes.sample_check(EstimatorOptions(rigidity_gate_probability=p))
        rates[p] = np.mean(np.concatenate([check.accept(problem, samples) for problem, samples in cases]))
        tolerance = 4.0 * np.sqrt(p * (1.0 - p) / n_pairs) + 0.01  # binomial, plus first-order slack
        assert abs(rates[p] - p) <= tolerance, (p, rates[p], tolerance)
        assert check.threshold_sq == pytest.approx(chi2.ppf(p, 1), rel=1e-9)
    # the gate follows the probability: at 0.5 it passes about half as many as at 0.999
    assert rates[0.5] < rates[0.9] < rates[0.999]
    assert rates[0.999] - rates[0.5] > 0.4
