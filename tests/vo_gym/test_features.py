"""vo_gym.features: layout, label-free inputs, meaning of the columns, the rigid-consistency degree,
unusable rows, malformed input.

Just past 600 lines: the compiled fast paths (the consistency counts, the clip, the score order) are
each held to the numpy formulation they replaced here, beside the behaviour they compute."""

from __future__ import annotations

import dataclasses
import inspect
import warnings

import numpy as np
import pytest
from hypothesis import given, strategies as st
from scipy.stats import rankdata

from stereovo import StereoCamera
from stereovo.estimation import StereoProblem
from stereovo.estimation.kernels.rigidity import distance_change_sq, rigid_distance_consistent
from stereovo.geometry import relative_motion
from stereovo.simulation import Sequence, SimulationConfig, simulate_frame
from tests.support.frames import CAMERA
from tests.support.fuzz import FUZZ, WEIRD_NUMBERS, corrupted, fuzz_frame, measurements, names_an_argument
from tests.support.rows import spoil_rows
from vo_gym import features as F
from vo_gym.features import (
    FEATURE_BOUND,
    FEATURE_LAYOUT_VERSION,
    FEATURE_NAMES,
    N_FEATURES,
    check_feature_layout,
    compute_features,
    feature_index,
    MAX_ANCHORS,
    rigid_consistency_degree,
    usable_rows,
)


@pytest.fixture(scope="module")
def sequence() -> Sequence:
    return Sequence(SimulationConfig(n_frames=4, outlier_ratio=0.6), seed=7)


def _auc(values: np.ndarray, positive: np.ndarray) -> float:
    """ROC AUC of ``values`` as a detector of ``positive`` (Mann-Whitney)."""
    ranks = rankdata(values)
    n1, n0 = positive.sum(), (~positive).sum()
    return float((ranks[positive].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def _features(frame, motion=None) -> np.ndarray:
    return compute_features(frame.prev, frame.curr, frame.scores, frame.camera, frame.noise_sigma, motion)


def _full_counts(P, Q, s2, anchors, gate_sq):
    """Every match against every anchor, in numpy: the formulation the compiled kernel replaced."""
    d = distance_change_sq(*(P[anchors][None, :, c] - P[:, None, c] for c in range(3)),
                           *(Q[anchors][None, :, c] - Q[:, None, c] for c in range(3)))
    return rigid_distance_consistent(d, s2[:, None] + s2[anchors][None, :], gate_sq).sum(axis=1)


def test_layout_constants():
    assert N_FEATURES == 14 and len(FEATURE_NAMES) == 14 == len(set(FEATURE_NAMES))
    assert FEATURE_LAYOUT_VERSION == 1
    assert [feature_index(name) for name in FEATURE_NAMES] == list(range(N_FEATURES))
    with pytest.raises(ValueError, match="unknown feature"):
        feature_index("inlier")


def test_check_feature_layout_refuses_other_layouts():
    check_feature_layout(FEATURE_NAMES, FEATURE_LAYOUT_VERSION)
    check_feature_layout(list(FEATURE_NAMES), FEATURE_LAYOUT_VERSION)
    with pytest.raises(ValueError, match="feature layout mismatch"):
        check_feature_layout(FEATURE_NAMES, FEATURE_LAYOUT_VERSION + 1)
    with pytest.raises(ValueError, match="feature layout mismatch"):
        check_feature_layout(FEATURE_NAMES[::-1], FEATURE_LAYOUT_VERSION)


def test_inputs_carry_no_label():
    params = list(inspect.signature(compute_features).parameters)
    assert params == ["prev", "curr", "scores", "camera", "noise_sigma", "previous_motion", "problem"]
    # the optional problem holds only what the estimator sees: measurements, camera, noise, triangulation
    assert {f.name for f in dataclasses.fields(StereoProblem)} == {
        "prev", "curr", "camera", "noise_sigma", "points_prev", "points_curr", "cov_prev", "cov_curr",
        "usable",  # which rows have depth: computed from the measurements
        "min_disparity_sigmas",  # the rule for that: a setting, not a label
    }


def test_features_from_a_prebuilt_problem_are_identical_and_checked(sequence):
    frame = sequence.frame(2)
    motion = (frame.truth.rotation, frame.truth.translation)
    args = (frame.prev, frame.curr, frame.scores, frame.camera, frame.noise_sigma, motion)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    assert problem.prev is frame.prev  # the problem's own arrays: validated once, when it was built
    expected = compute_features(*args)
    np.testing.assert_array_equal(compute_features(*args, problem=problem), expected)
    copies = (frame.prev.copy(), frame.curr.copy(), *args[2:])  # equal arrays, other objects: compared
    np.testing.assert_array_equal(compute_features(*copies, problem=problem), expected)
    other = StereoProblem.build(frame.prev, frame.curr, frame.camera, 2 * frame.noise_sigma)
    with pytest.raises(ValueError, match="same prev, curr, camera and noise_sigma"):
        compute_features(*args, problem=other)
    next_frame = sequence.frame(3)
    with pytest.raises(ValueError, match="same prev, curr, camera and noise_sigma"):
        compute_features(next_frame.prev, next_frame.curr, *args[2:], problem=problem)
    # A camera equal to the problem's but another object is the same camera; another rig is refused.
    twin = dataclasses.replace(frame.camera)
    assert twin is not frame.camera and twin == frame.camera
    np.testing.assert_array_equal(compute_features(*args[:3], twin, *args[4:], problem=problem), expected)
    other_rig = StereoProblem.build(frame.prev, frame.curr, dataclasses.replace(frame.camera, baseline=0.6),
                                    frame.noise_sigma)
    with pytest.raises(ValueError, match="same prev, curr, camera and noise_sigma"):
        compute_features(*args, problem=other_rig)


def test_shape_dtype_bounds(sequence):
    frame = sequence.frame(1)
    x = _features(frame)
    assert x.shape == (frame.n, N_FEATURES) and x.dtype == np.float32
    assert np.all(np.isfinite(x)) and np.all(np.abs(x) <= FEATURE_BOUND)
    np.testing.assert_array_equal(x[:, feature_index("match_score")], frame.scores.astype(np.float32))
    for name in ("u_prev", "v_prev", "u_curr", "v_curr"):
        assert np.all(np.abs(x[:, feature_index(name)]) <= 1.0)
    assert np.all(x[:, feature_index("rigid_consistency")] >= 0) and np.all(x[:, feature_index("rigid_consistency")] <= 1)
    # Without a previous motion there is no prediction: residual 0 and the flag off.
    assert np.all(x[:, feature_index("cv_residual")] == 0) and np.all(x[:, feature_index("cv_available")] == 0)


def test_geometry_columns(sequence):
    frame = sequence.frame(2)
    x = _features(frame)
    cam = frame.camera
    depth = cam.triangulate(frame.prev)[:, 2]
    np.testing.assert_allclose(np.exp(x[:, feature_index("log_depth_prev")]) * 10.0, depth, rtol=1e-5)
    np.testing.assert_allclose(x[:, feature_index("disparity_prev")], 10 * cam.baseline / depth, rtol=1e-5)
    # Depth std grows as z^2: log std - 2 log z is constant.
    offset = x[:, feature_index("log_depth_std_prev")] - 2 * np.log(depth)
    assert np.ptp(offset) < 1e-3
    rank = x[:, feature_index("score_rank")]
    assert rank[np.argmax(frame.scores)] == 0 and rank[np.argmin(frame.scores)] == 1


def test_consistency_and_prediction_separate_inliers(sequence):
    """The label-free features carry real information about the (hidden) labels."""
    k = 3
    frame = sequence.frame(k)
    motion = relative_motion(sequence.true_poses[k - 2], sequence.true_poses[k - 1])  # last frame's motion
    x = _features(frame, motion)
    inlier = frame.truth.inlier
    assert _auc(x[:, feature_index("rigid_consistency")], inlier) > 0.8
    assert _auc(-x[:, feature_index("cv_residual")], inlier) > 0.8
    assert np.all(x[:, feature_index("cv_available")] == 1)


def test_row_permutation_equivariance(sequence):
    frame = sequence.frame(1)
    perm = np.random.default_rng(0).permutation(frame.n)
    a = _features(frame)[perm]
    b = compute_features(frame.prev[perm], frame.curr[perm], frame.scores[perm], frame.camera, frame.noise_sigma)
    # float32 sums in another order may flip a borderline pair of the consistency count.
    np.testing.assert_allclose(a, b, atol=3.0 / frame.n)


def test_large_frames_use_anchors(monkeypatch):
    frame = Sequence(SimulationConfig(n_frames=1, n_correspondences=300), seed=1).frame(1)
    full = _features(frame)[:, feature_index("rigid_consistency")]
    monkeypatch.setattr(F, "MAX_ANCHORS", 150)
    anchored = _features(frame)[:, feature_index("rigid_consistency")]
    assert np.all((anchored >= 0) & (anchored <= 1))
    assert np.corrcoef(full, anchored)[0, 1] > 0.9


def test_malformed_input(sequence, camera):
    frame = sequence.frame(1)
    args = (frame.prev, frame.curr, frame.scores, camera, 0.5)
    with pytest.raises(ValueError, match="prev must have shape"):
        compute_features(frame.prev[:, :3], *args[1:])
    with pytest.raises(ValueError, match="same number of rows"):
        compute_features(frame.prev, frame.curr[:-1], *args[2:])
    bad = frame.curr.copy()
    bad[3, 0] = np.nan  # a front end's failed match: an unusable row, flagged, not an error
    flagged = compute_features(frame.prev, bad, *args[2:])
    assert np.all(np.isfinite(flagged)) and flagged[3, 8] == FEATURE_BOUND and flagged[3, 13] == 0.0
    with pytest.raises(ValueError, match="scores"):
        compute_features(frame.prev, frame.curr, frame.scores[:-1], camera, 0.5)
    with pytest.raises(ValueError, match="noise_sigma"):
        compute_features(*args[:4], 0.0)
    with pytest.raises(ValueError, match="previous_motion"):
        compute_features(*args, previous_motion=(np.eye(3), np.zeros(2)))
    with pytest.raises(ValueError, match="camera"):
        compute_features(frame.prev, frame.curr, frame.scores, "kitti", 0.5)
    no_depth = frame.prev.copy()
    no_depth[0, 2] = no_depth[0, 0]  # zero disparity: not malformed, a flagged row (tests/stereovo/estimation/test_problem.py)
    flagged = compute_features(no_depth, *args[1:])
    assert np.all(np.isfinite(flagged)) and flagged[0, feature_index("log_depth_prev")] == FEATURE_BOUND
    with pytest.raises(ValueError, match="prev must be real"):
        compute_features(frame.prev + 0j, *args[1:])
    empty = compute_features(np.zeros((0, 4)), np.zeros((0, 4)), np.zeros(0), StereoCamera(), 0.5)
    assert empty.shape == (0, N_FEATURES)


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


def test_features_flag_unusable_rows_with_finite_values(frame):
    prev, curr = spoil_rows(frame, np.array([0, 9]), "curr")
    feats = compute_features(prev, curr, frame.scores, CAMERA, 0.5, previous_motion=(np.eye(3), np.zeros(3)))
    assert feats.shape == (frame.n, len(FEATURE_NAMES)) and np.all(np.isfinite(feats))
    np.testing.assert_array_equal(~usable_rows(feats), np.isin(np.arange(frame.n), [0, 9]))
    for name in ("log_depth_prev", "log_depth_curr", "log_depth_std_prev"):
        np.testing.assert_array_equal(feats[[0, 9], feature_index(name)], FEATURE_BOUND)
    np.testing.assert_array_equal(feats[[0, 9], feature_index("rigid_consistency")], 0.0)
    problem = StereoProblem.build(prev, curr, CAMERA, 0.5)
    with_problem = compute_features(prev, curr, frame.scores, CAMERA, 0.5, (np.eye(3), np.zeros(3)), problem=problem)
    np.testing.assert_array_equal(with_problem, feats)
    # the other rows' consistency degree is over the rows with depth only
    keep = np.setdiff1d(np.arange(frame.n), [0, 9])
    alone = compute_features(prev[keep], curr[keep], frame.scores[keep], CAMERA, 0.5)
    np.testing.assert_array_equal(feats[keep, feature_index("rigid_consistency")],
                                  alone[:, feature_index("rigid_consistency")])


VALID_NOISE = (0.5, 1.0, np.float32(0.3), 2.0, 1, np.int64(3))
UNUSUAL_VALID_KINDS = ("fortran", "strided", "float32", "int", "list", "duplicate", "constant")


def test_compute_features_fuzz():
    # Most examples draw a valid noise_sigma (and the measurements strategy a usable frame), so the success
    # path's assertions run; the rest are refused with an error naming the argument. Both are counted.
    outcomes = []

    @FUZZ
    @given(data=measurements(), valid_noise=st.sampled_from([True, True, True, False]),
           noise=st.sampled_from(VALID_NOISE), weird=WEIRD_NUMBERS,
           motion=st.sampled_from(["none", "none", "identity", "identity", "nan", "shape", "bad"]))
    def run(data, valid_noise, noise, weird, motion):
        prev, curr, scores, _ = data
        noise = noise if valid_noise else weird
        previous = {"none": None, "identity": (np.eye(3), np.zeros(3)),
                    "nan": (np.full((3, 3), np.nan), np.zeros(3)), "shape": (np.eye(2), np.zeros(3)),
                    "bad": "fast"}[motion]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error", np.exceptions.ComplexWarning)
                feats = compute_features(prev, curr, scores, CAMERA, noise, previous)
        except (ValueError, TypeError) as err:
            assert names_an_argument(err), repr(err)
            outcomes.append("refused")
            return
        n = np.shape(prev)[0]
        assert feats.shape == (n, N_FEATURES) and feats.dtype == np.float32
        assert np.all(np.isfinite(feats)) and np.all(np.abs(feats) <= FEATURE_BOUND)
        outcomes.append("computed")

    run()
    tally = {outcome: outcomes.count(outcome) for outcome in set(outcomes)}
    assert len(outcomes) == 30
    assert tally.get("computed", 0) >= 12 and tally.get("refused", 0) >= 5, tally


def _unusual(frame, kind):
    """The measurements strategy's valid-but-unusual input kinds (tests/support/fuzz.py), applied to frame."""
    prev, curr, _ = corrupted(frame.prev.copy(), frame.curr.copy(), frame.scores.copy(), kind)
    return prev, curr


@pytest.mark.parametrize("kind", UNUSUAL_VALID_KINDS)
def test_compute_features_takes_the_fuzzers_unusual_valid_inputs(kind):
    frame = fuzz_frame(3, 20, 0.3)
    for noise in VALID_NOISE:
        for previous in (None, (np.eye(3), np.zeros(3))):
            reference = compute_features(frame.prev, frame.curr, frame.scores, CAMERA, noise, previous)
            prev, curr = _unusual(frame, kind)
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                feats = compute_features(prev, curr, frame.scores, CAMERA, noise, previous)
            assert feats.shape == (20, N_FEATURES) and feats.dtype == np.float32
            assert np.all(np.isfinite(feats)) and np.all(np.abs(feats) <= FEATURE_BOUND)
            np.testing.assert_array_equal(compute_features(prev, curr, frame.scores, CAMERA, noise, previous), feats)
            if kind in ("fortran", "strided", "list"):  # the same values in another layout: the same features
                np.testing.assert_array_equal(feats, reference)
            elif kind == "float32":
                np.testing.assert_allclose(feats, reference, rtol=1e-4, atol=1e-4)
            elif kind == "constant":  # no motion: every row with a depth keeps its distances to every other
                usable = usable_rows(feats)
                assert usable.sum() >= 15
                np.testing.assert_array_equal(feats[usable, feature_index("rigid_consistency")], 1.0)


# --- The degree and every column by their definitions, the anchors' choice, the input checks' exact messages,
#     one- and two-match frames, float32 inputs read in double precision, the depth flag ---


def _reference(P, Q, spread, anchors, gate=3.0):
    out = []
    for i in range(len(P)):
        others = [j for j in anchors if j != i]
        kept = sum((np.linalg.norm(Q[i] - Q[j]) - np.linalg.norm(P[i] - P[j])) ** 2
                   < gate**2 * (spread[i] ** 2 + spread[j] ** 2) for j in others)
        out.append(kept / len(others))
    return np.array(out, dtype=np.float32)


def _many(n=300, moved=(0, 17, 200, 299)):
    rng = np.random.default_rng(8)
    P = rng.uniform(-1.0, 1.0, (n, 3)) + [0.0, 0.0, 10.0]
    Q = P.copy()
    for k, row in enumerate(moved):  # 10 m apart from each other and from the rigid rows: kept by none
        Q[row, 0] += 10.0 * (k + 1)
    return P, Q, np.full(n, 1e-3)


def _frame():
    frame = simulate_frame(SimulationConfig(n_correspondences=30, outlier_ratio=0.3), 6)
    return frame, StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)


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
    for not_a_pair in (5, (np.eye(3),), (np.eye(3), np.zeros(3), 0)):  # no length, or not two: the same message
        with pytest.raises(ValueError, match=r"^previous_motion must be None or a pair"):
            features(not_a_pair)
    for bad_sigma in ([0.5], "0.5", -1.0):  # a list is not hashed into the checked values' cache
        with pytest.raises(ValueError, match="noise_sigma"):
            compute_features(frame.prev, frame.curr, frame.scores, frame.camera, bad_sigma, None)
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
    # Integer scores are numbers; booleans are not (as everywhere numbers are taken: a mask passed as
    # scores is a mistake to name, not a score of 0 or 1).
    np.testing.assert_array_equal(compute_features(frame.prev, frame.curr, (frame.scores > 0.5).astype(int), cam, sigma),
                                  compute_features(frame.prev, frame.curr, (frame.scores > 0.5) * 1.0, cam, sigma))
    with pytest.raises(ValueError, match=r"scores must be .*got ndarray of dtype bool"):
        compute_features(frame.prev, frame.curr, frame.scores > 0.5, cam, sigma)
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
              r"^scores must be real numbers, got complex dtype complex128$"),
             ((frame.prev, frame.curr, frame.scores[:29], cam, sigma), r"^scores must have shape \(30,\), got \(29,\)$"),
             ((frame.prev, frame.curr, np.where(np.arange(30) < 2, np.nan, frame.scores), cam, sigma),
              r"^scores must be finite, got NaN or inf in 2 row\(s\)$")]
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
    # Raw arrays are validated by name, curr as prev: lists are read, a bad shape or type names its argument.
    np.testing.assert_array_equal(compute_features(frame.prev.tolist(), frame.curr.tolist(), frame.scores, cam, sigma),
                                  compute_features(frame.prev, frame.curr, frame.scores, cam, sigma))
    for name, (prev, curr) in (("prev", (frame.prev[:, :3], frame.curr)), ("curr", (frame.prev, frame.curr[:, :3])),
                               ("curr", (frame.prev, "abc"))):
        with pytest.raises(ValueError, match=rf"^{name} must "):
            compute_features(prev, curr, frame.scores, cam, sigma)


def test_features_use_the_given_noise_sigma_and_zero_the_pixels_of_a_nan_row():
    # Built here or handed in, the problem has the caller's noise_sigma (the uncertainty column reads it);
    # a row with a NaN pixel gets zeros, not NaN or another fill, in its pixel columns.
    frame = simulate_frame(SimulationConfig(n_correspondences=40, outlier_ratio=0.3), 8)
    cam = frame.camera
    for sigma in (0.5, 1.5):
        problem = StereoProblem.build(frame.prev, frame.curr, cam, sigma)
        np.testing.assert_array_equal(compute_features(frame.prev, frame.curr, frame.scores, cam, sigma),
                                      compute_features(problem.prev, problem.curr, frame.scores, cam, sigma,
                                                       problem=problem))
    loud = compute_features(frame.prev, frame.curr, frame.scores, cam, 1.5)
    quiet = compute_features(frame.prev, frame.curr, frame.scores, cam, 0.5)
    assert np.all(loud[:, 10] > quiet[:, 10])  # log of the depth's standard deviation grows with the noise
    bad = frame.prev.copy()
    bad[3, 1] = np.nan
    out = compute_features(bad, frame.curr, frame.scores, cam, 0.5)
    clean = compute_features(frame.prev, frame.curr, frame.scores, cam, 0.5)
    assert np.all(np.isfinite(out[3])) and out[3, 3] == 0.0 != clean[3, 3]  # v_prev of the NaN pixel: zero
    np.testing.assert_array_equal(np.delete(out[3, 2:8], 1), np.delete(clean[3, 2:8], 1))  # the others as given


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


def test_degree_squares_float32_spreads_in_double_precision():
    # Two matches 1 m apart at k-1 and 1 + c m apart at k, both spreads s = float32(0.3), gate 1: the pair is
    # consistent when c^2 < s^2 + s^2. s's square is 0.0900000071...; rounded to float32 it is 0.0900000035...
    # (rounded down). c^2 is placed between twice the rounded square and twice the exact one: consistent (degree
    # 1 each) with s squared in double precision, not (degree 0) with s squared in float32.
    s = np.float32(0.3)
    exact, rounded = float(s) ** 2, float(np.float32(float(s) ** 2))
    c = np.sqrt(exact + rounded)
    P = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    Q = np.array([[0.0, 0.0, 0.0], [1.0 + c, 0.0, 0.0]])
    assert 2 * rounded < ((1.0 + c) - 1.0) ** 2 < 2 * exact
    for spread in (np.full(2, s), np.full(2, float(s)), [float(s)] * 2):
        degree = rigid_consistency_degree(P, Q, spread, gate=1.0)
        assert degree.dtype == np.float32 and degree.tolist() == [1.0, 1.0], type(spread)


def test_pixel_columns_run_from_minus_one_to_one_across_a_two_pixel_image():
    # u * 2 / (width - 1) - 1 and v * 2 / (height - 1) - 1: the first pixel column or row at -1, the last at +1,
    # on a 2 x 2 image as on any other; the divisor's floor of 1 is for a side of one pixel, whose column or
    # row 0 maps to -1. (Disparities of 0.5 to 1 px have a depth at sigma 0.01 px.)
    columns = [feature_index(name) for name in ("u_prev", "v_prev", "u_curr", "v_curr")]
    two = StereoCamera(fx=100.0, fy=100.0, cx=0.5, cy=0.5, width=2, height=2)
    prev = np.array([[1.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.5, 1.0], [0.5, 0.5, 0.0, 0.5]])
    curr = np.array([[1.0, 1.0, 0.0, 1.0], [0.5, 0.0, 0.0, 0.0], [1.0, 0.5, 0.5, 0.5]])
    out = compute_features(prev, curr, np.array([0.9, 0.5, 0.1]), two, 0.01)
    assert usable_rows(out).all()
    assert out[:, columns].tolist() == [[1.0, -1.0, 1.0, 1.0], [1.0, 1.0, 0.0, -1.0], [0.0, 0.0, 1.0, 0.0]]
    one = StereoCamera(fx=100.0, fy=100.0, cx=0.0, cy=0.0, width=1, height=1)
    single = np.array([[0.0, 0.0, -1.0, 0.0], [0.0, 0.0, -0.5, 0.0]])
    assert compute_features(single, single, np.array([0.9, 0.5]), one, 0.01)[:, columns].tolist() == [[-1.0] * 4] * 2


def test_usable_rows_are_those_under_the_depth_flag():
    # a row without a depth carries log_depth_prev = +FEATURE_BOUND exactly (the module doc); every other column
    # is ignored, and a nested list is read as an array
    col = FEATURE_NAMES.index("log_depth_prev")
    features = np.zeros((4, N_FEATURES), dtype=np.float32)
    features[:, [c for c in range(N_FEATURES) if c != col]] = FEATURE_BOUND  # the other columns at the flag
    features[:, col] = [0.0, FEATURE_BOUND, np.nextafter(np.float32(FEATURE_BOUND), np.float32(0)), -FEATURE_BOUND]
    assert usable_rows(features).tolist() == [True, False, True, True]
    assert usable_rows(features.tolist()).tolist() == [True, False, True, True]


def _pair_inputs(points_prev, points_curr, s2, n_anchors=None):
    n = len(points_prev)
    anchors = np.arange(n) if n_anchors is None else np.sort(np.random.default_rng(0).permutation(n)[:n_anchors])
    return (np.ascontiguousarray(points_prev, float), np.ascontiguousarray(points_curr, float),
            np.ascontiguousarray(s2, float), anchors.astype(np.int64), 9.0)


@pytest.mark.parametrize("outliers", ["default", "hostile"])
def test_screened_consistency_counts_are_the_tests_on_frames(outliers):
    """The single-precision screen decides only pairs far from the gate: the counts are the test's."""
    sequence = Sequence(SimulationConfig(n_frames=6, outlier_ratio=0.7, outliers=outliers), seed=11)
    for frame in sequence:
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, 0.5)
        rows = np.flatnonzero(problem.usable_mask)
        s2 = np.trace(problem.cov_prev[rows], axis1=1, axis2=2) + np.trace(problem.cov_curr[rows], axis1=1, axis2=2)
        args = _pair_inputs(problem.points_prev[rows], problem.points_curr[rows], s2, n_anchors=MAX_ANCHORS)
        np.testing.assert_array_equal(F._consistent_pairs(*args), F._consistent_pairs_exact(*args))


def test_screened_consistency_counts_are_the_tests_at_the_gate():
    """Pairs placed on the gate (a uniform scaling whose distance change is 3 sigma for typical pairs),
    coincident points, and the cases that skip the screen (a tiny or NaN spread, NaN or huge points)."""
    rng = np.random.default_rng(3)
    P = rng.uniform([-20, -5, 3], [20, 5, 60], (300, 3))
    P[10] = P[11]  # coincident at both frames
    scale = 1.0 + 1e-3
    Q = P * scale
    d = np.linalg.norm(P[:, None] - P[None], axis=-1)
    s2 = np.full(300, (1e-3 * np.median(d) / 3.0) ** 2 / 2.0) * rng.uniform(0.5, 1.5, 300)
    cases = [(P, Q, s2), (P + 1e6, Q + 1e6, s2), (P, Q, np.where(np.arange(300) == 7, 1e-40, s2)),
             (P, np.where(np.arange(300)[:, None] == 5, np.nan, Q), s2), (P, Q, np.where(np.arange(300) == 3, np.nan, s2)),
             (P * 1e16, Q * 1e16, s2)]
    for points_prev, points_curr, spreads in cases:
        args = _pair_inputs(points_prev, points_curr, spreads)
        exact = F._consistent_pairs_exact(*args)
        assert 0 < exact.sum() < 300 * 300 or not np.isfinite(spreads).all() or np.isnan(points_curr).any()
        np.testing.assert_array_equal(F._consistent_pairs(*args), exact)
    # for these many pairs lie within 1 % of the gate, and the screen still gives the test's counts
    change = np.abs(np.linalg.norm(Q[:, None] - Q[None], axis=-1) - d)
    ratio = change**2 / (9.0 * (s2[:, None] + s2[None]))
    assert np.count_nonzero(np.abs(ratio - 1) < 0.01) > 500


def test_anchor_fractions_are_numpys_formulation():
    """The compiled fractions equal (count - is_anchor) / (A - is_anchor) cast to float32, bit for bit."""
    from vo_gym.features import _anchor_fractions

    rng = np.random.default_rng(0)
    for _ in range(500):
        n = int(rng.integers(2, 700))
        anchors = np.sort(rng.permutation(n)[: min(n, 256)]).astype(np.int64)
        count = rng.integers(0, anchors.size + 1, n).astype(np.int64)
        is_anchor = np.zeros(n, dtype=bool)
        is_anchor[anchors] = True
        expected = ((count - is_anchor) / (anchors.size - is_anchor)).astype(np.float32)
        ours = _anchor_fractions(count, anchors, np.empty(n, dtype=np.float32))
        assert ours.dtype == np.float32 and ours.tobytes() == expected.tobytes()


def test_screened_counts_share_the_anchor_pairs_as_the_test_counts_them():
    """Each pair of two anchors is tested once and counted for both: the counts are the test's for
    sorted, unsorted and repeated anchors, coincident points, a zero spread and pairs near the gate."""
    rng = np.random.default_rng(7)
    for trial in range(300):
        n = int(rng.integers(0, 600))
        P = rng.uniform([-20, -5, 3], [20, 5, 60], (n, 3))
        Q = P * (1 + 1e-3) + rng.normal(0, 0.01 * (trial % 3), (n, 3))  # trial % 3 == 0: many near the gate
        s2 = np.full(n, 1e-4) * rng.uniform(0.5, 1.5, n)
        if trial % 4 == 0 and n:
            s2[rng.integers(0, n)] = 0.0
        if trial % 5 == 0 and n > 3:
            P[1], Q[1] = P[2], Q[2]
        anchors = np.sort(rng.permutation(n)[: min(n, int(rng.integers(1, 300)))]).astype(np.int64)
        if trial % 7 == 0:
            anchors = rng.permutation(anchors)
        if trial % 9 == 0 and anchors.size > 2:
            anchors[1] = anchors[0]
        args = (P, Q, s2, anchors, 9.0)
        np.testing.assert_array_equal(F._consistent_pairs(*args), F._consistent_pairs_exact(*args))


def test_the_compiled_clip_is_numpys():
    from vo_gym.features import _clip_in_place

    rng = np.random.default_rng(9)
    for _ in range(200):
        x = (rng.standard_normal((int(rng.integers(0, 40)), N_FEATURES)) * 10.0 ** rng.integers(-2, 3)).astype(np.float32)
        if x.size:
            x.flat[rng.integers(0, x.size, 5)] = rng.choice(np.array(
                [np.nan, np.inf, -np.inf, -0.0, 10.0, -10.0, np.nextafter(10, 11), np.nextafter(-10, -11)], np.float32), 5)
        want = np.clip(x, -FEATURE_BOUND, FEATURE_BOUND)
        _clip_in_place(x, FEATURE_BOUND)
        assert x.tobytes() == want.tobytes()


def test_previous_motion_and_noise_sigma_are_checked_every_time(sequence):
    frame = sequence.frame(1)
    args = (frame.prev, frame.curr, frame.scores, frame.camera)
    R, t = np.eye(3), np.zeros(3)
    good = compute_features(*args, 0.5, (R, t))
    for _ in range(2):  # a value once accepted, then refused
        for bad_R, bad_t in ((np.where(np.eye(3) == 1, np.nan, 0.0), t), (R, np.array([0.0, np.inf, 0.0])),
                             (R[:2], t), (R, t[:2])):
            with pytest.raises(ValueError, match="previous_motion"):
                compute_features(*args, 0.5, (bad_R, bad_t))
        for bad in (0.0, -1.0, float("nan"), float("inf")):
            with pytest.raises(ValueError, match="noise_sigma"):
                compute_features(*args, bad, (R, t))
    same = compute_features(*args, 0.5, [R.tolist(), t.tolist()])  # lists take numpy's reading
    np.testing.assert_array_equal(same, good)
    np.testing.assert_array_equal(compute_features(*args, 0.5, (R.astype(np.float32), t)), good)

