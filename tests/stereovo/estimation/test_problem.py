"""StereoProblem: rows without depth are outliers, not errors, and the input contract at the
problem's boundary (non-real values refused by name, other layouts converted once)."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo import StereoCamera, estimate_motion
from stereovo.estimation import StereoProblem
from stereovo.geometry import rotation_error
from stereovo.metrics import frame_metrics
from stereovo.simulation import SimulationConfig, simulate_frame
from tests.support.frames import CAMERA
from tests.support.rows import spoil_rows


def _kernel_signatures() -> dict[str, int]:
    """Compiled signatures of every numba kernel of the package (its kernel modules' private ones too)."""
    from stereovo.compilation import package_kernels

    return {f"{k.py_func.__module__}.{k.py_func.__qualname__}": len(k.signatures) for k in package_kernels()}


@pytest.mark.parametrize("method", ["probabilistic", "ransac", "msac", "mlesac", "inlier-detection"])
def test_unusable_rows_are_reported_and_never_inliers(frame, method):
    rows = np.array([0, 5, 17, 42, 100, 299])
    prev, curr = spoil_rows(frame, rows[:3], "prev")
    curr[rows[3:], 2] = curr[rows[3:], 0] + 0.05  # disparity -0.05: none either
    est = estimate_motion(prev, curr, CAMERA, method=method, rng=3)
    assert est.ok, est.status
    expected = np.zeros(frame.n, dtype=bool)
    expected[rows] = True
    np.testing.assert_array_equal(est.unusable, expected)
    assert est.n_unusable == rows.size
    assert est.inliers.shape == (frame.n,) and not est.inliers[rows].any()
    assert np.degrees(rotation_error(est.rotation, frame.truth.rotation)) < 0.5


def test_a_frame_without_unusable_rows_is_unchanged_and_not_copied(frame):
    problem = StereoProblem.build(frame.prev, frame.curr, CAMERA, 0.5)
    assert problem.usable is None and problem.n_unusable == 0
    assert problem.prev is frame.prev  # C-contiguous float64 already: no copy
    sub, rows = problem.usable_subproblem()
    assert sub is problem and rows is None


def test_result_equals_the_estimate_on_the_usable_rows_alone(frame):
    rows = np.array([3, 4, 250])
    prev, curr = spoil_rows(frame, rows, "curr")
    keep = np.setdiff1d(np.arange(frame.n), rows)
    full = estimate_motion(prev, curr, CAMERA, rng=9)
    alone = estimate_motion(prev[keep], curr[keep], CAMERA, rng=9)
    np.testing.assert_array_equal(full.rotation, alone.rotation)
    np.testing.assert_array_equal(full.translation, alone.translation)
    np.testing.assert_array_equal(full.inliers[keep], alone.inliers)
    np.testing.assert_array_equal(full.covariance, alone.covariance)


def test_priors_and_order_map_to_the_usable_rows(frame):
    rows = np.array([1, 2, 10])
    prev, curr = spoil_rows(frame, rows, "prev")
    keep = np.setdiff1d(np.arange(frame.n), rows)
    order = np.argsort(-frame.scores, kind="stable")
    full = estimate_motion(prev, curr, CAMERA, method="prosac", order=order, rng=1)
    # the permutation's relative order of the usable rows, renumbered among them
    position = np.full(frame.n, -1)
    position[keep] = np.arange(keep.size)
    sub_order = position[order][position[order] >= 0]
    alone = estimate_motion(prev[keep], curr[keep], CAMERA, method="prosac", order=sub_order, rng=1)
    np.testing.assert_array_equal(full.rotation, alone.rotation)
    np.testing.assert_array_equal(full.inliers[keep], alone.inliers)
    guided = estimate_motion(prev, curr, CAMERA, method="ransac", priors=frame.scores, rng=1)
    guided_alone = estimate_motion(prev[keep], curr[keep], CAMERA, method="ransac", priors=frame.scores[keep], rng=1)
    np.testing.assert_array_equal(guided.rotation, guided_alone.rotation)


def test_too_few_usable_rows_is_a_failed_status_naming_the_counts(frame):
    prev, curr = spoil_rows(frame, np.arange(2, frame.n), "prev")
    est = estimate_motion(prev, curr, CAMERA)
    assert not est.ok
    assert est.status == f"failed: too few usable correspondences (2 of {frame.n} usable, need 6)"
    assert est.n_unusable == frame.n - 2 and est.covariance is None
    np.testing.assert_array_equal(est.rotation, np.eye(3))


def test_priors_only_on_unusable_rows_fail_the_frame_without_raising(frame):
    prev, curr = spoil_rows(frame, np.arange(3), "prev")
    priors = np.zeros(frame.n)
    priors[:3] = 1.0
    est = estimate_motion(prev, curr, CAMERA, method="ransac", priors=priors)
    assert not est.ok and "positive weights" in est.status


def test_far_and_non_finite_depth_rows_are_unusable():
    cam = StereoCamera()
    meas = np.array([[600.0, 100, 590, 100], [600.0, 100, 599.95, 100], [1e308, 100, -1e308, 100]])
    points, cov, usable = cam.triangulate_usable(meas, 0.5)
    np.testing.assert_array_equal(usable, [True, False, False])
    assert np.all(np.isnan(points[1:])) and np.all(np.isnan(cov[1:]))
    with pytest.raises(ValueError, match="no depth"):
        cam.triangulate(meas)


@pytest.mark.parametrize("name", ["prev", "curr"])
def test_complex_measurements_are_refused_by_name_without_a_cast(frame, name):
    prev, curr = frame.prev.astype(complex), frame.curr.copy()
    if name == "curr":
        prev, curr = frame.prev.copy(), frame.curr.astype(complex)
    with pytest.raises(ValueError, match=f"{name} must be real"):
        estimate_motion(prev, curr, CAMERA)
    with pytest.raises(ValueError, match=f"{name} must be real"):
        StereoProblem.build(prev, curr, CAMERA)


def test_other_layouts_are_converted_once_to_the_same_result(frame):
    reference = estimate_motion(frame.prev, frame.curr, CAMERA, rng=2)
    fortran = estimate_motion(np.asfortranarray(frame.prev), np.asfortranarray(frame.curr), CAMERA, rng=2)
    wide = np.zeros((frame.n, 8))
    wide[:, ::2] = frame.prev
    strided = estimate_motion(wide[:, ::2], frame.curr, CAMERA, rng=2)
    as_list = estimate_motion(frame.prev.tolist(), frame.curr.tolist(), CAMERA, rng=2)
    for est in (fortran, strided, as_list):
        np.testing.assert_array_equal(est.rotation, reference.rotation)
        np.testing.assert_array_equal(est.inliers, reference.inliers)
    problem = StereoProblem.build(np.asfortranarray(frame.prev), frame.curr.astype(np.float32), CAMERA)
    for array in (problem.prev, problem.curr):
        assert array.dtype == np.float64 and array.flags.c_contiguous


def test_other_layouts_compile_nothing_new(frame):
    """A Fortran-order, strided or float32 input is converted once at the boundary: after a warm-up
    call with ordinary arrays, no kernel gains a compiled signature (each new one costs 11-28 s of compiling)."""
    for method, kw in (("probabilistic", {}), ("ransac", {"priors": frame.scores})):
        estimate_motion(frame.prev, frame.curr, CAMERA, method=method, rng=0, **kw)
    before = _kernel_signatures()
    wide = np.zeros((frame.n, 8))
    wide[:, 1::2] = frame.curr
    estimate_motion(np.asfortranarray(frame.prev), wide[:, 1::2], CAMERA, rng=0)
    estimate_motion(frame.prev.astype(np.float32), frame.curr, CAMERA, method="ransac",
                    priors=np.asfortranarray(np.stack([frame.scores, frame.scores], 1))[:, 0], rng=0)
    assert _kernel_signatures() == before


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
