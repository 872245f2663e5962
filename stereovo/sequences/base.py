"""The one interface of frame-pair sequences, simulated or from images.

A *frame sequence* has a ``camera`` (:class:`~stereovo.camera.StereoCamera`), ``true_poses``
(``(F+1, 4, 4)`` camera-to-world, or None when unknown), ``len()`` (F frame pairs), and
``frame(k)`` / iteration giving :class:`~stereovo.simulation.Frame` s for ``k = 1..F``: the rows
``prev``, ``curr``, ``scores`` an estimator takes, the camera, the pixel noise, and ``truth``
(None when unknown). :func:`stereovo.odometry.run_odometry`, the environments and the benchmarks
read nothing else.

- :class:`SimulatedSequence` adapts :class:`stereovo.simulation.Sequence` (its frames unchanged).
- :class:`ImageSequence` is the base of image-backed sequences: a subclass supplies the images
  (and, when it knows them, poses and per-match labels); the front end
  (:mod:`stereovo.frontend`) turns each frame pair's images into a frame. Each image pair is
  detected and stereo-matched once, and the last few are kept, so iterating costs one pair a frame.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import OrderedDict
from collections.abc import Iterator
from typing import Any, Protocol, runtime_checkable

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.frontend import FrontendOptions, Matches, StereoFrontend
from stereovo.frontend.stereo import StereoFeatures
from stereovo.options import Number, is_integer
from stereovo.simulation import Frame, FrameTruth, Sequence

FRONTEND_SCORE_AUC = 0.79
"""The ROC AUC the image frames declare for their scores (``Frame.score_auc``: Guided-MLESAC's
calibration of scores into inlier probabilities reads it). Measured on rendered ``car`` sequences
with ground-truth labels, the default front end (one-level ORB): mean per-frame AUC 0.79 over two
500-frame sequences (``scripts/bench_image_odometry.py``, docs/images.md; 0.693 and 0.695 with
the earlier 4-level ORB; ``tests/stereovo/frontend/test_scores.py`` checks the AUC of a few rendered
frames stays within 0.15 of it)."""

NOISE_SIGMA = Number(low=0.0, high=100.0, low_open=True, unit="px")


@runtime_checkable
class FrameSequence(Protocol):
    """What every frame-pair sequence offers (see the module docstring)."""

    camera: StereoCamera
    true_poses: np.ndarray | None

    def __len__(self) -> int: ...

    def frame(self, k: int) -> Frame: ...

    def __iter__(self) -> Iterator[Frame]: ...


class SimulatedSequence:
    """:class:`stereovo.simulation.Sequence` as a :class:`FrameSequence`: the same frames, bit for bit."""

    def __init__(self, sequence: Sequence) -> None:
        if not isinstance(sequence, Sequence):
            raise TypeError(f"sequence must be a stereovo.simulation.Sequence, got {type(sequence).__name__}")
        self.sequence = sequence
        self.camera = sequence.config.camera
        self.true_poses = sequence.true_poses

    def __len__(self) -> int:
        return len(self.sequence)

    def frame(self, k: int) -> Frame:
        return self.sequence.frame(k)

    def __iter__(self) -> Iterator[Frame]:
        return iter(self.sequence)

    def __repr__(self) -> str:
        return f"SimulatedSequence({self.sequence!r})"


class ImageSequence(ABC):
    """Frame pairs from stereo images through the front end.

    Subclasses implement :meth:`n_images`, :meth:`load_images` and optionally :meth:`label`.

    Args:
        camera: the rectified rig of the images.
        noise_sigma: the pixel noise (px) the frames declare to the estimator.
        cache_size: image pairs whose images and stereo features are kept.
        **frontend_options: :class:`~stereovo.frontend.FrontendOptions` fields (or ``options=`` one).
    """

    true_poses: np.ndarray | None = None

    def __init__(self, camera: StereoCamera, noise_sigma: float = 0.5, cache_size: int = 4,
                 **frontend_options: Any) -> None:
        self.camera = camera
        self.noise_sigma = float(NOISE_SIGMA.check("noise_sigma", noise_sigma, prefix=f"{type(self).__name__}: "))
        self.frontend = StereoFrontend(camera, **frontend_options)
        self._cache_size = max(2, int(cache_size))
        self._features: OrderedDict[int, StereoFeatures] = OrderedDict()

    @property
    def frontend_options(self) -> FrontendOptions:
        return self.frontend.options

    @abstractmethod
    def n_images(self) -> int:
        """Image pairs in the sequence (frame pairs + 1)."""

    @abstractmethod
    def load_images(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Left and right grey uint8 images of image pair ``k`` (0-based)."""

    def label(self, k: int, matches: Matches) -> FrameTruth | None:
        """Ground truth of frame pair ``(k-1, k)``'s matches; None when unknown (the default)."""
        return None

    def __len__(self) -> int:
        return self.n_images() - 1

    def _check_image_index(self, k: Any) -> int:
        if not is_integer(k) or not 0 <= k < self.n_images():
            raise IndexError(f"image index must be an integer in [0, {self.n_images() - 1}], got {k!r}")
        return int(k)

    def images(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """``(left, right)`` grey uint8 images of image pair ``k`` (0-based; frame pair k is images k-1, k)."""
        return self.load_images(self._check_image_index(k))

    def features(self, k: int) -> StereoFeatures:
        """Stereo features of image pair ``k`` (kept for the next few calls)."""
        k = self._check_image_index(k)
        if k in self._features:
            self._features.move_to_end(k)
            return self._features[k]
        left, right = self.load_images(k)
        feats = self.frontend.features(left, right, (f"left image {k}", f"right image {k}"))
        self._features[k] = feats
        while len(self._features) > self._cache_size:
            self._features.popitem(last=False)
        return feats

    def matches(self, k: int) -> Matches:
        """The front end's matches of frame pair ``(k-1, k)``, ``1 <= k <= len(self)``."""
        if not is_integer(k) or not 1 <= k <= len(self):
            raise IndexError(f"frame index must be an integer in [1, {len(self)}], got {k!r}")
        return self.frontend.match(self.features(int(k) - 1), self.features(int(k)))

    def frame(self, k: int) -> Frame:
        """Frame pair ``(k-1, k)`` as a :class:`~stereovo.simulation.Frame` (``truth`` from :meth:`label`)."""
        matches = self.matches(k)
        return Frame(
            index=int(k), prev=matches.prev, curr=matches.curr, scores=matches.scores, camera=self.camera,
            noise_sigma=self.noise_sigma, score_auc=FRONTEND_SCORE_AUC, truth=self.label(int(k), matches),
        )

    def __iter__(self) -> Iterator[Frame]:
        for k in range(1, len(self) + 1):
            yield self.frame(k)


def as_frame_sequence(source: Any) -> Any:
    """A :class:`FrameSequence` of ``source``: a simulator :class:`~stereovo.simulation.Sequence` is
    wrapped (:class:`SimulatedSequence`), a frame sequence is returned as is."""
    if isinstance(source, Sequence):
        return SimulatedSequence(source)
    if isinstance(source, FrameSequence):
        return source
    raise TypeError(f"not a frame sequence (camera, true_poses, len, frame(k)): {type(source).__name__}")
