"""The front end's settings: :class:`FrontendOptions`, validated on construction.

Every field is declared once with :mod:`stereovo.options`, so a bad value is refused with a
message naming the argument and the value wherever it enters (a keyword of
:func:`~stereovo.frontend.match_stereo_frames`, of a sequence, of the images environment).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping

from stereovo.options import Boolean, Choice, Integer, Number, Option

DETECTORS: tuple[str, ...] = ("orb", "sift", "akaze")
"""Feature detectors and descriptors: ORB (Rublee et al., ICCV 2011; binary, Hamming distance),
SIFT (Lowe, IJCV 2004; float, L2 distance), AKAZE (Alcantarilla et al., BMVC 2013; binary M-LDB)."""

ORB_SCORES: tuple[str, ...] = ("harris", "fast")
"""How ORB ranks its FAST corners: Harris's corner measure (Rublee et al.'s choice, OpenCV's
default) or the FAST score itself (OpenCV's ``ORB_FAST_SCORE``)."""

TEMPORAL_CHECKS: tuple[str, ...] = ("mutual", "ratio", "both")
"""How a temporal match k-1 -> k is accepted: ``"mutual"`` (each is the other's nearest
neighbour), ``"ratio"`` (Lowe's ratio test on the nearest two), or ``"both"``."""

_RULES: dict[str, Option] = {
    "detector": Choice(choices=DETECTORS),
    "n_features": Integer(low=8, high=200_000),
    "fast_threshold": Integer(low=1, high=254),
    "pyramid_levels": Integer(low=1, high=16),
    "orb_score": Choice(choices=ORB_SCORES),
    "grid_rows": Integer(low=1, high=64),
    "grid_cols": Integer(low=1, high=64),
    "stereo_ratio": Number(low=0.0, high=1.0, low_open=True),
    "temporal_ratio": Number(low=0.0, high=1.0, low_open=True),
    "max_distance": Number(low=0.0, high=1.0, low_open=True),
    "row_tolerance": Number(low=0.0, high=50.0, unit="px"),
    "min_disparity": Number(low=0.0, high=1e4, unit="px", allow_none=True),
    "max_disparity": Number(low=0.0, high=1e4, low_open=True, unit="px", allow_none=True),
    "min_depth": Number(low=0.0, high=1e6, low_open=True, unit="m"),
    "temporal_check": Choice(choices=TEMPORAL_CHECKS),
    "search_radius": Number(low=1.0, high=1e5, unit="px", allow_none=True),
    "subpixel": Boolean(),
    "patch_radius": Integer(low=1, high=15),
}


def option_value(text: str) -> Any:
    """A front-end option's value written as text (a command line's ``NAME=VALUE``): an int, a float,
    ``None`` or the text itself; :class:`FrontendOptions` then checks it against the option's rule."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return None if text == "None" else text


@dataclass(frozen=True)
class FrontendOptions:
    """Settings of the image front end (:mod:`stereovo.frontend`).

    Args:
        detector: ``"orb"`` (default), ``"sift"`` or ``"akaze"`` (:data:`DETECTORS`).
        n_features: keypoints kept per image (ORB's and SIFT's budget; AKAZE keeps its strongest).
        fast_threshold: ORB's FAST corner threshold (grey levels). The default 7 leaves one level
            of a rendered 1241x376 image 3000-6000 candidates, so the grid has at least 1.5 times
            ``n_features`` to choose from.
        pyramid_levels: ORB's pyramid levels (scale factor 1.2 between levels). Default 1: the two
            images of a stereo pair have one scale, and consecutive frames change scale little, so
            the front end detects and describes one level (detection about 1.7x and a streamed frame
            pair about 1.5x faster than with 4 levels at 2000 features, with more matches on the
            poorest rendered frames and the accuracy targets met; docs/images.md).
            The coarser levels help when the scale changes between the frames matched.
        orb_score: how ORB ranks its FAST corners for the budget and the grid: ``"fast"`` (the FAST
            score, default) or ``"harris"`` (Harris's measure, OpenCV's default) (:data:`ORB_SCORES`).
        grid_rows, grid_cols: bucketing grid: the detector proposes up to three times ``n_features``
            keypoints and each cell keeps its strongest share, so one strong (often repetitive)
            patch cannot take every feature; ``1 x 1`` keeps the strongest overall.
        stereo_ratio: Lowe's ratio test along the row band: a stereo match is kept when its
            descriptor distance is below ``stereo_ratio`` times the second best candidate's.
        temporal_ratio: the same test for the temporal match (``temporal_check`` ``"ratio"`` or ``"both"``).
        max_distance: largest accepted descriptor distance, as a fraction of the descriptor's
            maximum (ORB: 256 bits; SIFT: unit-norm L2, at most 2 apart: fraction of 2); also the
            distance at which a match's score reaches zero.
        row_tolerance: the row band, ``|vL - vR| <= row_tolerance`` px (rectified images).
        min_disparity: smallest disparity searched (px); None: the camera's ``min_disparity``.
        max_disparity: largest disparity searched (px); None: ``fx * baseline / min_depth``.
        min_depth: nearest depth (m) a stereo match may have, for the default ``max_disparity``.
        temporal_check: :data:`TEMPORAL_CHECKS`.
        search_radius: temporal matches are searched within this many pixels of the previous
            left position (a square window); None searches the whole image.
        subpixel: refine disparities (and the temporal position) to subpixel precision by a
            parabola through the sum of absolute differences of ``patch_radius`` patches.
        patch_radius: half size of the refinement patches (px).

    Raises:
        ValueError: naming the field and the value, e.g.
            ``FrontendOptions.stereo_ratio must be a finite number in (0, 1], got 1.5``.
    """

    detector: str = "orb"
    n_features: int = 2000
    fast_threshold: int = 7
    pyramid_levels: int = 1
    orb_score: str = "fast"
    grid_rows: int = 4
    grid_cols: int = 12
    stereo_ratio: float = 0.9
    temporal_ratio: float = 0.8
    max_distance: float = 0.3
    row_tolerance: float = 1.5
    min_disparity: float | None = None
    max_disparity: float | None = None
    min_depth: float = 2.0
    temporal_check: str = "mutual"
    search_radius: float | None = 200.0
    subpixel: bool = True
    patch_radius: int = 3

    def __post_init__(self) -> None:
        for name, rule in _RULES.items():
            object.__setattr__(self, name, rule.check(name, getattr(self, name), prefix="FrontendOptions."))
        for name in ("stereo_ratio", "temporal_ratio", "max_distance", "row_tolerance", "min_depth"):
            object.__setattr__(self, name, float(getattr(self, name)))
        lo, hi = self.min_disparity, self.max_disparity
        if lo is not None and hi is not None and hi <= lo:
            raise ValueError(f"FrontendOptions.max_disparity must be > min_disparity={lo:g} px, got {hi!r}")

    @classmethod
    def from_keywords(cls, options: Mapping[str, Any], owner: str = "match_stereo_frames") -> "FrontendOptions":
        """Options from keywords, a :class:`FrontendOptions` under ``options["options"]``, or both.

        Raises:
            TypeError: an unknown keyword, named with the list of known ones.
        """
        options = dict(options)
        base = options.pop("options", None)
        if base is not None and not isinstance(base, FrontendOptions):
            raise TypeError(f"{owner}: options must be a FrontendOptions, got {type(base).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise TypeError(f"{owner} got unexpected keyword argument(s) {unknown}; front-end options: {sorted(known)}")
        if base is None:
            return cls(**options)
        return dataclasses.replace(base, **options) if options else base

    def disparity_range(self, camera: Any) -> tuple[float, float]:
        """``(low, high)`` disparities (px) searched along the rows of ``camera``'s images."""
        low = camera.min_disparity if self.min_disparity is None else self.min_disparity
        high = camera.fx * camera.baseline / self.min_depth if self.max_disparity is None else self.max_disparity
        if high <= low:
            raise ValueError(
                f"FrontendOptions: the disparity range is empty: max_disparity={high:g} px <= min_disparity={low:g} px"
            )
        return float(low), float(high)

