"""The post-condition of every method (stereovo.estimation.loop.final_report) and the rows it rests on.

"ok" means: the returned pose is finite, at least ``min_inliers`` rows pass the method's own final
gate under it, and the returned inliers are exactly those rows. Checked on hostile frames, whose
match errors (independent left/right moves, duplicates, far clutter, repetitive texture,
Student-t noise) no method was built on, and on a rendered frame pair through the image front end.
"""

from __future__ import annotations

import numpy as np
import pytest

from stereovo import estimate_motion
from stereovo.benchmark.runner import METHOD_INPUTS, score_inputs
from stereovo.estimation import available_methods
from stereovo.estimation.loop import final_report
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.refinement import ReprojectionRefiner
from stereovo.estimation.roles.scoring import InlierCount, ReprojectionResidual
from stereovo.geometry import so3_exp
from stereovo.metrics import frame_metrics
from stereovo.simulation import SimulationConfig, simulate_frame

COUNTS = dict(n_hypotheses=1, n_scored=1, n_degenerate=0, n_local_optimizations=0, best_found_at=1)
FRAMES = [simulate_frame(SimulationConfig(n_correspondences=150, outlier_ratio=eps, outliers="hostile"), seed)
          for seed, eps in ((11, 0.5), (12, 0.8))]


@pytest.fixture(scope="module")
def rendered_frame():
    """One frame pair of a rendered drive through the ORB front end (real matcher errors)."""
    from images_support import rendered

    sequence = rendered(preset="car", n_frames=2, resolution="vga", seed=3)
    frame = sequence.frame(1)
    sequence.close()
    return frame


@pytest.mark.parametrize("method", sorted(available_methods()))
def test_ok_means_the_returned_inliers_pass_the_final_gate_under_the_returned_pose(method, rendered_frame):
    for i, frame in enumerate([*FRAMES, rendered_frame]):
        est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=i, max_iterations=2000,
                              noise_sigma=frame.noise_sigma,
                              **score_inputs(frame, METHOD_INPUTS.get(method)))
        if not est.ok:
            assert est.n_inliers == 0 and np.array_equal(est.rotation, np.eye(3))
            continue
        assert np.all(np.isfinite(est.rotation)) and np.all(np.isfinite(est.translation))
        gate_model, gate_sq = est.report.gate
        problem, rows = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma).usable_subproblem()
        passing = gate_model.squared(problem, est.rotation[None], est.translation[None])[0] < gate_sq
        returned = est.inliers if rows is None else est.inliers[rows]
        np.testing.assert_array_equal(returned, passing)
        assert not np.any(est.inliers & est.unusable)
        assert passing.sum() >= 6


@pytest.mark.parametrize("seed", [2, 15, 24])
@pytest.mark.parametrize("method", ["probabilistic", "mlesac", "guided-mlesac", "bansac"])
def test_no_confident_absurd_pose_where_far_rows_once_won_the_consensus(method, seed):
    # Hostile frames at eps 0.8, N 500 on which the estimator before the post-condition and the
    # resolvable-depth rule returned "ok" with a rotation error of 140-175 deg, translations of
    # 1.9-22 km and 93-327 inliers (probabilistic), none of which passed its gate.
    frame = simulate_frame(SimulationConfig(n_correspondences=500, outlier_ratio=0.8, outliers="hostile"), seed)
    given = score_inputs(frame, METHOD_INPUTS.get(method))
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=0, **given)
    errors = frame_metrics(est, frame.truth)
    assert not (est.ok and (errors.rot_err_deg > 10 or errors.trans_err_m > 1)), (est.status, errors)
    if method == "probabilistic":
        assert errors.success


def test_unresolvable_rows_are_unusable_and_never_inliers():
    frame = simulate_frame(SimulationConfig(n_correspondences=300, outlier_ratio=0.6, outliers="hostile"), 4)
    sigma_d = np.sqrt(2) * frame.noise_sigma
    low = np.minimum(frame.prev[:, 0] - frame.prev[:, 2], frame.curr[:, 0] - frame.curr[:, 2]) <= 2 * sigma_d
    est = estimate_motion(frame.prev, frame.curr, frame.camera, rng=0)
    np.testing.assert_array_equal(est.unusable, low)
    assert low.any() and not np.any(est.inliers & low)
    # min_disparity_sigmas=0 keeps them (the papers' inputs); only disparities at or below min_disparity go
    kept = estimate_motion(frame.prev, frame.curr, frame.camera, rng=0, min_disparity_sigmas=0.0)
    assert kept.n_unusable < est.n_unusable


def test_nan_rows_are_flagged_not_refused():
    frame = simulate_frame(SimulationConfig(n_correspondences=200, outlier_ratio=0.3), 1)
    prev, curr = frame.prev.copy(), frame.curr.copy()
    prev[[3, 7], 0] = np.nan
    curr[9, 2] = np.inf
    est = estimate_motion(prev, curr, frame.camera, rng=0)
    assert est.ok and frame_metrics(est, frame.truth).success
    assert est.unusable[[3, 7, 9]].all() and not est.inliers[[3, 7, 9]].any()
    with pytest.raises(ValueError, match=r"prev must have shape \(N, 4\)"):
        estimate_motion(prev[:, :3], curr, frame.camera)
    with pytest.raises(ValueError, match="min_disparity_sigmas must be"):
        estimate_motion(prev, curr, frame.camera, min_disparity_sigmas=-1.0)


class _Refiner:
    """A refiner whose result is given: the pose it returns, whatever it is handed."""

    gate = None
    rounds = 1

    def __init__(self, R: np.ndarray, t: np.ndarray) -> None:
        self.R, self.t = R, t

    def refine_with_residuals(self, problem, R, t, inliers, residual_model, threshold_sq):
        return self.R, self.t, inliers, None


@pytest.mark.parametrize("bad", ["diverged", "nan"])
def test_a_refinement_that_loses_support_or_diverges_is_rolled_back(bad):
    frame = simulate_frame(SimulationConfig(n_correspondences=200, outlier_ratio=0.3), 2)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    gate = ReprojectionResidual(9.0)
    R, t = frame.truth.rotation, frame.truth.translation
    good = gate.squared(problem, R[None], t[None])[0] < 9.0
    away = (so3_exp(np.array([0.0, 0.2, 0.0])) @ R, t + 2.0) if bad == "diverged" else (np.full((3, 3), np.nan), t)
    report = final_report(problem, R, t, good, float(good.sum()), _Refiner(*away), gate, InlierCount(), 9.0, 6, {},
                          **COUNTS)
    assert report.status == "ok" and report.counters["refine_rolled_back"] == 1
    np.testing.assert_array_equal(report.rotation, R)
    np.testing.assert_array_equal(report.inliers, good)  # re-selected under the pose it kept
    # a refinement that is no worse is kept, and its inliers are selected under its pose
    kept = final_report(problem, R, t, good, float(good.sum()), ReprojectionRefiner(rounds=1), gate, InlierCount(),
                        9.0, 6, {}, **COUNTS)
    assert kept.counters["refine_rolled_back"] == 0 and kept.inliers.sum() >= good.sum()
    np.testing.assert_array_equal(kept.inliers, gate.squared(problem, kept.rotation[None], kept.translation[None])[0] < 9.0)


def test_a_non_finite_best_model_fails():
    frame = simulate_frame(SimulationConfig(n_correspondences=100, outlier_ratio=0.3), 3)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    R = np.full((3, 3), np.nan)
    report = final_report(problem, R, np.zeros(3), np.ones(100, dtype=bool), 100.0, None, ReprojectionResidual(9.0),
                          InlierCount(), 9.0, 6, {}, **COUNTS)
    assert report.status.startswith("failed") and not report.inliers.any()
