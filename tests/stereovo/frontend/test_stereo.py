"""Stereo matching (stereovo/frontend/stereo.py): disparities against rendered depth and on the
Middlebury 2014 Motorcycle pair bundled with scikit-image (``skimage.data.stereo_motorcycle``:
500x741, ground-truth disparities; f 994.978 px, baseline 193.001 mm, doffs 31.086 px), and what
bad input gets."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.camera import StereoCamera
from stereovo.frontend import FrontendOptions, stereo_matches
from tests.support.frontend import CAM, texture_image


cv2 = pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")


skdata = pytest.importorskip("skimage.data", reason="the Motorcycle pair comes with scikit-image: pip install 'vo-gym[images]'")


def _true_disparity(sequence, k, points):
    depth, _ = sequence.depth(k)
    x = np.rint(points[:, 0]).astype(int)
    y = np.rint(points[:, 1]).astype(int)
    z = depth[y, x]
    return np.where(z > 0, sequence.camera.fx * sequence.camera.baseline / np.where(z > 0, z, 1), np.nan)


def test_motorcycle_disparities_are_within_half_a_pixel(capsys):
    left, right, truth = skdata.stereo_motorcycle()
    grey_left = cv2.cvtColor(left, cv2.COLOR_RGB2GRAY)
    grey_right = cv2.cvtColor(right, cv2.COLOR_RGB2GRAY)
    h, w = grey_left.shape
    camera = StereoCamera(fx=994.978, fy=994.978, cx=w / 2, cy=h / 2, baseline=0.193001, width=w, height=h)
    # the scene's disparities run 7-60 px; the search goes to 100 px
    feats = stereo_matches(grey_left, grey_right, camera, max_disparity=100.0)
    x, y = np.rint(feats.points[:, 0]).astype(int), np.rint(feats.points[:, 1]).astype(int)
    gt = truth[y, x]
    known = np.isfinite(gt)
    error = np.abs(feats.disparity[known] - gt[known])
    within = float(np.mean(error <= 1.0))
    with capsys.disabled():
        print(f"\nMotorcycle: {len(feats)} stereo matches, {known.sum()} with ground truth; median disparity "
              f"error {np.median(error):.3f} px, {100 * within:.1f} % within 1 px")
    assert known.sum() > 300
    assert np.median(error) <= 0.5
    assert within > 0.75


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


@pytest.mark.parametrize("image, message", [
    (np.zeros((240, 320), dtype=np.float64), "left must have dtype uint8"),
    (np.zeros((240, 320, 3), dtype=np.uint8), "left is a colour image"),
    (np.zeros((240,), dtype=np.uint8), "left must be a grey image of shape"),
    ([[0, 1], [2, 3]], "left must be a numpy array"),
    (np.zeros((100, 320), dtype=np.uint8), "left has shape (100, 320) but the camera's images"),
])
def test_bad_images_are_named(image, message):
    with pytest.raises(ValueError) as err:
        stereo_matches(image, texture_image(), CAM)
    assert message in str(err.value)


def test_tiny_images_give_a_reason():
    cam = StereoCamera(width=40, height=30, cx=20.0, cy=15.0)
    feats = stereo_matches(texture_image(0, (30, 40)), texture_image(1, (30, 40)), cam)
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
        stereo_matches(texture_image(), texture_image(), CAM, **options)
    assert message in str(err.value)


def test_option_values_written_as_text_are_read_by_type_and_checked_by_the_options():
    from stereovo.frontend.options import option_value

    assert [option_value(t) for t in ("4", "0.5", "None", "harris", "1e3")] == [4, 0.5, None, "harris", 1000.0]
    assert isinstance(option_value("4"), int) and isinstance(option_value("4.0"), float)
    options = FrontendOptions(**{k: option_value(v) for k, v in (("pyramid_levels", "4"), ("orb_score", "harris"))})
    assert (options.pyramid_levels, options.orb_score) == (4, "harris")
    with pytest.raises(ValueError, match="FrontendOptions.subpixel"):
        FrontendOptions(subpixel=option_value("yes"))
