"""The streaming front end (stereovo/frontend/temporal.py): labelled inlier rates, motion from its
matches, other detectors, determinism, and what bad input gets."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation import estimate_motion
from stereovo.frontend import FrontendOptions, StereoFrontend, match_stereo_frames, stereo_matches
from stereovo.metrics import frame_metrics
from stereovo.simulation import OutlierKind
from tests.support.frontend import CAM, texture_image
from tests.support.images import rendered


cv2 = pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")


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


def test_mismatched_frames_are_named():
    with pytest.raises(ValueError, match="right_curr has shape"):
        match_stereo_frames(texture_image(0), texture_image(1), texture_image(2), texture_image(3, (240, 300)), CAM)


def test_blank_images_give_an_empty_result_with_a_reason():
    blank = np.full((240, 320), 7, dtype=np.uint8)
    feats = stereo_matches(blank, texture_image(), CAM)
    assert len(feats) == 0 and "left is blank (every pixel is 7)" in feats.reason
    matches = match_stereo_frames(texture_image(0), texture_image(1), blank, blank, CAM)
    assert len(matches) == 0 and "left_curr is blank" in matches.reason
    assert matches.prev.shape == (0, 4) and matches.scores.shape == (0,)
    est = estimate_motion(matches.prev, matches.curr, CAM, noise_sigma=0.5)
    assert not est.ok and est.status.startswith("failed")


def test_unknown_keywords_and_bad_cameras_are_named():
    with pytest.raises(TypeError, match=r"unexpected keyword argument\(s\) \['ratio'\]"):
        stereo_matches(texture_image(), texture_image(), CAM, ratio=0.8)
    with pytest.raises(ValueError, match="camera must be a StereoCamera, got dict"):
        stereo_matches(texture_image(), texture_image(), {"fx": 1})
    with pytest.raises(ValueError, match="disparity range is empty"):
        StereoFrontend(CAM, min_disparity=500.0)
    assert FrontendOptions().detector == "orb"


def test_default_orb_is_one_level_ranked_by_fast_score_and_the_earlier_configuration_still_runs(street):
    from stereovo.frontend.detection import detect

    options = FrontendOptions()
    assert (options.pyramid_levels, options.orb_score, options.n_features) == (1, "fast", 2000)
    left, right = street.images(0)
    keypoints = detect(left, options)
    h, w = left.shape
    assert len(keypoints) == 2000  # the budget, chosen by the grid from more candidates
    assert np.all((keypoints.xy >= 31) & (keypoints.xy < (w - 31, h - 31)))  # ORB's border
    assert np.array_equal(keypoints.xy, np.rint(keypoints.xy))  # one level: FAST corners lie on pixels
    earlier = FrontendOptions(pyramid_levels=4, fast_threshold=12, orb_score="harris")
    assert len(match_stereo_frames(left, right, *street.images(1), street.camera, options=earlier)) > 100
    with pytest.raises(ValueError, match="FrontendOptions.orb_score"):
        FrontendOptions(orb_score="shi-tomasi")
