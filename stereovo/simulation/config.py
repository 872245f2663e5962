"""The settings of the simulator: :class:`SimulationConfig`, validated on construction.

Its scalar fields are declared once (:mod:`stereovo.options`); the composite ones
(the outlier ratio or range, the outlier mix, the camera, the depth range) are
checked here. The landmark layouts it may name are :data:`WORLDS`.

Two kinds of refusal: settings that can never be simulated are refused when the config is made
(a ``ValueError`` naming the field and the value); settings whose frames depend on the random
draw (a depth range so thin, or a speed so high, that few landmarks stay in view) are refused by
the simulator for the frame that cannot be drawn, with :class:`InfeasibleSettingsError` (a
``ValueError``) naming the settings to change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.options import Choice, Integer, Number, Option, OptionError, is_finite_real, is_real, value_repr
from stereovo.simulation.motion import PRESETS, MotionPreset
from stereovo.simulation.scores import SCORE_AUC

OUTLIER_KINDS: tuple[str, ...] = (
    "random", "stereo", "moving", "independent", "duplicate", "far", "repetitive",
)
"""Names of the outlier kinds, in the order of :attr:`SimulationConfig.outlier_mix`'s weights: the
default three (:mod:`stereovo.simulation.outliers`) and the hostile four
(:mod:`stereovo.simulation.hostile`)."""

OUTLIER_PRESETS: dict[str, dict] = {
    "default": {"outlier_mix": (0.6, 0.2, 0.2), "noise_dof": None},
    # Six in ten errors are the two a real front end makes most, one of which the default never
    # makes (independent left/right moves, random points); the rest the other hostile kinds and a
    # few stereo mismatches. No moving object: a rigid object is a second motion, not a match
    # error (the default mix has one).
    "hostile": {
        "outlier_mix": {"random": 0.3, "independent": 0.3, "duplicate": 0.1, "far": 0.15, "repetitive": 0.1,
                        "stereo": 0.05},
        "noise_dof": 3.0,
    },
}
"""``SimulationConfig.outliers`` presets: the outlier mix and the pixel noise's tail (Student-t
degrees of freedom; None is Gaussian) that a config takes unless it sets them itself."""

WORLDS: tuple[str, ...] = ("street", "open")
"""Landmark layouts: a street (ground, facades, clutter) or an open volume."""

_DEFAULT_WORLD = {"car": "street", "free": "open"}


MAX_NOISE_SIGMA_PX = 1e3
"""The largest simulated pixel noise (px): noise as large as the image; beyond it the measurements
are no longer pixels of this camera (and at ~1e300 they overflow)."""

MAX_CORRESPONDENCES = 10**8
"""The most putative matches of a simulated frame (``n_correspondences``): far above any front end's."""

MAX_FRAMES = 10**6
"""The most frame pairs of a :class:`~stereovo.simulation.Sequence`: its trajectory and seeds are
drawn up front, some 600 bytes and 10 microseconds a frame (a million frames: ~10 s and ~0.6 GB;
the 10**9 once allowed took hours and hundreds of GB). KITTI's longest sequence has 4,661 frames."""

MIN_OUTLIER_PX, OUTLIER_SIGMAS = 4.0, 8.0  # the outlier threshold max(4 px, 8 sigma) (outliers.outlier_threshold)


class InfeasibleSettingsError(ValueError):
    """Valid settings whose frame could not be drawn: the message names the settings to change.

    Raised by the simulator (:func:`~stereovo.simulation.simulate_frame`,
    :meth:`~stereovo.simulation.Sequence.frame`), not by the config: whether a frame can be drawn
    depends on the random draw there (a landmark that stays in a thin depth range, a moving object
    that shows against a large outlier threshold). Settings that can never be drawn are refused by
    :class:`SimulationConfig` itself.
    """

_CONFIG_RULES: dict[str, Option] = {
    "preset": Choice(choices=tuple(sorted(PRESETS))),
    "world": Choice(choices=tuple(WORLDS), allow_none=True),
    "n_frames": Integer(low=1, high=MAX_FRAMES),
    "n_correspondences": Integer(low=3, high=MAX_CORRESPONDENCES),
    "noise_sigma": Number(low=0.0, high=MAX_NOISE_SIGMA_PX, unit="px"),
    "score_auc": SCORE_AUC,
    "z_min": Number(low=0.0, high=1e6, low_open=True, unit="m"),
    "z_max": Number(low=0.0, high=1e6, low_open=True, unit="m"),
    "speed": Number(low=0.0, high=1e3, unit="m/frame", allow_none=True),
    "outliers": Choice(choices=tuple(OUTLIER_PRESETS)),
    "noise_dof": Number(low=2.0, high=1e6, low_open=True, allow_none=True),
}
"""Declarations (:mod:`stereovo.options`) of :class:`SimulationConfig`'s scalar fields."""


@dataclass(frozen=True)
class SimulationConfig:
    """Everything that defines the synthetic frames; validated on construction.

    Args:
        preset: motion style, a key of :data:`PRESETS` (``"car"`` or ``"free"``).
        world: landmark layout, ``"street"`` or ``"open"``; None picks street for
            ``car`` and open otherwise.
        n_frames: frame pairs per :class:`Sequence`, in ``[1, 10**6]`` (:data:`MAX_FRAMES`).
        n_correspondences: putative matches per frame, exactly (>= 3).
        noise_sigma: std of the Gaussian pixel noise on every coordinate (px, in [0, 1e3]). With
            outliers its outlier threshold ``max(4, 8 noise_sigma)`` px must fit in the image (see
            Raises).
        outlier_ratio: contamination epsilon in [0, 1), or ``(low, high)`` drawn
            uniformly per frame.
        outliers: a preset of :data:`OUTLIER_PRESETS`, ``"default"`` or ``"hostile"``: the
            outlier mix and noise tail used where ``outlier_mix`` / ``noise_dof`` are None.
        outlier_mix: non-negative weights (sum > 0) of the outlier kinds among the outliers: a
            sequence in the order of :data:`OUTLIER_KINDS` (random mismatches, stereo mismatches,
            moving-object points, then the hostile kinds; missing trailing weights are 0) or a
            mapping from those names; None takes the ``outliers`` preset's. Stored as a tuple
            without trailing zeros beyond the first three.
        noise_dof: degrees of freedom (> 2) of Student-t pixel noise with scale ``noise_sigma``
            (heavy-tailed errors); None takes the preset's (Gaussian for ``default``).
        score_auc: ROC AUC of the match score as an inlier detector, in [0.5, 1).
        z_min, z_max: depth range (m) of the landmarks in both frames.
        camera: the stereo rig.
        speed: mean speed (m/frame) overriding the preset's; None keeps it.

    Raises:
        ValueError: naming the field and the value, e.g.
            ``SimulationConfig.noise_sigma must be a finite number in [0, 1000] (px), got -1``.
            Besides each field's own range, settings that no draw can simulate are refused:

            - ``noise_sigma`` whose outlier threshold ``max(4, 8 noise_sigma)`` px exceeds the
              largest distance between two measurements of the image, ``sqrt(2 (width - 1)^2 +
              (height - 1)^2)`` (1793 px for the default camera: ``noise_sigma <= 224``), when a
              frame can have outliers (``round(max epsilon * n_correspondences) >= 1``): every
              outlier is drawn at least that far from its true measurement, inside the image.
              Without outliers any ``noise_sigma`` up to 1e3 px stays valid.
            - ``z_min`` whose disparity ``fx baseline / z_min`` is not above ``min_disparity``, and
              ``z_max`` whose disparity ``fx baseline / z_max`` exceeds ``width - 1`` px (a point
              must be seen by both images at a depth in the range; a camera whose
              ``min_disparity`` is not below ``width - 1`` sees none at all).
            - ``n_frames`` above :data:`MAX_FRAMES`.
            - ``outlier_mix`` weights so large that their sum, or the outlier count times one,
              overflows a float (``(1e308, 1e308, 1e308)``: only the ratios matter).

    Settings that pass but leave the simulator unable to draw a frame (few landmarks stay in
    view for a very thin depth range, a high speed or a small, off-centre image; no moving object
    shows by a large outlier threshold: e.g. ``noise_sigma`` >= 50 px with the default mix) raise
    :class:`InfeasibleSettingsError` (a ``ValueError``) from :func:`~stereovo.simulation.simulate_frame`
    and :class:`~stereovo.simulation.Sequence`, naming the settings to change.
    """

    preset: str = "car"
    world: str | None = None
    n_frames: int = 100
    n_correspondences: int = 500
    noise_sigma: float = 0.5
    outlier_ratio: float | tuple[float, float] = 0.5
    outlier_mix: tuple[float, ...] | dict[str, float] | None = None
    score_auc: float = 0.75
    z_min: float = 3.0
    z_max: float = 60.0
    camera: StereoCamera = StereoCamera()
    speed: float | None = None
    outliers: str = "default"
    noise_dof: float | None = None

    def __post_init__(self) -> None:
        def fail(name: str, requirement: str) -> None:
            # an OptionError, as the scalar fields' checks raise: a caller maps the field by its name
            rule = f" must be {requirement}, got {value_repr(getattr(self, name))}"
            raise OptionError(f"SimulationConfig.{name}{rule}", name=name, rule=rule)

        # The scalar fields by the one options contract (stereovo.options); the composite ones below.
        for name, rule in _CONFIG_RULES.items():
            object.__setattr__(self, name, rule.check(name, getattr(self, name), prefix="SimulationConfig."))
        object.__setattr__(self, "noise_sigma", float(self.noise_sigma))

        ratio = self.outlier_ratio
        bounds = (ratio, ratio) if is_real(ratio) else tuple(ratio) if isinstance(ratio, (tuple, list)) else ()
        if len(bounds) != 2 or not all(is_finite_real(x) for x in bounds):
            fail("outlier_ratio", "a number in [0, 1) or a (low, high) pair in [0, 1)")
        low, high = float(bounds[0]), float(bounds[1])
        if not (0.0 <= low <= high < 1.0):
            fail("outlier_ratio", "in [0, 1) (a range needs 0 <= low <= high < 1)")
        object.__setattr__(self, "outlier_ratio", low if is_real(ratio) else (low, high))

        preset = OUTLIER_PRESETS[self.outliers]
        if self.noise_dof is None and preset["noise_dof"] is not None:
            object.__setattr__(self, "noise_dof", float(preset["noise_dof"]))
        mix = preset["outlier_mix"] if self.outlier_mix is None else self.outlier_mix
        if isinstance(mix, dict):
            unknown = sorted((str(k) if isinstance(k, str) else repr(k)) for k in mix if k not in OUTLIER_KINDS)
            if unknown:
                fail("outlier_mix", f"a mapping from outlier kinds {OUTLIER_KINDS} (unknown: {unknown})")
            mix = tuple(mix.get(kind, 0.0) for kind in OUTLIER_KINDS)
        # a sequence of weights (a numpy array only of one axis: len() of a 0-d array raises)
        mix_ok = isinstance(mix, (tuple, list)) or (isinstance(mix, np.ndarray) and mix.ndim == 1)
        mix_ok = mix_ok and 3 <= len(mix) <= len(OUTLIER_KINDS)
        mix_ok = mix_ok and all(is_finite_real(w) and w >= 0 for w in mix) and sum(mix) > 0
        if not mix_ok:
            fail("outlier_mix", f"3 to {len(OUTLIER_KINDS)} finite weights >= 0 with a positive sum "
                 f"(kinds {', '.join(OUTLIER_KINDS)}), or a mapping from those names")
        weights = [float(w) for w in mix]
        # A frame splits its outliers by count * w / sum(w) (pair._apportion): both must stay finite.
        n_out_max = round(self.epsilon_range[1] * self.n_correspondences)
        with np.errstate(over="ignore", invalid="ignore"):
            w = np.asarray(weights)
            if not (np.isfinite(w.sum()) and np.isfinite(n_out_max * w).all()):
                fail("outlier_mix", f"weights whose sum, and whose products with the outlier count ({n_out_max}), "
                                    "are finite floats (only their ratios matter: scale them down)")
        while len(weights) > 3 and weights[-1] == 0.0:
            weights.pop()
        object.__setattr__(self, "outlier_mix", tuple(weights))

        object.__setattr__(self, "score_auc", float(self.score_auc))

        if not isinstance(self.camera, StereoCamera):
            fail("camera", "a StereoCamera")
        if self.z_max <= self.z_min:
            fail("z_max", f"a finite depth > z_min={self.z_min} (m)")
        cam = self.camera
        # A landmark must be seen by both images at a depth in [z_min, z_max]: a disparity fx b / z
        # above min_disparity and at most width - 1 px (uL <= width - 1, uR >= 0).
        if not cam.min_disparity < cam.width - 1:
            fail("camera", f"a camera whose min_disparity ({cam.min_disparity} px) is below width - 1 "
                           f"({cam.width - 1} px): no disparity fits in its image")
        if cam.fx * cam.baseline / self.z_min <= cam.min_disparity:
            fail("z_min", f"small enough that fx*baseline/z_min exceeds min_disparity={cam.min_disparity} px")
        if cam.fx * cam.baseline / self.z_max > cam.width - 1:
            fail("z_max", f"large enough that fx*baseline/z_max fits in the image (at most width - 1 = "
                          f"{cam.width - 1} px; at z_max it is {cam.fx * cam.baseline / self.z_max:.6g} px)")
        object.__setattr__(self, "z_min", float(self.z_min))
        object.__setattr__(self, "z_max", float(self.z_max))

        # Every outlier lies at least max(4, 8 sigma) px (over uL, v, uR) from its true measurement,
        # both inside the image: a threshold beyond the image's largest such distance admits none.
        high = self.epsilon_range[1]
        if round(high * self.n_correspondences) >= 1:
            tau = max(MIN_OUTLIER_PX, OUTLIER_SIGMAS * self.noise_sigma)
            span = math.sqrt(2.0 * float(cam.width - 1) ** 2 + float(cam.height - 1) ** 2)
            if MIN_OUTLIER_PX > span:
                fail("camera", f"an image that can hold an outlier ({MIN_OUTLIER_PX:g} px from its true measurement) "
                               f"when frames have outliers (outlier_ratio={value_repr(self.outlier_ratio)})")
            if tau > span:
                fail("noise_sigma", f"small enough that the outlier threshold max(4, 8*noise_sigma) = {tau:g} px "
                                    f"fits in the {cam.width}x{cam.height} px image (at most {span:.6g} px between "
                                    f"two measurements) when frames have outliers (outlier_ratio={value_repr(self.outlier_ratio)})")

        if self.speed is not None:
            object.__setattr__(self, "speed", float(self.speed))

    @property
    def outlier_weights(self) -> dict[str, float]:
        """``outlier_mix`` as a mapping from every name of :data:`OUTLIER_KINDS` to its weight."""
        return {kind: (self.outlier_mix[i] if i < len(self.outlier_mix) else 0.0) for i, kind in enumerate(OUTLIER_KINDS)}

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
