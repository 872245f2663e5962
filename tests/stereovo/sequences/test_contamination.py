"""stereovo.sequences.contaminate: an image frame's outliers raised to a chosen epsilon."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation import estimate_motion
from stereovo.metrics import frame_metrics
from stereovo.sequences import contaminate
from stereovo.sequences.labels import PIXEL_TOLERANCE
from stereovo.simulation import OutlierKind


@pytest.fixture(scope="module")
def frame(short):
    return short.frame(1)


@pytest.mark.parametrize("epsilon", [0.5, 0.8, 0.9])
def test_contamination_reaches_the_asked_outlier_fraction_by_re_pairing_inliers(frame, epsilon):
    out = contaminate(frame, epsilon, np.random.default_rng(3))
    n = frame.n
    assert out.n == n and np.array_equal(out.prev, frame.prev)
    # at most a re-paired row that landed within the labels' tolerance keeps its label
    assert abs(out.truth.outlier_ratio - epsilon) <= 2.0 / n
    assert out.truth.outlier_ratio == pytest.approx(1.0 - out.truth.inlier.mean())
    changed = np.any(out.curr != frame.curr, axis=1)
    # only inliers were touched, old outliers stay as they were
    assert not np.any(changed & ~frame.truth.inlier)
    new_outliers = frame.truth.inlier & ~out.truth.inlier
    assert np.all(changed[new_outliers])
    assert np.all(out.truth.outlier_kind[new_outliers] == int(OutlierKind.RANDOM_MISMATCH))
    moved = np.abs(out.curr[new_outliers, :2] - frame.curr[new_outliers, :2]).max(axis=1)
    assert np.all(moved > PIXEL_TOLERANCE)
    # every new outlier's k measurement is some other row's real one at k (a wrong temporal match)
    originals = {tuple(row) for row in frame.curr}
    assert all(tuple(row) in originals for row in out.curr[new_outliers])
    # their scores come from the frame's labelled outliers, the other rows keep theirs
    assert set(out.scores[new_outliers]) <= set(frame.scores[~frame.truth.inlier])
    assert np.array_equal(out.scores[~new_outliers], frame.scores[~new_outliers])


def test_contamination_is_deterministic_and_leaves_a_frame_at_or_above_epsilon_alone(frame):
    a = contaminate(frame, 0.8, np.random.default_rng(5))
    b = contaminate(frame, 0.8, np.random.default_rng(5))
    assert np.array_equal(a.curr, b.curr) and np.array_equal(a.scores, b.scores)
    assert contaminate(frame, 0.0, np.random.default_rng(5)) is frame
    assert contaminate(a, 0.5, np.random.default_rng(5)) is a


def test_a_contaminated_frame_is_still_solved_by_the_default_method(frame):
    out = contaminate(frame, 0.8, np.random.default_rng(0))
    est = estimate_motion(out.prev, out.curr, out.camera, noise_sigma=out.noise_sigma, rng=0)
    assert est.status == "ok" and frame_metrics(est, out.truth).success
    # no wrong temporal match is taken for an inlier, and nearly every labelled inlier is found
    re_paired = frame.truth.inlier & ~out.truth.inlier
    assert not np.any(est.inliers & re_paired)
    assert np.mean(est.inliers[out.truth.inlier]) > 0.95


@pytest.mark.parametrize("epsilon", [1.0, -0.1, float("nan"), True, "0.5"])
def test_contamination_refuses_a_bad_epsilon_by_name(frame, epsilon):
    with pytest.raises(ValueError, match="epsilon must be an outlier fraction"):
        contaminate(frame, epsilon, np.random.default_rng(0))


def test_contamination_refuses_a_seed_in_place_of_a_generator(frame):
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator, got int"):
        contaminate(frame, 0.5, 0)
