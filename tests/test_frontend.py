"""The image front end: disparities against rendered depth, labelled inlier rates, motion from
its matches, scores, determinism, and what bad input gets."""

from __future__ import annotations

import numpy as np
import pytest

from images_support import rendered

cv2 = pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")

from stereovo.camera import StereoCamera  # noqa: E402
from stereovo.estimation import estimate_motion  # noqa: E402
from stereovo.frontend import FrontendOptions, StereoFrontend, match_stereo_frames, roc_auc, stereo_matches  # noqa: E402
from stereovo.frontend import kernels  # noqa: E402
from stereovo.metrics import frame_metrics  # noqa: E402
from stereovo.sequences import FRONTEND_SCORE_AUC  # noqa: E402
from stereovo.simulation import OutlierKind  # noqa: E402


@pytest.fixture(scope="module")
def street():
    sequence = rendered(preset="car", n_frames=3, resolution="vga", seed=11)
    yield sequence
    sequence.close()


def _true_disparity(sequence, k, points):
    depth, _ = sequence.depth(k)
    x = np.rint(points[:, 0]).astype(int)
    y = np.rint(points[:, 1]).astype(int)
    z = depth[y, x]
    return np.where(z > 0, sequence.camera.fx * sequence.camera.baseline / np.where(z > 0, z, 1), np.nan)


def test_stereo_disparities_match_the_rendered_depth(street):
    left, right = street.images(0)
    feats = stereo_matches(left, right, street.camera)
    assert len(feats) > 150
    assert np.all(feats.points[:, 1] == feats.points[:, 3])  # rectified: one row
    error = np.abs(feats.disparity - _true_disparity(street, 0, feats.points))
    error = error[np.isfinite(error)]
    assert np.median(error) < 0.25
    assert np.mean(error <= 1.0) > 0.8


def test_subpixel_refinement_beats_descriptor_positions(street):
    left, right = street.images(1)
    refined = stereo_matches(left, right, street.camera)
    coarse = stereo_matches(left, right, street.camera, subpixel=False)
    e_refined = np.abs(refined.disparity - _true_disparity(street, 1, refined.points))
    e_coarse = np.abs(coarse.disparity - _true_disparity(street, 1, coarse.points))
    assert np.nanmedian(e_refined) < 0.7 * np.nanmedian(e_coarse)


def test_frames_have_mostly_labelled_inliers_and_estimate_motion_succeeds(street):
    for k in (1, 2):
        frame = street.frame(k)
        assert frame.n >= 100
        assert frame.truth.inlier.mean() > 0.6
        assert set(np.unique(frame.truth.outlier_kind)) <= {int(kind) for kind in OutlierKind}
        est = estimate_motion(frame.prev, frame.curr, frame.camera, method="probabilistic",
                              noise_sigma=frame.noise_sigma, rng=np.random.default_rng(0))
        metrics = frame_metrics(est, frame.truth)
        assert metrics.success, metrics
        assert metrics.recall > 0.9 and metrics.precision > 0.85


def test_labelled_inliers_agree_with_the_true_motion(street):
    frame = street.frame(1)
    R, t = frame.truth.rotation, frame.truth.translation
    inl = frame.truth.inlier
    X = street.camera.triangulate(frame.prev[inl])
    predicted = street.camera.project(X @ R.T + t)
    residual = frame.curr[inl, :3] - predicted[:, :3]
    assert np.median(np.abs(residual)) < 0.5


def test_scores_lie_in_the_open_interval_and_rank_inliers_first(street):
    scores, labels = [], []
    for k in (1, 2, 3):
        frame = street.frame(k)
        scores.append(frame.scores)
        labels.append(frame.truth.inlier)
    scores, labels = np.concatenate(scores), np.concatenate(labels)
    assert np.all((scores > 0) & (scores < 1))
    auc = roc_auc(scores, labels)
    assert auc > 0.6
    assert abs(auc - FRONTEND_SCORE_AUC) < 0.15


def test_same_seed_same_images_and_matches():
    a = rendered(preset="car", n_frames=1, resolution="vga", seed=5)
    b = rendered(preset="car", n_frames=1, resolution="vga", seed=5)
    c = rendered(preset="car", n_frames=1, resolution="vga", seed=6)
    for k in (0, 1):
        assert np.array_equal(a.images(k)[0], b.images(k)[0]) and np.array_equal(a.images(k)[1], b.images(k)[1])
    fa, fb = a.frame(1), b.frame(1)
    assert np.array_equal(fa.prev, fb.prev) and np.array_equal(fa.curr, fb.curr) and np.array_equal(fa.scores, fb.scores)
    assert not np.array_equal(a.images(1)[0], c.images(1)[0])


def test_the_stateless_call_equals_the_streaming_front_end(street):
    (l0, r0), (l1, r1) = street.images(0), street.images(1)
    once = match_stereo_frames(l0, r0, l1, r1, street.camera)
    stream = StereoFrontend(street.camera)
    first = stream.push(l0, r0)
    assert len(first) == 0 and "first pair" in first.reason
    second = stream.push(l1, r1)
    assert np.array_equal(once.prev, second.prev) and np.array_equal(once.scores, second.scores)


@pytest.mark.parametrize("detector", ["sift", "akaze"])
def test_other_detectors_match_and_give_motion(street, detector):
    if detector == "akaze" and not any(hasattr(m, "AKAZE_create") for m in (cv2, getattr(cv2, "xfeatures2d", None)) if m):
        with pytest.raises(ValueError, match="needs an OpenCV with AKAZE"):
            stereo_matches(*street.images(0), street.camera, detector="akaze")
        pytest.skip(f"OPENCV {cv2.__version__} HAS NO AKAZE (OpenCV 5 moved it to contrib): only its refusal was tested")
    (l0, r0), (l1, r1) = street.images(1), street.images(2)
    matches = match_stereo_frames(l0, r0, l1, r1, street.camera, detector=detector)
    assert len(matches) > 50, matches.reason
    frame = street.frame(2)
    est = estimate_motion(matches.prev, matches.curr, street.camera, method="probabilistic", noise_sigma=0.5,
                          rng=np.random.default_rng(1))
    assert est.ok
    assert np.rad2deg(np.arccos(np.clip((np.trace(est.rotation @ frame.truth.rotation.T) - 1) / 2, -1, 1))) < 0.5
    assert np.linalg.norm(est.translation - frame.truth.translation) < 0.1


def test_ratio_check_and_both_checks_work(street):
    (l0, r0), (l1, r1) = street.images(0), street.images(1)
    mutual = match_stereo_frames(l0, r0, l1, r1, street.camera, temporal_check="mutual")
    both = match_stereo_frames(l0, r0, l1, r1, street.camera, temporal_check="both")
    ratio = match_stereo_frames(l0, r0, l1, r1, street.camera, temporal_check="ratio")
    assert 0 < len(both) <= min(len(mutual), len(ratio))
    assert len(np.unique(ratio.curr_index)) == len(ratio)  # one k feature per match


# ------------------------------------------------------------------ bad input

CAM = StereoCamera(width=320, height=240, cx=160.0, cy=120.0)


def _texture(seed=0, shape=(240, 320)):
    return np.random.default_rng(seed).integers(0, 256, shape, dtype=np.uint8)


@pytest.mark.parametrize("image, message", [
    (np.zeros((240, 320), dtype=np.float64), "left must have dtype uint8"),
    (np.zeros((240, 320, 3), dtype=np.uint8), "left is a colour image"),
    (np.zeros((240,), dtype=np.uint8), "left must be a grey image of shape"),
    ([[0, 1], [2, 3]], "left must be a numpy array"),
    (np.zeros((100, 320), dtype=np.uint8), "left has shape (100, 320) but the camera's images"),
])
def test_bad_images_are_named(image, message):
    with pytest.raises(ValueError) as err:
        stereo_matches(image, _texture(), CAM)
    assert message in str(err.value)


def test_mismatched_frames_are_named():
    with pytest.raises(ValueError, match="right_curr has shape"):
        match_stereo_frames(_texture(0), _texture(1), _texture(2), _texture(3, (240, 300)), CAM)


def test_blank_images_give_an_empty_result_with_a_reason():
    blank = np.full((240, 320), 7, dtype=np.uint8)
    feats = stereo_matches(blank, _texture(), CAM)
    assert len(feats) == 0 and "left is blank (every pixel is 7)" in feats.reason
    matches = match_stereo_frames(_texture(0), _texture(1), blank, blank, CAM)
    assert len(matches) == 0 and "left_curr is blank" in matches.reason
    assert matches.prev.shape == (0, 4) and matches.scores.shape == (0,)
    est = estimate_motion(matches.prev, matches.curr, CAM, noise_sigma=0.5)
    assert not est.ok and est.status.startswith("failed")


def test_tiny_images_give_a_reason():
    cam = StereoCamera(width=40, height=30, cx=20.0, cy=15.0)
    feats = stereo_matches(_texture(0, (30, 40)), _texture(1, (30, 40)), cam)
    assert len(feats) == 0 and "smaller than" in feats.reason


@pytest.mark.parametrize("options, message", [
    ({"stereo_ratio": 1.5}, "FrontendOptions.stereo_ratio must be a finite number in (0, 1], got 1.5"),
    ({"detector": "surf"}, "FrontendOptions.detector must be one of 'orb', 'sift', 'akaze', got 'surf'"),
    ({"n_features": 2.5}, "FrontendOptions.n_features must be an integer"),
    ({"temporal_check": "cross"}, "FrontendOptions.temporal_check must be one of"),
    ({"min_disparity": 50.0, "max_disparity": 10.0}, "FrontendOptions.max_disparity must be > min_disparity=50"),
    ({"subpixel": "yes"}, "FrontendOptions.subpixel must be True or False, got 'yes'"),
])
def test_bad_options_are_named(options, message):
    with pytest.raises(ValueError) as err:
        stereo_matches(_texture(), _texture(), CAM, **options)
    assert message in str(err.value)


def test_unknown_keywords_and_bad_cameras_are_named():
    with pytest.raises(TypeError, match=r"unexpected keyword argument\(s\) \['ratio'\]"):
        stereo_matches(_texture(), _texture(), CAM, ratio=0.8)
    with pytest.raises(ValueError, match="camera must be a StereoCamera, got dict"):
        stereo_matches(_texture(), _texture(), {"fx": 1})
    with pytest.raises(ValueError, match="disparity range is empty"):
        StereoFrontend(CAM, min_disparity=500.0)
    assert FrontendOptions().detector == "orb"


# ------------------------------------------------------------------ kernels and AUC


def test_hamming_kernel_counts_bits_and_best_two_picks_the_nearest():
    rng = np.random.default_rng(3)
    a = rng.integers(0, 256, (20, 32), dtype=np.uint8)
    b = rng.integers(0, 256, (30, 32), dtype=np.uint8)
    ia, jb = np.repeat(np.arange(20), 30), np.tile(np.arange(30), 20)
    got = kernels.hamming_pairs(a.view(np.uint64), b.view(np.uint64), ia, jb)
    want = np.unpackbits(a[ia] ^ b[jb], axis=1).sum(axis=1)
    assert np.array_equal(got, want)
    best, d1, d2 = kernels.best_two(ia, jb, got, 20)
    table = want.reshape(20, 30)
    assert np.array_equal(d1, table.min(axis=1))
    assert np.array_equal(d2, np.sort(table, axis=1)[:, 1])
    assert np.array_equal(table[np.arange(20), best], d1)


def test_the_fused_window_kernel_equals_the_pair_path():
    rng = np.random.default_rng(5)
    pa, pb = rng.uniform(0, 100, (300, 2)), rng.uniform(0, 100, (280, 2))
    da = rng.integers(0, 2**63, (300, 4), dtype=np.int64).astype(np.uint64)
    db = da[rng.integers(0, 300, 280)] ^ (rng.random((280, 4)) < 0.05).astype(np.uint64)  # near copies: ties
    order = np.argsort(pb[:, 1], kind="stable")
    vb = np.ascontiguousarray(pb[order, 1])
    ia, jb = kernels.window_pairs(pa, pb, order, vb, 6.0, -10.0, 25.0)
    dist = kernels.hamming_pairs(da, db, ia, jb)
    best, d1, d2 = kernels.best_two(ia, jb, dist, 300)
    back, _, _ = kernels.best_two(jb, ia, dist, 280)
    fused = kernels.window_best_two_hamming(pa, pb, order, vb, da, db, 6.0, -10.0, 25.0)
    for want, got in zip((best, d1, d2, back), fused):
        assert np.array_equal(want, got)
    assert ia.size > 300 and np.all(np.abs(pa[ia, 1] - pb[jb, 1]) <= 6) and np.all((pa[ia, 0] - pb[jb, 0]) <= 25)


def test_roc_auc_counts_pairs_with_ties_as_halves():
    rng = np.random.default_rng(4)
    scores = rng.integers(0, 5, 200).astype(float)
    labels = rng.random(200) < 0.4
    pos, neg = scores[labels], scores[~labels]
    brute = (np.sum(pos[:, None] > neg[None, :]) + 0.5 * np.sum(pos[:, None] == neg[None, :])) / (pos.size * neg.size)
    assert roc_auc(scores, labels) == pytest.approx(brute)
    assert np.isnan(roc_auc(scores, np.ones(200, bool)))
