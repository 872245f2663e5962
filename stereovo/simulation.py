"""Synthetic stereo visual-odometry frames: motion, world, matches, outliers and match scores.

A :class:`Frame` is one frame pair ``(k-1, k)``: ``N`` putative stereo matches
``prev[i] <-> curr[i]`` (each row ``(uL, vL, uR, vR)`` in pixels), a match score
per row, and a :class:`FrameTruth` that only benchmarks may read.

How a frame is made:

1. Motion. Body-frame linear and angular velocities (a twist ``(v, w)`` in
   m/frame and rad/frame) follow a mean-reverting AR(1) process, the exact
   discretisation of an Ornstein-Uhlenbeck process, per :class:`MotionPreset`.
   The camera moves by ``exp(twist)`` in its own frame, so the point transform
   is ``T = exp(-twist)`` and the pose update is ``geometry.pose_update``.
2. World. Landmarks are drawn procedurally, per frame pair, in a window
   anchored at the camera k-1 (a street: ground plane, two facades, clutter;
   or an open volume), stored in world coordinates, and kept only when both
   stereo pairs see them within ``[z_min, z_max]``. Nothing persists between
   frames: each frame pair is a fresh, seeded world patch.
3. Correspondences. Exactly ``N`` rows: ``round(epsilon N)`` outliers split
   by ``outlier_mix`` (random mismatches, stereo mismatches, one moving
   object), the rest inliers; Gaussian pixel noise with one ``v`` noise shared
   by both images; rows shuffled.
4. Scores. ``score = Phi(latent)`` with ``latent ~ N(mu, 1)`` for inliers and
   ``N(0, 1)`` for outliers, ``mu = sqrt(2) Phi^-1(auc)``: the ROC AUC of score
   vs inlier is ``auc`` exactly in expectation.

Every outlier is a *detectable* outlier: its noise-free measurement at k lies
at least ``max(4 px, 8 sigma)`` (norm over ``uL, v, uR``) from where the true
motion would put it, so labels mean what they say; stereo mismatches
additionally carry a relative depth error of at least 20 %.

Randomness: a frame's generator is split into independent streams (landmarks,
outliers, noise, scores, row order). With one seed, changing only
``noise_sigma`` leaves the inlier geometry and the standard-normal noise draws
unchanged, and changing only ``score_auc`` leaves everything but the scores
unchanged: benchmark grids get common random numbers across those axes.
"""

from __future__ import annotations

import enum
import functools
import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from scipy.signal import lfilter
from scipy.special import ndtr, ndtri

from .camera import StereoCamera
from .options import Choice, Integer, Number, Option, is_integer, is_real
from .geometry import (
    invert_transform,
    make_transform,
    pose_update,
    random_rotation,
    se3_exp,
    so3_exp,
)
from .seeding import seeded_generators

__all__ = [
    "OutlierKind",
    "MotionPreset",
    "PRESETS",
    "WORLDS",
    "SimulationConfig",
    "FrameTruth",
    "Frame",
    "simulate_frame",
    "Sequence",
]


class OutlierKind(enum.IntEnum):
    """Ground-truth label of a correspondence (stored as int8 in :class:`FrameTruth`)."""

    INLIER = 0
    RANDOM_MISMATCH = 1
    STEREO_MISMATCH = 2
    MOVING_OBJECT = 3


# --------------------------------------------------------------------------- motion


@dataclass(frozen=True)
class MotionPreset:
    """Stationary statistics of the body-frame velocity process of one motion style.

    The twist ``xi = (v, w)`` (linear m/frame along camera x, y, z; angular
    rad/frame about camera x, y, z) evolves as
    ``xi_k - mean = a (xi_{k-1} - mean) + sqrt(1 - a^2) std * eta_k`` with
    ``a = exp(-reversion)`` and ``eta_k ~ N(0, I)``: its stationary law is
    ``N(mean, diag(std^2))`` and its correlation time ``1 / reversion`` frames.

    Args:
        speed: mean forward speed along the camera +z axis (m/frame).
        linear_std: stationary std of the linear velocity along x, y, z (m/frame).
        angular_std: stationary std of the angular velocity about x, y, z (rad/frame);
            y points down, so yaw is about y.
        reversion: mean-reversion rate per frame (> 0); large values give white noise.
        description: one line for humans.
    """

    speed: float
    linear_std: tuple[float, float, float]
    angular_std: tuple[float, float, float]
    reversion: float
    description: str = ""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speed) and self.speed >= 0):
            raise ValueError(f"MotionPreset.speed must be a finite number >= 0, got {self.speed!r}")
        for name in ("linear_std", "angular_std"):
            value = tuple(float(x) for x in getattr(self, name))
            if len(value) != 3 or not all(math.isfinite(x) and x >= 0 for x in value):
                raise ValueError(f"MotionPreset.{name} must be 3 finite numbers >= 0, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)
        if not (math.isfinite(self.reversion) and self.reversion > 0):
            raise ValueError(f"MotionPreset.reversion must be a finite number > 0, got {self.reversion!r}")

    @property
    def mean(self) -> np.ndarray:
        """Mean twist ``(6,)``: forward at ``speed``, no rotation."""
        return np.array([0.0, 0.0, self.speed, 0.0, 0.0, 0.0])

    @property
    def std(self) -> np.ndarray:
        """Stationary std ``(6,)`` of the twist, ordered like the twist ``(v, w)``."""
        return np.array(self.linear_std + self.angular_std)

    def with_speed(self, speed: float) -> MotionPreset:
        """The same style at another mean speed (m/frame); linear stds scale along."""
        scale = speed / self.speed if self.speed > 0 else 0.0
        return replace(self, speed=float(speed), linear_std=tuple(s * scale for s in self.linear_std))

    def sample_twist(self, rng: np.random.Generator) -> np.ndarray:
        """One twist ``(6,)`` from the stationary law: the process at a random time."""
        return self.mean + self.std * rng.standard_normal(6)

    def sample_twists(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` consecutive twists ``(n, 6)`` of the process, started in its stationary law."""
        a = math.exp(-self.reversion)
        start = self.std * rng.standard_normal(6)
        innovations = self.std * math.sqrt(1.0 - a * a) * rng.standard_normal((n, 6))
        # lfilter runs the AR(1) recursion in C; zi carries the start state.
        deviation = lfilter([1.0], [1.0, -a], innovations, axis=0, zi=(a * start)[None, :])[0]
        return self.mean + deviation


PRESETS: dict[str, MotionPreset] = {
    "car": MotionPreset(
        speed=1.0,
        linear_std=(0.02, 0.01, 0.15),
        angular_std=(0.001, 0.02, 0.001),
        reversion=0.1,
        description="road vehicle: forward ~1 m/frame, yaw-dominant turns, small pitch/roll",
    ),
    "free": MotionPreset(
        speed=0.3,
        linear_std=(0.1, 0.1, 0.1),
        angular_std=(0.03, 0.03, 0.03),
        reversion=0.2,
        description="hand-held / drone: 6-DoF, ~0.3 m/frame, a few degrees per frame about all axes",
    ),
}
"""Motion presets by name; ``SimulationConfig.preset`` picks one."""

WORLDS: tuple[str, ...] = ("street", "open")
"""Landmark layouts: a street (ground, facades, clutter) or an open volume."""

_DEFAULT_WORLD = {"car": "street", "free": "open"}


# --------------------------------------------------------------------------- config


MAX_NOISE_SIGMA_PX = 1e3
"""The largest simulated pixel noise (px): noise as large as the image; beyond it the measurements
are no longer pixels of this camera (and at ~1e300 they overflow)."""

_CONFIG_RULES: dict[str, Option] = {
    "preset": Choice(choices=tuple(sorted(PRESETS))),
    "world": Choice(choices=tuple(WORLDS), allow_none=True),
    "n_frames": Integer(low=1, high=10**9),
    "n_correspondences": Integer(low=3, high=10**8),
    "noise_sigma": Number(low=0.0, high=MAX_NOISE_SIGMA_PX, unit="px"),
    "score_auc": Number(low=0.5, high=1.0, high_open=True),
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


# --------------------------------------------------------------------------- frames


@dataclass(frozen=True, eq=False)
class FrameTruth:
    """Ground truth of one frame pair. No estimator, feature or agent may read it.

    Attributes:
        rotation: ``(3, 3)`` true motion R with ``x_k = R x_{k-1} + t``.
        translation: ``(3,)`` true t (m); ``(R, t) = relative_motion(pose_prev, pose_curr)``.
        inlier: ``(N,)`` bool.
        outlier_kind: ``(N,)`` int8 values of :class:`OutlierKind`.
        pose_prev: ``(4, 4)`` camera-to-world pose of frame k-1.
        pose_curr: ``(4, 4)`` camera-to-world pose of frame k.
        outlier_ratio: the contamination epsilon drawn for this frame.
    """

    rotation: np.ndarray
    translation: np.ndarray
    inlier: np.ndarray
    outlier_kind: np.ndarray
    pose_prev: np.ndarray
    pose_curr: np.ndarray
    outlier_ratio: float


@dataclass(frozen=True, eq=False)
class Frame:
    """One frame pair ``(k-1, k)`` of putative stereo matches.

    Attributes:
        index: k, 1-based within a :class:`Sequence`.
        prev: ``(N, 4)`` float64 measurements ``(uL, vL, uR, vR)`` (px) at k-1.
        curr: ``(N, 4)`` at k; row i of ``prev`` and ``curr`` is one putative match.
        scores: ``(N,)`` float64 match scores in (0, 1), higher = more likely an inlier.
        camera: the stereo rig.
        noise_sigma: the sensor's pixel noise std (px), a known sensor spec.
        truth: ground truth; for benchmarks only.
    """

    index: int
    prev: np.ndarray
    curr: np.ndarray
    scores: np.ndarray
    camera: StereoCamera
    noise_sigma: float
    truth: FrameTruth

    def __post_init__(self) -> None:
        n = np.shape(self.prev)[0] if np.ndim(self.prev) == 2 else -1
        if np.shape(self.prev) != (n, 4) or np.shape(self.curr) != (n, 4):
            raise ValueError(
                "Frame.prev and Frame.curr must both be (N, 4), "
                f"got {np.shape(self.prev)} and {np.shape(self.curr)}"
            )
        if np.shape(self.scores) != (n,):
            raise ValueError(f"Frame.scores must be ({n},), got {np.shape(self.scores)}")

    @property
    def n(self) -> int:
        """Number of putative matches N."""
        return int(self.prev.shape[0])

    def __repr__(self) -> str:
        return (
            f"Frame(index={self.index}, n={self.n}, noise_sigma={self.noise_sigma}, "
            f"outlier_ratio={self.truth.outlier_ratio:.3f})"
        )


# --------------------------------------------------------------------------- internals

_CAMERA_HEIGHT = 1.65  # m above the ground (KITTI rig)
_FRUSTUM_SLACK = 1.15  # landmarks are drawn in a frustum this much wider, so frame k's view is covered
_STREET_PARTS = (0.35, 0.45, 0.20)  # ground, facades, clutter (fractions of drawn candidates)
_ACCEPTANCE_GUESS = {"street": 0.45, "open": 0.4}  # sizes the first oversampling batch
_MAX_BATCHES = 8
_MAX_BATCH_SIZE = 2_000_000
_MAX_REDRAWS = 30
_MAX_OBJECT_ATTEMPTS = 30
_MIN_OUTLIER_PX = 4.0
_STEREO_FACTOR = (1.25, 2.5)  # range of the disparity ratio of a stereo mismatch (>= 20 % depth error)
_STREAMS = 5  # landmarks, outliers, noise, scores, row order
_SEQUENCE_NAMESPACE = 0x566F  # keeps Sequence's child seeds apart from a user's own spawn() children


def _outlier_threshold(sigma: float) -> float:
    """Minimum pixel distance (px) between an outlier and where the true motion puts it."""
    return max(_MIN_OUTLIER_PX, 8.0 * sigma)


@functools.lru_cache(maxsize=256)
def _apportion(total: int, weights: tuple[float, ...]) -> tuple[int, ...]:
    """Split ``total`` into integer counts proportional to ``weights`` (largest remainder).

    Cached: a sequence asks for the same split every frame, and the dozen small numpy
    calls cost as much as drawing a frame's scores.
    """
    w = np.asarray(weights, dtype=float)
    raw = total * w / w.sum()
    counts = np.floor(raw).astype(int)
    order = np.argsort(-(raw - counts), kind="stable")
    counts[order[: total - counts.sum()]] += 1
    return tuple(int(c) for c in counts)


def _stream_generators(entropy: np.ndarray, n_streams: int) -> list[np.random.Generator]:
    """Generators of ``np.random.SeedSequence(entropy.tolist()).spawn(n_streams)``, ``entropy``
    four non-negative int64 draws (numpy's seeding, computed by :mod:`stereovo.seeding`)."""
    return seeded_generators(entropy.tolist(), [(i,) for i in range(n_streams)])


def _loguniform(rng: np.random.Generator, low: float, high: float, size: int) -> np.ndarray:
    return low * np.exp(rng.random(size) * math.log(high / low))


def _rotation_about_y(angle: float) -> np.ndarray:
    """``so3_exp((0, angle, 0))`` in closed form (a heading change on the street)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _frustum(cam: StereoCamera) -> tuple[float, float, float, float]:
    """Tangent bounds ``(left, right, top, bottom)`` of the left camera's view, widened by the slack."""
    s = _FRUSTUM_SLACK
    return (-s * cam.cx / cam.fx, s * (cam.width - 1 - cam.cx) / cam.fx,
            -s * cam.cy / cam.fy, s * (cam.height - 1 - cam.cy) / cam.fy)


def _valid(meas: np.ndarray, cam: StereoCamera) -> np.ndarray:
    """Mask ``(N,)`` of measurements ``(N, 4)`` inside both images with a disparity above
    ``min_disparity`` (``cam.in_image & cam.has_depth`` in one compiled pass)."""
    return _valid_rows(np.ascontiguousarray(meas, dtype=float), float(cam.width - 1), float(cam.height - 1),
                       float(cam.min_disparity))


@njit(cache=True, nogil=True)
def _valid_rows(meas, u_max, v_max, min_disparity):
    n = meas.shape[0]
    ok = np.empty(n, dtype=np.bool_)
    for i in range(n):
        uL, vL, uR, vR = meas[i, 0], meas[i, 1], meas[i, 2], meas[i, 3]
        ok[i] = (0.0 <= uL <= u_max and 0.0 <= uR <= u_max and 0.0 <= vL <= v_max and 0.0 <= vR <= v_max
                 and uL - uR > min_disparity)
    return ok


@njit(cache=True, nogil=True)
def _see_point(p0, p1, p2, to_prev, to_curr, cam, z_min, z_max, X_prev, X_curr, i):
    """Map the point ``(p0, p1, p2)`` by ``to_prev``, ``to_curr`` (4x4) into row ``i`` of
    ``X_prev``, ``X_curr``; True if both stereo cameras see it (as :meth:`StereoCamera.is_visible`).

    ``cam`` is ``(fx, fy, cx, cy, baseline, width, height, min_disparity)``.
    """
    fx, fy, cx, cy, b, width, height, min_disp = cam[0], cam[1], cam[2], cam[3], cam[4], cam[5], cam[6], cam[7]
    visible = True
    for T, out in ((to_prev, X_prev), (to_curr, X_curr)):
        for r in range(3):
            out[i, r] = T[r, 0] * p0 + T[r, 1] * p1 + T[r, 2] * p2 + T[r, 3]
        z = out[i, 2]
        if not (z >= z_min and z <= z_max):
            visible = False
            continue
        uL = fx * out[i, 0] / z + cx
        v = fy * out[i, 1] / z + cy
        disparity = fx * b / z
        uR = uL - disparity
        inside = uL >= 0.0 and uL <= width - 1 and uR >= 0.0 and uR <= width - 1 and v >= 0.0 and v <= height - 1
        visible = visible and inside and disparity > min_disp
    return visible


@njit(cache=True, nogil=True)
def _seen_by_both(points, to_prev, to_curr, cam, z_min, z_max):
    """The points ``(n, 3)`` visible in both cameras (see :func:`_see_point`), mapped by the rigid
    transforms ``to_prev``, ``to_curr`` (4x4) into cameras k-1 and k: ``X_prev, X_curr (m, 3)``,
    in their order."""
    n = points.shape[0]
    X_prev = np.empty((n, 3))
    X_curr = np.empty((n, 3))
    kept = 0
    for i in range(n):
        kept += _see_point(points[i, 0], points[i, 1], points[i, 2], to_prev, to_curr, cam, z_min, z_max, X_prev, X_curr, kept)
    return X_prev[:kept], X_curr[:kept]


@njit(cache=True, nogil=True)
def _street_candidates(u, g, walls, frustum, z_min, z_max, to_prev, to_curr, cam):
    """Street landmarks from uniforms ``u (7, n)`` and normals ``g (2, n)``, seen through the
    cameras: ``X_prev, X_curr (m, 3)`` of the candidates drawn and visible in both, in their order.

    ``walls`` is ``(left, right, height_left, height_right)`` (m), ``frustum`` the tangent bounds
    ``(left, right, top, bottom)``. A candidate is on the ground, a facade or clutter with the
    odds of ``_STREET_PARTS``; its depth is log-uniform in ``[z_min, z_max]``. Rows of ``u``:
    depth, part, ground x, facade side, facade height, clutter x, clutter height; of ``g``:
    ground roughness, facade relief.
    """
    n = u.shape[1]
    h = _CAMERA_HEIGHT
    left_wall, right_wall, height_left, height_right = walls[0], walls[1], walls[2], walls[3]
    log_range = math.log(z_max / z_min)
    ground_end = _STREET_PARTS[0]
    facade_end = _STREET_PARTS[0] + _STREET_PARTS[1]
    total = _STREET_PARTS[0] + _STREET_PARTS[1] + _STREET_PARTS[2]
    X_prev = np.empty((n, 3))
    X_curr = np.empty((n, 3))
    kept = 0  # rows written so far: a candidate is written at row `kept` and kept if it counts
    for i in range(n):
        z = z_min * math.exp(u[0, i] * log_range)
        x_lo, x_hi = max(frustum[0] * z, -left_wall), min(frustum[1] * z, right_wall)
        y_top = frustum[2] * z
        part = u[1, i] * total
        if part < ground_end:  # rough ground plane h below the camera, between the facades
            drawn = x_hi >= x_lo
            x = x_lo + (x_hi - x_lo) * u[2, i]
            y = h + 0.02 * g[0, i]
        elif part < facade_end:  # a facade, with some relief, up to its building's height
            on_right = u[3, i] < 0.5
            x = (right_wall if on_right else -left_wall) + 0.1 * g[1, i]
            y_lo = max(y_top, h - (height_right if on_right else height_left))
            drawn = h >= y_lo
            y = y_lo + (h - y_lo) * u[4, i]
        else:  # clutter up to 3 m: poles, parked cars, vegetation
            cx_lo, cx_hi = max(x_lo, 0.5 - left_wall), min(x_hi, right_wall - 0.5)
            cy_lo = max(y_top, h - 3.0)
            drawn = cx_hi >= cx_lo and h >= cy_lo
            x = cx_lo + (cx_hi - cx_lo) * u[5, i]
            y = cy_lo + (h - cy_lo) * u[6, i]
        seen = _see_point(x, y, z, to_prev, to_curr, cam, z_min, z_max, X_prev, X_curr, kept)
        if drawn and seen:
            kept += 1
    return X_prev[:kept], X_curr[:kept]


@njit(cache=True, nogil=True)
def _object_candidates(u, half, face_cdf, orientation, centre, to_prev, to_curr_moved, to_curr_static, cam, z_min, z_max, tau):
    """Points on the faces of a box, from uniforms ``u (n, 5)``, that both cameras see on a face
    turned towards camera k-1 and whose frame-k image lies at least ``tau`` px (over uL, v, uR)
    from where a static point would be (or that would be behind camera k if static): their
    ``X_prev, X_curr (m, 3)`` in the cameras, in their order.

    Columns of ``u``: the position along the three box axes, the face (area-weighted through
    ``face_cdf``), its side. ``half (3,)`` are the box's half sizes, ``orientation (3, 3)`` and
    ``centre (3,)`` its pose in camera k-1; ``to_curr_moved`` sees the box after its own motion.
    """
    n = u.shape[0]
    fx, fy, b = cam[0], cam[1], cam[4]
    X_prev = np.empty((n, 3))
    X_curr = np.empty((n, 3))
    kept = 0  # as in _street_candidates: a candidate is written at row `kept`, kept if it counts
    local = np.empty(3)
    p = np.empty(3)
    for i in range(n):
        for k in range(3):
            local[k] = half[k] * (2.0 * u[i, k] - 1.0)
        axis = 0
        while axis < 2 and face_cdf[axis] <= u[i, 3]:
            axis += 1
        sign = -1.0 if u[i, 4] < 0.5 else 1.0
        local[axis] = sign * half[axis]
        facing = 0.0
        for r in range(3):
            p[r] = orientation[r, 0] * local[0] + orientation[r, 1] * local[1] + orientation[r, 2] * local[2] + centre[r]
        for r in range(3):
            facing += sign * orientation[r, axis] * p[r]  # outward normal . ray from camera k-1
        seen = _see_point(p[0], p[1], p[2], to_prev, to_curr_moved, cam, z_min, z_max, X_prev, X_curr, kept)
        if not (seen and facing < 0.0):
            continue
        s0 = to_curr_static[0, 0] * p[0] + to_curr_static[0, 1] * p[1] + to_curr_static[0, 2] * p[2] + to_curr_static[0, 3]
        s1 = to_curr_static[1, 0] * p[0] + to_curr_static[1, 1] * p[1] + to_curr_static[1, 2] * p[2] + to_curr_static[1, 3]
        s2 = to_curr_static[2, 0] * p[0] + to_curr_static[2, 1] * p[1] + to_curr_static[2, 2] * p[2] + to_curr_static[2, 3]
        if s2 <= 1e-6:
            kept += 1  # a static point there would be behind camera k: the motion shows
            continue
        zc = X_curr[kept, 2]
        du = fx * (X_curr[kept, 0] / zc - s0 / s2)
        dv = fy * (X_curr[kept, 1] / zc - s1 / s2)
        dd = fx * b * (1.0 / zc - 1.0 / s2)  # uR = uL - fx b / z
        if math.sqrt(du * du + dv * dv + (du - dd) * (du - dd)) >= tau:
            kept += 1
    return X_prev[:kept], X_curr[:kept]


def _camera_vector(cam: StereoCamera) -> np.ndarray:
    return np.array([cam.fx, cam.fy, cam.cx, cam.cy, cam.baseline, cam.width, cam.height, cam.min_disparity])


class _StreetLayout:
    """One frame's street, in the frame of camera k-1: facades at ``x = -left, +right``."""

    def __init__(self, rng: np.random.Generator) -> None:
        left, right = rng.uniform(4.0, 10.0, 2)
        height_left, height_right = rng.uniform(6.0, 20.0, 2)
        self.walls = np.array([left, right, height_left, height_right])

    def sample_visible(
        self, rng: np.random.Generator, n: int, cam: StereoCamera, z_min: float, z_max: float,
        to_prev: np.ndarray, to_curr: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Of ``n`` candidates, those drawn and visible in both cameras, seen through the 4x4
        ``to_prev``, ``to_curr``: ``X_prev, X_curr (m, 3)`` (m; see :func:`_street_candidates`)."""
        u = rng.random((7, n))
        g = rng.standard_normal((2, n))
        return _street_candidates(
            u, g, self.walls, np.array(_frustum(cam)), z_min, z_max, to_prev, to_curr, _camera_vector(cam)
        )


def _sample_open(rng: np.random.Generator, n: int, cam: StereoCamera, z_min: float, z_max: float) -> np.ndarray:
    """Candidate landmarks ``(n, 3)`` uniform in image direction and log-uniform in depth."""
    left, right, top, bottom = _frustum(cam)
    z = _loguniform(rng, z_min, z_max, n)
    x = z * rng.uniform(left, right, n)
    y = z * rng.uniform(top, bottom, n)
    return np.stack([x, y, z], axis=1)


def _visible_landmarks(
    n: int, config: SimulationConfig, to_prev: np.ndarray, to_curr: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` landmarks seen by both stereo pairs: their camera-frame points ``(n, 3)`` at k-1 and k.

    Landmarks live in world coordinates, drawn in camera k-1's frame; the 4x4 ``to_prev``,
    ``to_curr`` (world-to-camera @ camera-k-1-to-world) take them to the two cameras.
    """
    cam, world = config.camera, config.resolved_world
    layout = _StreetLayout(rng) if world == "street" else None
    acceptance = _ACCEPTANCE_GUESS[world]
    cam_vector = _camera_vector(cam)
    kept_prev, kept_curr, count = [], [], 0
    for _ in range(_MAX_BATCHES):
        if count >= n:
            break
        batch = min(_MAX_BATCH_SIZE, int(1.3 * (n - count) / acceptance) + 32)
        if layout is not None:
            X_prev, X_curr = layout.sample_visible(rng, batch, cam, config.z_min, config.z_max, to_prev, to_curr)
        else:
            local = _sample_open(rng, batch, cam, config.z_min, config.z_max)
            X_prev, X_curr = _seen_by_both(local, to_prev, to_curr, cam_vector, config.z_min, config.z_max)
        kept_prev.append(X_prev)
        kept_curr.append(X_curr)
        count += len(X_prev)
        acceptance = max(len(X_prev) / batch, 1e-3)
    if count < n:
        raise RuntimeError(
            f"found only {count} of {n} landmarks visible in both frames; the camera and depth range "
            f"[{config.z_min}, {config.z_max}] m see too little of the {world!r} world"
        )
    return np.concatenate(kept_prev)[:n], np.concatenate(kept_curr)[:n]


@njit(cache=True, nogil=True)
def _place_mismatches(todo, rows, other, shift, depth, u, v, meas_curr, fake, fb, d_lo, d_hi, u_max, v_max, tau):
    """Write a wrong frame-k measurement into ``fake[todo[i]]`` for each ``i``; return the rows of
    ``todo`` whose measurement still lies within ``tau`` px (over uL, v, uR) of the true one.

    ``other[i] < 0.5`` borrows landmark ``(rows[todo[i]] + shift[i]) % pool``'s measurement;
    otherwise a random stereo point: disparity ``fb / depth[i]`` clipped to ``[d_lo, d_hi]``
    (tiny custom images cannot hold the disparity of near depths), ``uL`` uniform (``u[i]``)
    where that disparity fits, ``v = v_max v[i]``. Same arithmetic, in the same order, as the
    numpy expressions it replaced (frames bit for bit).
    """
    pool = meas_curr.shape[0]
    near = np.empty(todo.shape[0], dtype=np.int64)
    n_near = 0
    for i in range(todo.shape[0]):
        row = todo[i]
        if other[i] < 0.5:
            j = (rows[row] + shift[i]) % pool
            for c in range(4):
                fake[row, c] = meas_curr[j, c]
        else:
            d = min(max(fb / depth[i], d_lo), d_hi)
            uL = d + (u_max - d) * u[i]
            fake[row, 0] = uL
            fake[row, 1] = v_max * v[i]
            fake[row, 2] = uL - d
            fake[row, 3] = v_max * v[i]
        true = meas_curr[rows[row]]
        e0, e1, e2 = fake[row, 0] - true[0], fake[row, 1] - true[1], fake[row, 2] - true[2]
        if np.sqrt(e0 * e0 + e1 * e1 + e2 * e2) < tau:
            near[n_near] = row
            n_near += 1
    return near[:n_near]


def _random_mismatches(
    rows: np.ndarray, meas_curr: np.ndarray, config: SimulationConfig, rng: np.random.Generator
) -> np.ndarray:
    """Wrong frame-k measurements ``(len(rows), 4)`` for landmarks ``rows`` of ``meas_curr``.

    Half take another landmark's frame-k measurement, half a random stereo point (a depth
    log-uniform in [z_min, z_max], in the image); draws that land near the true one are
    redrawn so every row is a real outlier.
    """
    n, pool, cam = len(rows), len(meas_curr), config.camera
    fake = np.empty((n, 4))
    todo = np.arange(n)
    tau = _outlier_threshold(config.noise_sigma)
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    meas_curr = np.ascontiguousarray(meas_curr, dtype=float)
    for _ in range(_MAX_REDRAWS):
        if todo.size == 0:
            break
        m = todo.size
        other = rng.random(m)
        shift = rng.integers(1, pool, size=m)
        depth = _loguniform(rng, config.z_min, config.z_max, m)
        u, v = rng.random(m), rng.random(m)
        todo = _place_mismatches(
            todo, rows, other, shift, depth, u, v, meas_curr, fake, cam.fx * cam.baseline,
            cam.min_disparity * 1.5, 0.9 * (cam.width - 1), float(cam.width - 1), float(cam.height - 1), tau,
        )
    return fake


def _stereo_mismatches(meas: np.ndarray, config: SimulationConfig, rng: np.random.Generator) -> np.ndarray:
    """Frame-k measurements ``(n, 4)`` with the true left point and a wrong right point.

    The disparity is multiplied or divided by a factor in ``_STEREO_FACTOR`` (a
    depth error of at least 20 %) and moved by at least the outlier threshold,
    staying valid: the right point in the image, the disparity above
    ``min_disparity`` with room for noise.
    """
    cam, n = config.camera, len(meas)
    factor = np.exp(rng.uniform(*np.log(_STEREO_FACTOR), n))
    want_up = rng.random(n)
    out = np.array(meas, dtype=float)  # a C-ordered copy
    floor = cam.min_disparity + max(0.5, 3.0 * config.noise_sigma)
    _move_right_points(out, factor, want_up, _outlier_threshold(config.noise_sigma), floor)
    return out


@njit(cache=True, nogil=True)
def _move_right_points(meas, factor, want_up, tau, floor):
    """In place: ``uR = uL - d'``, ``d'`` the disparity times (``want_up < 0.5``) or divided by
    ``factor``, moved at least ``tau``; the other way when that one leaves the image (``uR < 0``)
    or the disparity floor; neither fitting (a far point at the left border under heavy noise),
    the largest disparity the image allows."""
    for i in range(meas.shape[0]):
        uL = meas[i, 0]
        d = uL - meas[i, 2]
        d_up = max(d * factor[i], d + tau)
        d_down = min(d / factor[i], d - tau)
        up_ok, down_ok = uL - d_up >= 0, d_down >= floor
        if up_ok and (want_up[i] < 0.5 or not down_ok):
            d_new = d_up
        elif down_ok:
            d_new = d_down
        else:
            d_new = max(uL, floor)
        meas[i, 2] = uL - d_new


def _moving_object(
    n: int, config: SimulationConfig, to_prev: np.ndarray, to_curr_static: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame points ``(n, 3)`` at k-1 and k of one rigid box moving on its own.

    A car on the street (on the ground, driving along its heading at 0.5-2
    m/frame, turning up to 3 deg/frame) or a box anywhere in the open world,
    5-25 m ahead. Only faces turned towards camera k-1 carry points, and only
    points whose frame-k image lies at least the outlier threshold away from
    where a static point would be are kept: the object's motion must show.
    """
    if n == 0:
        return np.empty((0, 3)), np.empty((0, 3))
    cam = config.camera
    cam_vector = _camera_vector(cam)
    tau = _outlier_threshold(config.noise_sigma)
    street = config.resolved_world == "street"
    z_lo, z_hi = max(5.0, config.z_min + 2.0), min(25.0, config.z_max - 2.0)
    if z_lo > z_hi:
        z_lo = z_hi = 0.5 * (config.z_min + config.z_max)
    for _ in range(_MAX_OBJECT_ATTEMPTS):
        depth = rng.uniform(z_lo, z_hi)
        centre = np.array([
            (rng.uniform(0.25, 0.75) * (cam.width - 1) - cam.cx) / cam.fx * depth,
            (rng.uniform(0.25, 0.75) * (cam.height - 1) - cam.cy) / cam.fy * depth,
            depth,
        ])
        if street:
            half = 0.5 * np.array([rng.uniform(1.6, 2.0), rng.uniform(1.4, 1.8), rng.uniform(3.5, 5.0)])
            centre[1] = _CAMERA_HEIGHT - half[1]
            heading = rng.uniform(-np.pi, np.pi)
            orientation = _rotation_about_y(heading)
            # a random sign, drawn as Generator.choice([-1.0, 1.0]) draws it, without its overhead
            velocity = orientation[:, 2] * rng.uniform(0.5, 2.0) * (-1.0, 1.0)[int(rng.integers(0, 2))]
            spin = _rotation_about_y(rng.uniform(-1, 1) * np.radians(3.0))
        else:
            half = 0.5 * rng.uniform(0.8, 3.0, 3)
            orientation = random_rotation(rng)
            direction = rng.standard_normal(3)
            velocity = direction / np.linalg.norm(direction) * rng.uniform(0.5, 2.0)
            spin = random_rotation(rng, np.radians(3.0))
        # Object motion in camera k-1 coordinates: rotate about its centre, then translate.
        obj_R, obj_t = spin, centre - spin @ centre + velocity
        areas = np.array([half[1] * half[2], half[0] * half[2], half[0] * half[1]])
        face_cdf = np.cumsum(areas)
        face_cdf /= face_cdf[-1]
        # Object points live in camera k-1 coordinates; at k the object has moved by obj first.
        obj = np.eye(4)
        obj[:3, :3], obj[:3, 3] = obj_R, obj_t
        to_curr_moved = to_curr_static @ obj

        def draw(size: int) -> tuple[np.ndarray, np.ndarray]:
            return _object_candidates(
                rng.random((size, 5)), half, face_cdf, orientation, centre, to_prev, to_curr_moved,
                to_curr_static, cam_vector, config.z_min, config.z_max, tau,
            )

        probe = max(64, 2 * n)
        X_prev, X_curr = draw(probe)
        acceptance = len(X_prev) / probe
        if acceptance < 0.02:
            continue  # mostly hidden or barely moving: try another object
        kept_prev, kept_curr, count = [X_prev], [X_curr], len(X_prev)
        while count < n:
            X_prev, X_curr = draw(int(1.3 * (n - count) / acceptance) + 32)
            kept_prev.append(X_prev)
            kept_curr.append(X_curr)
            count += len(X_prev)
        return np.concatenate(kept_prev)[:n], np.concatenate(kept_curr)[:n]
    raise RuntimeError(
        f"could not place a visibly moving object with {n} points in {_MAX_OBJECT_ATTEMPTS} attempts; "
        f"the camera or depth range [{config.z_min}, {config.z_max}] m is too restrictive"
    )


@njit(cache=True, nogil=True)
def _noisy_rows(meas, z, sigma, out):
    """``out (N, 4) = meas + sigma * z[:, (0, 1, 2, 1)]``: the ``v`` noise shared by both images.
    (``out`` comes from numpy: see :func:`stereovo.camera._project_rows`.)"""
    n = meas.shape[0]
    for i in range(n):
        out[i, 0] = meas[i, 0] + sigma * z[i, 0]
        out[i, 1] = meas[i, 1] + sigma * z[i, 1]
        out[i, 2] = meas[i, 2] + sigma * z[i, 2]
        out[i, 3] = meas[i, 3] + sigma * z[i, 1]


def _add_noise(
    meas: np.ndarray, normal: np.ndarray, config: SimulationConfig, rng: np.random.Generator
) -> np.ndarray:
    """Noisy copies of valid noise-free measurements ``(N, 4)``.

    ``normal`` ``(N, 3)`` are standard-normal draws for ``(uL, v, uR)``; the
    ``v`` draw is shared by both images (rectified pair). Rows that leave the
    image or lose their disparity are redrawn (a truncated Gaussian), so every
    measurement stays usable.
    """
    sigma, cam = config.noise_sigma, config.camera

    def noisy(rows: np.ndarray, z: np.ndarray) -> np.ndarray:
        out = np.empty((rows.shape[0], 4))
        _noisy_rows(np.ascontiguousarray(rows, dtype=float), np.ascontiguousarray(z, dtype=float), float(sigma), out)
        return out

    out = noisy(meas, normal)
    for _ in range(_MAX_REDRAWS):
        bad = np.flatnonzero(~_valid(out, cam))
        if bad.size == 0:
            return out
        out[bad] = noisy(meas[bad], rng.standard_normal((bad.size, 3)))
    bad = ~_valid(out, cam)
    if not _valid(meas[bad], cam).all():
        raise RuntimeError("simulator bug: a noise-free measurement left the image or lost its disparity")
    out[bad] = meas[bad]  # vanishingly rare: keep the valid noise-free row
    return out


def _simulate_pair(
    config: SimulationConfig, pose_prev: np.ndarray, pose_curr: np.ndarray, index: int, rng: np.random.Generator
) -> Frame:
    """Correspondences between two given camera-to-world poses."""
    cam, N = config.camera, config.n_correspondences
    landmark_rng, outlier_rng, noise_rng, score_rng, order_rng = _stream_generators(
        rng.integers(0, 2**63, size=4), _STREAMS
    )

    low, high = config.epsilon_range
    epsilon = low if low == high else float(rng.uniform(low, high))
    n_out = int(round(epsilon * N))
    n_in = N - n_out
    n_random, n_stereo, n_moving = _apportion(n_out, config.outlier_mix)

    # World-to-camera @ camera-k-1-to-world: how cameras k-1 and k see points given in camera k-1's
    # frame. The second is the relative motion itself (geometry.relative_motion's product).
    to_prev = invert_transform(pose_prev) @ pose_prev
    to_curr = invert_transform(pose_curr) @ pose_prev
    rotation, translation = to_curr[:3, :3].copy(), to_curr[:3, 3].copy()

    # Two spare landmarks guarantee that a random mismatch always has another landmark to borrow.
    n_pool = n_in + n_random + n_stereo
    X_prev, X_curr = _visible_landmarks(n_pool + 2, config, to_prev, to_curr, landmark_rng)
    meas_prev, meas_curr = cam.project(X_prev), cam.project(X_curr)
    O_prev, O_curr = _moving_object(n_moving, config, to_prev, to_curr, outlier_rng)

    random_rows = np.arange(n_in, n_in + n_random)
    stereo_rows = np.arange(n_in + n_random, n_pool)
    clean_prev = np.concatenate([meas_prev[:n_pool], cam.project(O_prev).reshape(-1, 4)])
    clean_curr = np.concatenate([
        meas_curr[:n_in],
        _random_mismatches(random_rows, meas_curr, config, outlier_rng),
        _stereo_mismatches(meas_curr[stereo_rows], config, outlier_rng),
        cam.project(O_curr).reshape(-1, 4),
    ])
    kind = np.repeat(
        np.array([OutlierKind.INLIER, OutlierKind.RANDOM_MISMATCH, OutlierKind.STEREO_MISMATCH,
                  OutlierKind.MOVING_OBJECT], dtype=np.int8),
        [n_in, n_random, n_stereo, n_moving],
    )
    assert clean_prev.shape == clean_curr.shape == (N, 4)

    # One (2, N, 3) draw in row order, so the same seed gives the same standard-normal noise at any sigma.
    normal = noise_rng.standard_normal((2, N, 3))
    prev = _add_noise(clean_prev, normal[0], config, noise_rng)
    curr = _add_noise(clean_curr, normal[1], config, noise_rng)

    inlier = kind == OutlierKind.INLIER
    mu = math.sqrt(2.0) * float(ndtri(config.score_auc))
    latent = score_rng.standard_normal(N) + mu * inlier
    scores = np.clip(ndtr(latent), np.finfo(float).tiny, np.nextafter(1.0, 0.0))

    order = order_rng.permutation(N)
    truth = FrameTruth(
        rotation=rotation,
        translation=translation,
        inlier=inlier[order],
        outlier_kind=kind[order],
        pose_prev=np.array(pose_prev, dtype=float),
        pose_curr=np.array(pose_curr, dtype=float),
        outlier_ratio=float(epsilon),
    )
    return Frame(
        index=int(index),
        prev=prev[order],
        curr=curr[order],
        scores=scores[order],
        camera=cam,
        noise_sigma=config.noise_sigma,
        truth=truth,
    )


# --------------------------------------------------------------------------- public entry points


def simulate_frame(config: SimulationConfig, rng: np.random.Generator | int | None = None) -> Frame:
    """A standalone frame pair: one step of the preset's motion at a random state, a fresh world patch.

    The pose of frame k-1 is random (a random heading and position for ``car``,
    a random orientation for ``free``); frame k follows from one twist drawn
    from the stationary law of the preset's velocity process.

    Args:
        config: the simulation settings.
        rng: a numpy Generator, an int seed, or None for fresh entropy.

    Returns:
        A :class:`Frame` with ``index == 1``.
    """
    rng = np.random.default_rng(rng)
    if config.preset == "car":
        orientation = so3_exp(np.array([0.0, rng.uniform(-np.pi, np.pi), 0.0]))
        position = np.array([rng.uniform(-100, 100), 0.0, rng.uniform(-100, 100)])
    else:
        orientation = random_rotation(rng)
        position = rng.uniform(-100, 100, 3)
    pose_prev = make_transform(orientation, position)
    rotation, translation = se3_exp(-config.motion.sample_twist(rng))
    pose_curr = pose_update(pose_prev, rotation, translation)
    return _simulate_pair(config, pose_prev, pose_curr, 1, rng)


class Sequence:
    """A lazily simulated trajectory of ``config.n_frames`` frame pairs.

    The trajectory (cheap) is drawn in ``__init__``; frame k is generated on
    demand from its own seed, so ``frame(k)`` gives the same result in any
    order of access, and the same seed gives bit-identical frames.

    Attributes:
        config: the simulation settings.
        seed: the seed as given (int, SeedSequence or None).
        true_poses: ``(n_frames + 1, 4, 4)`` read-only camera-to-world poses,
            ``true_poses[0]`` the identity.
    """

    def __init__(self, config: SimulationConfig, seed: int | np.random.SeedSequence | None = None) -> None:
        if not isinstance(config, SimulationConfig):
            raise TypeError(f"config must be a SimulationConfig, got {type(config).__name__}")
        self.config = config
        self.seed = seed
        self._root = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        twists = config.motion.sample_twists(self._child_rng(0), config.n_frames)
        rotations, translations = se3_exp(-twists)
        poses = np.empty((config.n_frames + 1, 4, 4))
        poses[0] = np.eye(4)
        for k in range(config.n_frames):
            poses[k + 1] = pose_update(poses[k], rotations[k], translations[k])
        poses.setflags(write=False)
        self.true_poses = poses

    @property
    def seed_sequence(self) -> np.random.SeedSequence:
        """The root SeedSequence; its entropy reproduces a sequence made with ``seed=None``."""
        return self._root

    def _child_rng(self, k: int) -> np.random.Generator:
        """The generator of ``SeedSequence(root.entropy, spawn_key=(*root.spawn_key, namespace, k))``."""
        root = self._root
        return seeded_generators(root.entropy, [(*root.spawn_key, _SEQUENCE_NAMESPACE, k)], root.pool_size)[0]

    def __len__(self) -> int:
        return self.config.n_frames

    def __iter__(self) -> Iterator[Frame]:
        for k in range(1, self.config.n_frames + 1):
            yield self.frame(k)

    def frame(self, k: int) -> Frame:
        """Frame pair ``(k-1, k)`` for ``1 <= k <= n_frames``.

        Raises:
            IndexError: if k is out of range.
        """
        if not is_integer(k) or not 1 <= k <= self.config.n_frames:
            raise IndexError(f"frame index must be an integer in [1, {self.config.n_frames}], got {k!r}")
        k = int(k)
        rng = self._child_rng(k)
        return _simulate_pair(self.config, self.true_poses[k - 1], self.true_poses[k], k, rng)

    def __repr__(self) -> str:
        return f"Sequence(n_frames={len(self)}, preset={self.config.preset!r}, seed={self.seed!r})"
