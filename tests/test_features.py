"""vo_gym.features: layout, label-free inputs, meaning of the columns, malformed input."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest
from scipy.stats import rankdata

from stereovo.camera import StereoCamera
from stereovo.estimation import StereoProblem
from stereovo.geometry import relative_motion
from stereovo.simulation import Sequence, SimulationConfig
from vo_gym import features as F
from vo_gym.features import (
    FEATURE_BOUND,
    FEATURE_LAYOUT_VERSION,
    FEATURE_NAMES,
    N_FEATURES,
    check_feature_layout,
    compute_features,
    feature_index,
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


def test_layout_constants():
    assert len(FEATURE_NAMES) == N_FEATURES == len(set(FEATURE_NAMES))
    assert isinstance(FEATURE_LAYOUT_VERSION, int)
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
    no_depth[0, 2] = no_depth[0, 0]  # zero disparity: not malformed, a flagged row (tests/test_unusable_rows.py)
    flagged = compute_features(no_depth, *args[1:])
    assert np.all(np.isfinite(flagged)) and flagged[0, feature_index("log_depth_prev")] == FEATURE_BOUND
    with pytest.raises(ValueError, match="prev must be real"):
        compute_features(frame.prev + 0j, *args[1:])
    empty = compute_features(np.zeros((0, 4)), np.zeros((0, 4)), np.zeros(0), StereoCamera(), 0.5)
    assert empty.shape == (0, N_FEATURES)
