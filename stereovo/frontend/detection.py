"""Keypoints and descriptors of one grey image by OpenCV: ORB, SIFT or AKAZE.

- ORB: Rublee, Rabaud, Konolige & Bradski, "ORB: an efficient alternative to SIFT or SURF",
  ICCV 2011. 256-bit binary descriptors, Hamming distance. One pyramid level by default
  (``FrontendOptions.pyramid_levels``): OpenCV's ORB detects the FAST corners of the image and
  orients them, the grid (:func:`bucket`) keeps ``n_features``, and OpenCV's ORB describes those.
- SIFT: Lowe, "Distinctive image features from scale-invariant keypoints", IJCV 2004.
  128 floats, normalised here to unit length, Euclidean distance.
- AKAZE: Alcantarilla, Nuevo & Bartoli, "Fast explicit diffusion for accelerated features in
  nonlinear scale spaces", BMVC 2013. 486-bit binary M-LDB descriptors, Hamming distance.
  OpenCV 4 has it in its main modules; OpenCV 5 only in the contrib build (``xfeatures2d``), which
  the ``images`` extra installs; with the plain build ``detector="akaze"`` is refused with a
  message saying so.

Binary descriptors are packed into uint64 words so that the matching kernels
(:mod:`stereovo.frontend.kernels`) compare eight bytes at a time.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from stereovo.frontend import kernels
from stereovo.frontend.options import FrontendOptions


def _cv2():
    try:
        import cv2
    except ImportError as err:  # the extra is optional: say how to get it
        raise ImportError(
            "the image front end needs OpenCV: pip install 'vo-gym[images]' (opencv-contrib-python-headless)"
        ) from err
    return cv2


@dataclass(frozen=True, eq=False)
class Keypoints:
    """Keypoints of one image.

    Attributes:
        xy: ``(K, 2)`` float64 positions ``(u, v)`` in pixels.
        descriptors: ``(K, W)`` uint64 words (binary) or ``(K, D)`` float32 unit vectors (SIFT).
        binary: whether descriptors are bit strings (Hamming) or vectors (L2).
        max_distance: the largest possible descriptor distance (bits, or 2 for unit vectors).
    """

    xy: np.ndarray
    descriptors: np.ndarray
    binary: bool
    max_distance: float

    def __len__(self) -> int:
        return int(self.xy.shape[0])


@functools.lru_cache(maxsize=16)
def _detector(options: FrontendOptions):
    cv2 = _cv2()
    # with a grid, detect more than kept so that every cell can fill its quota
    wanted = options.n_features * (BUCKET_OVERSAMPLING if options.grid_rows * options.grid_cols > 1 else 1)
    if options.detector == "orb":
        return cv2.ORB_create(
            nfeatures=wanted, scaleFactor=1.2, nlevels=options.pyramid_levels,
            fastThreshold=options.fast_threshold,
            scoreType=cv2.ORB_FAST_SCORE if options.orb_score == "fast" else cv2.ORB_HARRIS_SCORE,
        )
    if options.detector == "sift":
        return cv2.SIFT_create(nfeatures=wanted)
    for owner in (cv2, getattr(cv2, "xfeatures2d", None)):
        if owner is not None and hasattr(owner, "AKAZE_create"):
            return owner.AKAZE_create()
    raise ValueError(
        f"FrontendOptions.detector='akaze' needs an OpenCV with AKAZE; OpenCV {cv2.__version__} has none "
        "(OpenCV 5 keeps it in the contrib build: pip uninstall opencv-python-headless "
        "opencv-contrib-python-headless, then pip install opencv-contrib-python-headless; the two wheels share cv2)"
    )


BUCKET_OVERSAMPLING = 3
"""With a grid, the detector proposes up to this many times ``n_features`` keypoints (those its threshold finds), the grid keeps ``n_features``."""


def bucket(xy: np.ndarray, response: np.ndarray, shape: tuple[int, int], rows: int, cols: int,
           count: int) -> np.ndarray:
    """Indices (sorted) of at most ``count`` keypoints spread over a ``rows x cols`` grid: the
    strongest ``ceil(count / cells)`` of each cell, then the strongest of the rest up to ``count``
    (bucketing as in Kitt, Geiger & Lategahn, "Visual odometry based on stereo image sequences with
    RANSAC-based outlier rejection scheme", IV 2010: a strong repetitive patch cannot take every
    feature)."""
    n = xy.shape[0]
    if n <= count:
        return np.arange(n)
    h, w = shape
    cell = (np.minimum((xy[:, 1] * rows / h).astype(np.int64), rows - 1) * cols
            + np.minimum((xy[:, 0] * cols / w).astype(np.int64), cols - 1))
    quota = -(-count // (rows * cols))
    chosen = kernels.bucket_mask(cell, np.asarray(response, dtype=np.float64), rows * cols, quota, count)
    return np.flatnonzero(chosen)


def _pack_bits(descriptors: np.ndarray) -> np.ndarray:
    """uint8 ``(K, B)`` bit strings as ``(K, ceil(B / 8))`` uint64 words (zero padded)."""
    k, b = descriptors.shape
    words = -(-b // 8)
    padded = np.zeros((k, words * 8), dtype=np.uint8)
    padded[:, :b] = descriptors
    return padded.view(np.uint64)


def detect(image: np.ndarray, options: FrontendOptions) -> Keypoints:
    """Keypoints and descriptors of a checked grey uint8 image (:func:`~stereovo.frontend.images.grey_image`)."""
    cv2 = _cv2()
    detector = _detector(options)
    keypoints = detector.detect(image, None)
    if len(keypoints) > options.n_features:
        xy = cv2.KeyPoint_convert(keypoints).reshape(-1, 2)
        response = np.fromiter((kp.response for kp in keypoints), np.float64, len(keypoints))
        if options.grid_rows * options.grid_cols > 1:
            keep = bucket(xy, response, image.shape, options.grid_rows, options.grid_cols, options.n_features)
        else:
            keep = np.sort(np.argsort(-response, kind="stable")[: options.n_features])
        keypoints = [keypoints[i] for i in keep.tolist()]
    keypoints, descriptors = detector.compute(image, keypoints)
    binary = options.detector != "sift"
    if descriptors is None or len(keypoints) == 0:
        width = 4 if options.detector == "orb" else 8 if binary else 128
        empty = np.zeros((0, width), dtype=np.uint64 if binary else np.float32)
        return Keypoints(np.zeros((0, 2)), empty, binary, 256.0 if binary else 2.0)
    xy = cv2.KeyPoint_convert(keypoints).astype(np.float64).reshape(-1, 2)
    if binary:
        bits = descriptors.shape[1] * 8
        if options.detector == "akaze":
            bits = 486  # M-LDB's length: the last byte of OpenCV's 61 is only partly used
        return Keypoints(xy, _pack_bits(descriptors), True, float(bits))
    norms = np.linalg.norm(descriptors, axis=1, keepdims=True)
    unit = (descriptors / np.maximum(norms, 1e-12)).astype(np.float32)
    return Keypoints(xy, np.ascontiguousarray(unit), False, 2.0)
