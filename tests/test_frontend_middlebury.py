"""The front end on real images: the Middlebury 2014 Motorcycle pair bundled with scikit-image
(``skimage.data.stereo_motorcycle``: 500x741, ground-truth disparities; f 994.978 px, baseline
193.001 mm, doffs 31.086 px). Disparities ``uL - uR`` of the kept stereo matches are compared
with the ground truth at the left keypoint's pixel (doffs does not enter: it shifts depth, not
the disparity between the two images)."""

from __future__ import annotations

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")
skdata = pytest.importorskip("skimage.data", reason="the Motorcycle pair comes with scikit-image: pip install 'vo-gym[images]'")

from stereovo.camera import StereoCamera  # noqa: E402
from stereovo.frontend import stereo_matches  # noqa: E402


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
