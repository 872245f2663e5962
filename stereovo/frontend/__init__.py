"""The image front end: rectified stereo images in, putative stereo matches for
:func:`stereovo.estimation.estimate_motion` out.

A frame pair ``(k-1, k)`` of rectified grey pairs becomes :class:`Matches`: rows
``prev[i] <-> curr[i]`` of pixels ``(uL, vL, uR, vR)`` and a score per row in (0, 1).

1. Detection (:mod:`~stereovo.frontend.detection`): ORB (default), SIFT or AKAZE keypoints and
   descriptors per image, by OpenCV (the ``images`` extra).
2. Stereo (:mod:`~stereovo.frontend.stereo`): left keypoints matched to right keypoints within a
   row band and a disparity range from the camera, by descriptor distance with Lowe's ratio test,
   one left per right; disparities refined to subpixel precision by a parabola through patch
   differences along the row (:mod:`~stereovo.frontend.kernels`).
3. Temporal (:mod:`~stereovo.frontend.temporal`): the stereo features of k-1 matched to those of
   k by their left descriptors in a search window, with a mutual or ratio check, the position at
   k refined to subpixel precision; :class:`StereoFrontend` streams pairs, detecting each once.
4. Scores (:mod:`~stereovo.frontend.scores`): the geometric mean over the three comparisons of
   ``(1 - distance / max_distance) * (1 - ratio)``; :func:`roc_auc` measures them.

Settings: :class:`FrontendOptions` (:mod:`~stereovo.frontend.options`). Input checks
(:mod:`~stereovo.frontend.images`): a wrong dtype, shape, a colour image or a size that differs
from the camera's raises ``ValueError`` naming the argument; a blank image gives an empty result
whose ``reason`` says so.
"""

from stereovo.frontend.options import DETECTORS, TEMPORAL_CHECKS, FrontendOptions
from stereovo.frontend.scores import roc_auc
from stereovo.frontend.stereo import StereoFeatures, stereo_matches
from stereovo.frontend.temporal import Matches, StereoFrontend, match_stereo_frames

__all__ = [
    "DETECTORS",
    "TEMPORAL_CHECKS",
    "FrontendOptions",
    "Matches",
    "StereoFeatures",
    "StereoFrontend",
    "match_stereo_frames",
    "roc_auc",
    "stereo_matches",
]
