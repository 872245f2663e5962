"""The settings of the simulator: :class:`SimulationConfig`, validated on construction.

Its scalar fields are declared once (:mod:`stereovo.options`); the composite ones
(the outlier ratio or range, the outlier mix, the camera, the depth range) are
checked here. The landmark layouts it may name are :data:`WORLDS`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.options import Choice, Integer, Number, Option, is_real
from stereovo.simulation.motion import PRESETS, MotionPreset
from stereovo.simulation.scores import SCORE_AUC

WORLDS: tuple[str, ...] = ("street", "open")
"""Landmark layouts: a street (ground, facades, clutter) or an open volume."""

_DEFAULT_WORLD = {"car": "street", "free": "open"}


MAX_NOISE_SIGMA_PX = 1e3
"""The largest simulated pixel noise (px): noise as large as the image; beyond it the measurements
are no longer pixels of this camera (and at ~1e300 they overflow)."""

_CONFIG_RULES: dict[str, Option] = {
    "preset": Choice(choices=tuple(sorted(PRESETS))),
    "world": Choice(choices=tuple(WORLDS), allow_none=True),
    "n_frames": Integer(low=1, high=10**9),
    "n_correspondences": Integer(low=3, high=10**8),
    "noise_sigma": Number(low=0.0, high=MAX_NOISE_SIGMA_PX, unit="px"),
    "score_auc": SCORE_AUC,
    "z_min": Number(low=0.0, high=1e6, low_open=True, unit="m"),
    "z_max": Number(low=0.0, high=1e6, low_open=True, unit="m"),
    "speed": Number(low=0.0, high=1e3, unit="m/frame", allow_none=True),
}
"""Declarations (:mod:`stereovo.options`) of :class:`SimulationConfig`'s scalar fields."""


@dataclass(frozen=True)
class SimulationConfig:
    """Everything that defines the synthetic frames; validated on construction.

    Args:
        preset: motion style, a key of :data:`PRESETS` (``"car"`` or ``"free"``).
        world: landmark layout, ``"street"`` or ``"open"``; None picks street for
            ``car`` and open otherwise.
        n_frames: frame pairs per :class:`Sequence` (>= 1).
        n_correspondences: putative matches per frame, exactly (>= 3).
        noise_sigma: std of the Gaussian pixel noise on every coordinate (px, in [0, 1e3]).
        outlier_ratio: contamination epsilon in [0, 1), or ``(low, high)`` drawn
            uniformly per frame.
        outlier_mix: non-negative weights of random mismatches, stereo mismatches
            and moving-object points among the outliers (sum > 0).
        score_auc: ROC AUC of the match score as an inlier detector, in [0.5, 1).
        z_min, z_max: depth range (m) of the landmarks in both frames.
        camera: the stereo rig.
        speed: mean speed (m/frame) overriding the preset's; None keeps it.

    Raises:
        ValueError: naming the field, e.g.
            ``SimulationConfig.noise_sigma must be >= 0, got -1``.
    """

    preset: str = "car"
    world: str | None = None
    n_frames: int = 100
    n_correspondences: int = 500
    noise_sigma: float = 0.5
    outlier_ratio: float | tuple[float, float] = 0.5
    outlier_mix: tuple[float, float, float] = (0.6, 0.2, 0.2)
    score_auc: float = 0.75
    z_min: float = 3.0
    z_max: float = 60.0
    camera: StereoCamera = StereoCamera()
    speed: float | None = None

    def __post_init__(self) -> None:
        def fail(name: str, requirement: str) -> None:
            raise ValueError(f"SimulationConfig.{name} must be {requirement}, got {getattr(self, name)!r}")

        # The scalar fields by the one options contract (stereovo.options); the composite ones below.
        for name, rule in _CONFIG_RULES.items():
            object.__setattr__(self, name, rule.check(name, getattr(self, name), prefix="SimulationConfig."))
        object.__setattr__(self, "noise_sigma", float(self.noise_sigma))

        ratio = self.outlier_ratio
        bounds = (ratio, ratio) if is_real(ratio) else tuple(ratio) if isinstance(ratio, (tuple, list)) else ()
        if len(bounds) != 2 or not all(is_real(x) and math.isfinite(x) for x in bounds):
            fail("outlier_ratio", "a number in [0, 1) or a (low, high) pair in [0, 1)")
        low, high = float(bounds[0]), float(bounds[1])
        if not (0.0 <= low <= high < 1.0):
            fail("outlier_ratio", "in [0, 1) (a range needs 0 <= low <= high < 1)")
        object.__setattr__(self, "outlier_ratio", low if is_real(ratio) else (low, high))

        mix = self.outlier_mix
        mix_ok = isinstance(mix, (tuple, list, np.ndarray)) and len(mix) == 3
        mix_ok = mix_ok and all(is_real(w) and math.isfinite(w) and w >= 0 for w in mix) and sum(mix) > 0
        if not mix_ok:
            fail("outlier_mix", "3 finite weights >= 0 with a positive sum")
        object.__setattr__(self, "outlier_mix", tuple(float(w) for w in mix))

        object.__setattr__(self, "score_auc", float(self.score_auc))

        if not isinstance(self.camera, StereoCamera):
            fail("camera", "a StereoCamera")
        if self.z_max <= self.z_min:
            fail("z_max", f"a finite depth > z_min={self.z_min} (m)")
        cam = self.camera
        if cam.fx * cam.baseline / self.z_min <= cam.min_disparity:
            fail("z_min", f"small enough that fx*baseline/z_min exceeds min_disparity={cam.min_disparity} px")
        object.__setattr__(self, "z_min", float(self.z_min))
        object.__setattr__(self, "z_max", float(self.z_max))

        if self.speed is not None:
            object.__setattr__(self, "speed", float(self.speed))

    @property
    def resolved_world(self) -> str:
        """The landmark layout actually used: ``world`` or the preset's default."""
        return self.world if self.world is not None else _DEFAULT_WORLD.get(self.preset, "open")

    @property
    def motion(self) -> MotionPreset:
        """The preset's velocity process, with ``speed`` applied."""
        preset = PRESETS[self.preset]
        return preset if self.speed is None else preset.with_speed(self.speed)

    @property
    def epsilon_range(self) -> tuple[float, float]:
        """``(low, high)`` of the per-frame contamination; equal for a fixed epsilon."""
        ratio = self.outlier_ratio
        return (ratio, ratio) if isinstance(ratio, float) else ratio
