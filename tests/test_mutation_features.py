"""The features' contracts that the mutmut run of ``vo_gym/features.py`` found untested
(docs/mutation-testing.md): the rigid-consistency degree's exact value and its anchors, and the
validation of the previous motion and of a reused problem.

The degree's reference below is written from its definition (Hirschmueller, Innocent & Garibaldi,
"Fast, unconstrained camera motion estimation from stereo without tracking and robust statistics",
ICARCV 2002): the fraction of the anchors j other than i with
``(|Q_i - Q_j| - |P_i - P_j|)^2 < gate^2 (s_i^2 + s_j^2)``, the anchors being all rows, or above
MAX_ANCHORS the best by priority (ties by row) or evenly spaced rows.
"""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation.problem import StereoProblem
from stereovo.simulation import SimulationConfig, simulate_frame
from vo_gym.features import (FEATURE_BOUND, FEATURE_NAMES, MAX_ANCHORS, N_FEATURES, compute_features,
                             rigid_consistency_degree, usable_rows)


def _reference(P, Q, spread, anchors, gate=3.0):
    out = []
    for i in range(len(P)):
        others = [j for j in anchors if j != i]
        kept = sum((np.linalg.norm(Q[i] - Q[j]) - np.linalg.norm(P[i] - P[j])) ** 2
                   < gate**2 * (spread[i] ** 2 + spread[j] ** 2) for j in others)
        out.append(kept / len(others))
    return np.array(out, dtype=np.float32)


def test_degree_by_hand_on_four_matches():
    P = np.array([[0.0, 0.0, 10.0], [1.0, 0.0, 10.0], [0.0, 1.0, 10.0], [0.0, 0.0, 11.0]])
    Q = P.copy()
    Q[3, 2] = 11.2  # its distance to match 0 grows by 0.2 = 1.41 sigma of the pair (s = 0.1 each)
    spread = np.full(4, 0.1)
    degree = rigid_consistency_degree(P, Q, spread)
    assert degree.dtype == np.float32
    np.testing.assert_array_equal(degree, _reference(P, Q, spread, range(4)))
    # At gate 3 match 3 keeps all three distances; at gate 1 it keeps none (0.2, 0.148, 0.148 > 0.141).
    assert degree.tolist() == [1.0, 1.0, 1.0, 1.0]
    np.testing.assert_array_equal(rigid_consistency_degree(P, Q, spread, gate=1.0), np.float32([2 / 3, 2 / 3, 2 / 3, 0]))
    # One match has no other to compare with: 0; two rigid ones keep their distance: 1 each.
    one = rigid_consistency_degree(P[:1], Q[:1], spread[:1])
    assert one.dtype == np.float32 and one.tolist() == [0.0]
    assert rigid_consistency_degree(P[:2], Q[:2], spread[:2]).tolist() == [1.0, 1.0]


def _many(n=300, moved=(0, 17, 200, 299)):
    rng = np.random.default_rng(8)
    P = rng.uniform(-1.0, 1.0, (n, 3)) + [0.0, 0.0, 10.0]
    Q = P.copy()
    for k, row in enumerate(moved):  # 10 m apart from each other and from the rigid rows: kept by none
        Q[row, 0] += 10.0 * (k + 1)
    return P, Q, np.full(n, 1e-3)


def test_degree_above_max_anchors_uses_evenly_spaced_rows_without_priority():
    P, Q, spread = _many()
    n = P.shape[0]
    anchors = sorted({round(k * (n - 1) / (MAX_ANCHORS - 1)) for k in range(MAX_ANCHORS)})
    assert len(anchors) == MAX_ANCHORS and anchors[0] == 0 and anchors[-1] == n - 1
    np.testing.assert_array_equal(rigid_consistency_degree(P, Q, spread), _reference(P, Q, spread, anchors))


def test_degree_above_max_anchors_uses_the_best_priorities_ties_by_row():
    P, Q, spread = _many()
    n = P.shape[0]
    priority = np.random.default_rng(0).integers(0, 3, n).astype(float)  # many ties across the cut
    anchors = sorted(sorted(range(n), key=lambda i: (-priority[i], i))[:MAX_ANCHORS])
    expected = _reference(P, Q, spread, anchors)
    np.testing.assert_array_equal(rigid_consistency_degree(P, Q, spread, priority=priority), expected)
    order = np.argsort(-priority, kind="stable")
    np.testing.assert_array_equal(rigid_consistency_degree(P, Q, spread, priority=priority, priority_order=order),
                                  expected)


def _frame():
    frame = simulate_frame(SimulationConfig(n_correspondences=30, outlier_ratio=0.3), 6)
    return frame, StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)


def test_previous_motion_and_camera_are_validated_with_exact_messages():
    frame, _ = _frame()

    def features(motion, camera=frame.camera):
        return compute_features(frame.prev, frame.curr, frame.scores, camera, frame.noise_sigma, motion)

    with pytest.raises(ValueError, match=r"^previous_motion must be None or a pair \(R \(3, 3\), t \(3,\)\)$"):
        features(np.eye(3))
    with pytest.raises(ValueError, match=r"^previous_motion must be finite \(R \(3, 3\), t \(3,\)\), got shapes "
                                         r"\(3, 3\) and \(3,\)$"):
        features((np.eye(3), [np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match=r"^camera must be a StereoCamera, got str$"):
        features(None, camera="rig")
    # Integer motions are the same motions: the identity given as ints predicts like the float one.
    np.testing.assert_array_equal(features((np.eye(3, dtype=int), [0, 0, 0])), features((np.eye(3), np.zeros(3))))


def test_a_problem_of_other_measurements_is_refused():
    frame, problem = _frame()
    other_prev = frame.prev.copy()
    other_prev[0, 0] += 1.0
    with pytest.raises(ValueError, match="problem must be built from the same prev, curr, camera and noise_sigma"):
        compute_features(other_prev, problem.curr, frame.scores, frame.camera, frame.noise_sigma, problem=problem)
    # The problem's own arrays (the environment's case) give the features computed from scratch.
    np.testing.assert_array_equal(
        compute_features(problem.prev, problem.curr, frame.scores, frame.camera, frame.noise_sigma, problem=problem),
        compute_features(frame.prev, frame.curr, frame.scores, frame.camera, frame.noise_sigma))


def _degree_fast(P, Q, spread, anchors):
    """The same definition as _reference, one row against all anchors at a time."""
    anchors = np.asarray(anchors)
    out = np.empty(len(P))
    for i in range(len(P)):
        others = anchors[anchors != i]
        change = np.linalg.norm(Q[i] - Q[others], axis=1) - np.linalg.norm(P[i] - P[others], axis=1)
        out[i] = np.count_nonzero(change**2 < 9.0 * (spread[i] ** 2 + spread[others] ** 2)) / others.size
    return out.astype(np.float32)


def _by_definition(frame, scores, motion, unusable):
    """Every column from the module doc's table, with the camera's own triangulation and reprojection."""
    from stereovo.estimation.roles.reprojection import reprojection_sq

    cam, sigma, n = frame.camera, frame.noise_sigma, len(scores)
    prev, curr = frame.prev.copy(), frame.curr.copy()
    prev[unusable, 2] = prev[unusable, 0]  # zero disparity: no depth
    Pp, Cp, _ = cam.triangulate_usable(prev, sigma)
    Pc, Cc, _ = cam.triangulate_usable(curr, sigma)
    out = np.zeros((n, 14))
    out[:, 0] = scores
    order = sorted(range(n), key=lambda i: (-scores[i], i))
    out[order, 1] = np.arange(n) / max(n - 1, 1)
    for col, m in ((2, prev), (5, curr)):
        out[:, col] = m[:, 0] * 2 / (cam.width - 1) - 1
        out[:, col + 1] = m[:, 1] * 2 / (cam.height - 1) - 1
        out[:, col + 2] = (m[:, 0] - m[:, 2]) * 10 / cam.fx
    with np.errstate(invalid="ignore", divide="ignore"):
        out[:, 8], out[:, 9] = np.log(Pp[:, 2] / 10), np.log(Pc[:, 2] / 10)
        out[:, 10] = 0.5 * np.log(Cp[:, 2, 2])
        if motion is not None:
            sq = reprojection_sq(cam, motion[0][None], motion[1][None], Pp, curr)[0]
            out[:, 11] = np.log1p(np.sqrt(sq / 4) / sigma)
            out[:, 12] = 1.0
    spread = np.sqrt(np.trace(Cp, axis1=1, axis2=2) + np.trace(Cc, axis1=1, axis2=2))
    rows = np.setdiff1d(np.arange(n), unusable)
    anchors = np.arange(rows.size) if rows.size <= MAX_ANCHORS else \
        np.sort(sorted(range(rows.size), key=lambda i: (-scores[rows][i], i))[:MAX_ANCHORS])
    out[rows, 13] = _degree_fast(Pp[rows], Pc[rows], spread[rows], anchors)
    out[unusable, 8:11], out[unusable, 11], out[unusable, 13] = 10.0, 0.0, 0.0
    return prev, curr, np.clip(out, -10, 10).astype(np.float32)


@pytest.mark.parametrize("n, unusable", [(40, [3, 17]), (300, [5, 250])], ids=["40 matches", "300 matches"])
def test_every_column_by_its_definition(n, unusable):
    frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=0.4), 12)
    scores = np.round(frame.scores, 1)  # ties: ranks and anchors break them by row
    scores[0], scores[1] = 20.0, -20.0  # clipped to the bound
    motion = (frame.truth.rotation, frame.truth.translation)
    prev, curr, expected = _by_definition(frame, scores, motion, unusable)
    with np.errstate(all="raise"):  # rows without depth raise no floating-point warning either
        got = compute_features(prev, curr, scores, frame.camera, frame.noise_sigma, motion)
    np.testing.assert_allclose(got, expected, rtol=2e-6, atol=1e-6)
    np.testing.assert_array_equal(got[:, 13], expected[:, 13])
    # The same from a problem built for the estimator (its usable mask included).
    problem = StereoProblem.build(prev, curr, frame.camera, frame.noise_sigma)
    np.testing.assert_array_equal(compute_features(prev, curr, scores, frame.camera, frame.noise_sigma, motion, problem),
                                  got)


def test_two_and_one_matches_and_the_input_checks():
    frame = simulate_frame(SimulationConfig(n_correspondences=30, outlier_ratio=0.3), 6)
    cam, sigma = frame.camera, frame.noise_sigma
    two = compute_features(frame.prev[:2], frame.curr[:2], np.array([0.2, 0.9]), cam, sigma)
    assert two[:, 1].tolist() == [1.0, 0.0]  # rank / (n - 1)
    one = compute_features(frame.prev[:1], frame.curr[:1], np.array([0.7]), cam, sigma)
    assert one[0, 0] == np.float32(0.7) and one[0, 1] == 0.0 and one[0, 13] == 0.0 and one[0, 8] != 0.0
    # Boolean and integer scores are numbers.
    np.testing.assert_array_equal(compute_features(frame.prev, frame.curr, frame.scores > 0.5, cam, sigma),
                                  compute_features(frame.prev, frame.curr, (frame.scores > 0.5) * 1.0, cam, sigma))
    bad_curr = frame.curr.copy()
    bad_curr[0, 0] = np.nan
    flagged = compute_features(frame.prev, bad_curr, frame.scores, cam, sigma)  # NaN: an unusable row
    assert np.all(np.isfinite(flagged)) and flagged[0, 13] == 0.0 and flagged[0, 11] == 0.0
    cases = [((frame.prev, frame.curr, frame.scores, cam, -1.0),
              r"^noise_sigma must be a finite number in \[0\.001, 1000\] \(px\), got -1\.0$"),
             ((frame.prev, frame.curr[:29], frame.scores, cam, sigma),
              r"^prev and curr must have the same number of rows, got 30 and 29$"),
             ((frame.prev, frame.curr, "abc", cam, sigma), r"^scores must be a finite \(30,\) array of numbers, got str$"),
             ((frame.prev, frame.curr, frame.scores.astype(complex), cam, sigma),
              r"^scores must be real, got complex dtype complex128$")]
    for args, message in cases:
        with pytest.raises(ValueError, match=message):
            compute_features(*args)
    # A problem whose curr differs (prev the problem's own) is refused, with the exact message.
    problem = StereoProblem.build(frame.prev, frame.curr, cam, sigma)
    other_curr = frame.curr.copy()
    other_curr[0, 0] += 1.0
    with pytest.raises(ValueError, match=r"^problem must be built from the same prev, curr, camera and noise_sigma$"):
        compute_features(problem.prev, other_curr, frame.scores, cam, sigma, problem=problem)
    assert compute_features(frame.prev[:0], frame.curr[:0], np.zeros(0), cam, sigma).shape == (0, 14)


def test_degree_compares_float32_points_in_double_precision():
    # Two matches whose distance is 5 m at one frame and sqrt(25 + 2^-22) m, 5 + 2.4e-8 m, at the other (every
    # coordinate exact in float32): the change^2, about 5.7e-16 m^2, is above gate^2 (s_0^2 + s_1^2) = 9 * 2e-18, so
    # neither keeps the other, degree 0. In float32 arithmetic 25 + 2^-22 rounds to 25 and the pair would look
    # rigid (degree 1): float32 points are read as float64, at either frame.
    near = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]])
    off = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 2.0**-11]])
    spread = np.full(2, 1e-9)
    assert (np.sqrt(25 + 2.0**-22) - 5) ** 2 > 9 * 2e-18
    for P, Q in ((off, near), (near, off)):
        for dtype in (np.float64, np.float32):
            degree = rigid_consistency_degree(P.astype(dtype), Q.astype(dtype), spread)
            assert degree.tolist() == [0.0, 0.0], (P, dtype)
    # and a pair that keeps its distance within the gate stays consistent: degree 1
    assert rigid_consistency_degree(near.astype(np.float32), near.astype(np.float32), spread).tolist() == [1.0, 1.0]


def test_usable_rows_are_those_under_the_depth_flag():
    # a row without a depth carries log_depth_prev = +FEATURE_BOUND exactly (the module doc); every other column
    # is ignored, and a nested list is read as an array
    col = FEATURE_NAMES.index("log_depth_prev")
    features = np.zeros((4, N_FEATURES), dtype=np.float32)
    features[:, [c for c in range(N_FEATURES) if c != col]] = FEATURE_BOUND  # the other columns at the flag
    features[:, col] = [0.0, FEATURE_BOUND, np.nextafter(np.float32(FEATURE_BOUND), np.float32(0)), -FEATURE_BOUND]
    assert usable_rows(features).tolist() == [True, False, True, True]
    assert usable_rows(features.tolist()).tolist() == [True, False, True, True]
