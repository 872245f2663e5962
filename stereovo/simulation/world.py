"""The world of one frame pair: landmarks seen by both stereo cameras, drawn afresh per pair.

A street (rough ground, two facades of random height, clutter) or an open volume,
drawn in camera k-1's frame in a frustum a little wider than the view, depths
log-uniform in ``[z_min, z_max]``; a landmark is kept when both stereo pairs see it
(:func:`visible_landmarks`). Compiled kernels draw and test the candidates in one
pass. Also the small sampling helpers the outliers share (:func:`loguniform`,
:func:`see_point`, ...).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from stereovo.camera import StereoCamera
from stereovo.simulation.config import InfeasibleSettingsError, SimulationConfig

CAMERA_HEIGHT = 1.65  # m above the ground (KITTI rig)
_FRUSTUM_SLACK = 1.15  # landmarks are drawn in a frustum this much wider, so frame k's view is covered
_STREET_PARTS = (0.35, 0.45, 0.20)  # ground, facades, clutter (fractions of drawn candidates)
_ACCEPTANCE_GUESS = {"street": 0.45, "open": 0.4}  # sizes the first oversampling batch
_MAX_BATCHES = 8
_MAX_BATCH_SIZE = 2_000_000


def loguniform(rng: np.random.Generator, low: float, high: float, size: int) -> np.ndarray:
    """``size`` draws log-uniform in ``[low, high]`` (the depths of landmarks and random stereo points)."""
    return low * np.exp(rng.random(size) * math.log(high / low))


def _frustum(cam: StereoCamera) -> tuple[float, float, float, float]:
    """Tangent bounds ``(left, right, top, bottom)`` of the left camera's view, widened by the slack."""
    s = _FRUSTUM_SLACK
    return (-s * cam.cx / cam.fx, s * (cam.width - 1 - cam.cx) / cam.fx,
            -s * cam.cy / cam.fy, s * (cam.height - 1 - cam.cy) / cam.fy)


@njit(cache=True, nogil=True)
def see_point(p0, p1, p2, to_prev, to_curr, cam, z_min, z_max, X_prev, X_curr, i):
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
def _seen_by_both(points, to_prev, to_curr, cam, z_min, z_max, limit):
    """The points ``(n, 3)`` visible in both cameras (see :func:`see_point`), mapped by the rigid
    transforms ``to_prev``, ``to_curr`` (4x4) into cameras k-1 and k: ``X_prev, X_curr (m, 3)``,
    in their order; at most the first ``limit`` of them (the caller keeps no more: the candidates
    after them were drawn, and are not looked at)."""
    n = points.shape[0]
    X_prev = np.empty((n, 3))
    X_curr = np.empty((n, 3))
    kept = 0
    for i in range(n):
        if kept >= limit:
            break
        kept += see_point(points[i, 0], points[i, 1], points[i, 2], to_prev, to_curr, cam, z_min, z_max, X_prev, X_curr, kept)
    return X_prev[:kept], X_curr[:kept]


@njit(cache=True, nogil=True)
def _street_candidates(u, g, walls, frustum, z_min, z_max, to_prev, to_curr, cam, limit):
    """Street landmarks from uniforms ``u (7, n)`` and normals ``g (2, n)``, seen through the
    cameras: ``X_prev, X_curr (m, 3)`` of the candidates drawn and visible in both, in their order,
    at most the first ``limit`` (as :func:`_seen_by_both`).

    ``walls`` is ``(left, right, height_left, height_right)`` (m), ``frustum`` the tangent bounds
    ``(left, right, top, bottom)``. A candidate is on the ground, a facade or clutter with the
    odds of ``_STREET_PARTS``; its depth is log-uniform in ``[z_min, z_max]``. Rows of ``u``:
    depth, part, ground x, facade side, facade height, clutter x, clutter height; of ``g``:
    ground roughness, facade relief.
    """
    n = u.shape[1]
    h = CAMERA_HEIGHT
    left_wall, right_wall, height_left, height_right = walls[0], walls[1], walls[2], walls[3]
    log_range = math.log(z_max / z_min)
    ground_end = _STREET_PARTS[0]
    facade_end = _STREET_PARTS[0] + _STREET_PARTS[1]
    total = _STREET_PARTS[0] + _STREET_PARTS[1] + _STREET_PARTS[2]
    X_prev = np.empty((n, 3))
    X_curr = np.empty((n, 3))
    kept = 0  # rows written so far: a candidate is written at row `kept` and kept if it counts
    for i in range(n):
        if kept >= limit:
            break
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
        seen = see_point(x, y, z, to_prev, to_curr, cam, z_min, z_max, X_prev, X_curr, kept)
        if drawn and seen:
            kept += 1
    return X_prev[:kept], X_curr[:kept]


def camera_vector(cam: StereoCamera) -> np.ndarray:
    """The rig as the compiled visibility test takes it (see :func:`see_point`); read-only, one per camera."""
    return _camera_arrays(cam)[0]


def _frustum_vector(cam: StereoCamera) -> np.ndarray:
    """:func:`_frustum` as an array (the street kernel's argument); read-only, one per camera."""
    return _camera_arrays(cam)[1]


_CAMERA_ARRAYS: dict[int, tuple[StereoCamera, np.ndarray, np.ndarray]] = {}


def _camera_arrays(cam: StereoCamera) -> tuple[np.ndarray, np.ndarray]:
    """The camera's vector and frustum, built once per camera (a frame asks for them three times;
    the camera is frozen): by identity, the camera kept so that its id is not reused."""
    entry = _CAMERA_ARRAYS.get(id(cam))
    if entry is None or entry[0] is not cam:
        vector = np.array([cam.fx, cam.fy, cam.cx, cam.cy, cam.baseline, cam.width, cam.height, cam.min_disparity])
        frustum = np.array(_frustum(cam))
        vector.flags.writeable = frustum.flags.writeable = False
        if len(_CAMERA_ARRAYS) >= 32:
            _CAMERA_ARRAYS.clear()
        entry = _CAMERA_ARRAYS[id(cam)] = (cam, vector, frustum)
    return entry[1], entry[2]


class _StreetLayout:
    """One frame's street, in the frame of camera k-1: facades at ``x = -left, +right``."""

    def __init__(self, rng: np.random.Generator) -> None:
        # (left, right, height_left, height_right): the two draws end to end
        self.walls = np.concatenate((rng.uniform(4.0, 10.0, 2), rng.uniform(6.0, 20.0, 2)))

    def sample_visible(
        self, rng: np.random.Generator, n: int, cam: StereoCamera, z_min: float, z_max: float,
        to_prev: np.ndarray, to_curr: np.ndarray, limit: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Of ``n`` candidates, those drawn and visible in both cameras, seen through the 4x4
        ``to_prev``, ``to_curr``: ``X_prev, X_curr (m, 3)`` (m; see :func:`_street_candidates`), at
        most the first ``limit`` (None: all); all ``n`` are drawn either way."""
        u = rng.random((7, n))
        g = rng.standard_normal((2, n))
        return _street_candidates(
            u, g, self.walls, _frustum_vector(cam), z_min, z_max, to_prev, to_curr, camera_vector(cam),
            n if limit is None else limit,
        )


def _sample_open(rng: np.random.Generator, n: int, cam: StereoCamera, z_min: float, z_max: float) -> np.ndarray:
    """Candidate landmarks ``(n, 3)`` uniform in image direction and log-uniform in depth."""
    left, right, top, bottom = _frustum(cam)
    z = loguniform(rng, z_min, z_max, n)
    x = z * rng.uniform(left, right, n)
    y = z * rng.uniform(top, bottom, n)
    return np.stack([x, y, z], axis=1)


def visible_landmarks(
    n: int, config: SimulationConfig, to_prev: np.ndarray, to_curr: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` landmarks seen by both stereo pairs: their camera-frame points ``(n, 3)`` at k-1 and k.

    Landmarks live in world coordinates, drawn in camera k-1's frame; the 4x4 ``to_prev``,
    ``to_curr`` (world-to-camera @ camera-k-1-to-world) take them to the two cameras.

    Raises:
        InfeasibleSettingsError: fewer than ``n`` were found in ``_MAX_BATCHES`` batches (a very
            thin depth range, a step longer than the depth range, a small or off-centre image);
            the message names the settings.
    """
    cam, world = config.camera, config.resolved_world
    layout = _StreetLayout(rng) if world == "street" else None
    acceptance = _ACCEPTANCE_GUESS[world]
    cam_vector = camera_vector(cam)
    kept_prev, kept_curr, count = [], [], 0
    for _ in range(_MAX_BATCHES):
        if count >= n:
            break
        batch = min(_MAX_BATCH_SIZE, int(1.3 * (n - count) / acceptance) + 32)
        # Only the first n - count visible candidates are kept: the kernels stop there (a batch is
        # oversampled by 1.3 / acceptance, so that skips about a third of the tests). The whole
        # batch is drawn all the same, and a batch that stops early ends the loop, so the
        # acceptance it would have measured is never read.
        if layout is not None:
            X_prev, X_curr = layout.sample_visible(rng, batch, cam, config.z_min, config.z_max, to_prev, to_curr,
                                                   limit=n - count)
        else:
            local = _sample_open(rng, batch, cam, config.z_min, config.z_max)
            X_prev, X_curr = _seen_by_both(local, to_prev, to_curr, cam_vector, config.z_min, config.z_max, n - count)
        kept_prev.append(X_prev)
        kept_curr.append(X_curr)
        count += len(X_prev)
        acceptance = max(len(X_prev) / batch, 1e-3)
    if count < n:
        motion = config.motion
        raise InfeasibleSettingsError(
            f"z_min={config.z_min!r} m, z_max={config.z_max!r} m, speed={motion.speed!r} m/frame "
            f"(preset {config.preset!r}), camera {cam.width}x{cam.height} px (cx={float(cam.cx)!r}, cy={float(cam.cy)!r}, "
            f"min_disparity={float(cam.min_disparity)!r} px): found only {count} of {n} landmarks visible in both frames "
            f"of the {world!r} world; widen the depth range, lower the speed, or use a camera that sees more"
        )
    if len(kept_prev) == 1:  # the common case: the first batch held them all
        return kept_prev[0][:n], kept_curr[0][:n]
    return np.concatenate(kept_prev)[:n], np.concatenate(kept_curr)[:n]
