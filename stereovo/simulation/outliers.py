"""Outliers of a frame pair: random mismatches, stereo mismatches and one moving object.

Every outlier is detectable: its noise-free frame-k measurement lies at least
``max(4 px, 8 sigma)`` (norm over ``uL, v, uR``) from where the true motion would put
it (:func:`outlier_threshold`); draws that land nearer are redrawn. Stereo
mismatches also carry a depth error of at least 20 %.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from stereovo.geometry import random_rotation
from stereovo.simulation.config import MIN_OUTLIER_PX, OUTLIER_SIGMAS, InfeasibleSettingsError, SimulationConfig
from stereovo.simulation.world import CAMERA_HEIGHT, camera_vector, loguniform, see_point

MAX_REDRAWS = 30  # redraws of a row that misses its condition (an outlier too near, a noisy row off the image)
_MAX_OBJECT_ATTEMPTS = 30
_STEREO_FACTOR = (1.25, 2.5)
_MAX_SPIN = float(np.radians(3.0))  # rad/frame, the object's largest turn  # range of the disparity ratio of a stereo mismatch (>= 20 % depth error)


def outlier_threshold(sigma: float) -> float:
    """Minimum pixel distance (px) between an outlier and where the true motion puts it."""
    return max(MIN_OUTLIER_PX, OUTLIER_SIGMAS * sigma)


def _rotation_about_y(angle: float) -> np.ndarray:
    """``so3_exp((0, angle, 0))`` in closed form (a heading change on the street)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@njit(cache=True, nogil=True)
def _object_candidates(u, half, face_cdf, orientation, centre, to_prev, to_curr_moved, to_curr_static, cam, z_min, z_max,
                       tau, limit):
    """Points on the faces of a box, from uniforms ``u (n, 5)``, that both cameras see on a face
    turned towards camera k-1 and whose frame-k image lies at least ``tau`` px (over uL, v, uR)
    from where a static point would be (or that would be behind camera k if static): their
    ``X_prev, X_curr (m, 3)`` in the cameras, in their order, at most the first ``limit`` (the
    caller keeps no more; the candidates after them are not looked at).

    Columns of ``u``: the position along the three box axes, the face (area-weighted through
    ``face_cdf``), its side. ``half (3,)`` are the box's half sizes, ``orientation (3, 3)`` and
    ``centre (3,)`` its pose in camera k-1; ``to_curr_moved`` sees the box after its own motion.
    """
    n = u.shape[0]
    fx, fy, b = cam[0], cam[1], cam[4]
    X_prev = np.empty((n, 3))
    X_curr = np.empty((n, 3))
    kept = 0  # as in world._street_candidates: a candidate is written at row `kept`, kept if it counts
    local = np.empty(3)
    p = np.empty(3)
    for i in range(n):
        if kept >= limit:
            break
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
        seen = see_point(p[0], p[1], p[2], to_prev, to_curr_moved, cam, z_min, z_max, X_prev, X_curr, kept)
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


def random_mismatches(
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
    tau = outlier_threshold(config.noise_sigma)
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    meas_curr = np.ascontiguousarray(meas_curr, dtype=float)
    for _ in range(MAX_REDRAWS):
        if todo.size == 0:
            break
        m = todo.size
        other = rng.random(m)
        shift = rng.integers(1, pool, size=m)
        depth = loguniform(rng, config.z_min, config.z_max, m)
        u, v = rng.random(m), rng.random(m)
        todo = _place_mismatches(
            todo, rows, other, shift, depth, u, v, meas_curr, fake, cam.fx * cam.baseline,
            cam.min_disparity * 1.5, 0.9 * (cam.width - 1), float(cam.width - 1), float(cam.height - 1), tau,
        )
    return fake


def stereo_mismatches(meas: np.ndarray, config: SimulationConfig, rng: np.random.Generator) -> np.ndarray:
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
    _move_right_points(out, factor, want_up, outlier_threshold(config.noise_sigma), floor)
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


def moving_object(
    n: int, config: SimulationConfig, to_prev: np.ndarray, to_curr_static: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame points ``(n, 3)`` at k-1 and k of one rigid box moving on its own.

    A car on the street (on the ground, driving along its heading at 0.5-2
    m/frame, turning up to 3 deg/frame) or a box anywhere in the open world,
    5-25 m ahead. Only faces turned towards camera k-1 carry points, and only
    points whose frame-k image lies at least the outlier threshold away from
    where a static point would be are kept: the object's motion must show.

    Raises:
        InfeasibleSettingsError: no such object was found in ``_MAX_OBJECT_ATTEMPTS`` tries (an
            outlier threshold of some hundred pixels, ``noise_sigma`` >= 50 at the default rig, or
            a depth range or image that holds no such object); the message names the settings.
    """
    if n == 0:
        return np.empty((0, 3)), np.empty((0, 3))
    cam = config.camera
    cam_vector = camera_vector(cam)
    tau = outlier_threshold(config.noise_sigma)
    street = config.resolved_world == "street"
    z_lo, z_hi = max(5.0, config.z_min + 2.0), min(25.0, config.z_max - 2.0)
    if z_lo > z_hi:
        z_lo = z_hi = 0.5 * (config.z_min + config.z_max)
    # The arithmetic below is the numpy formulation's, element by element in the same order, on
    # Python floats where that saves numpy's per-call cost on 3-vectors (frames bit for bit); the
    # products of matrices stay numpy's.
    for _ in range(_MAX_OBJECT_ATTEMPTS):
        depth = rng.uniform(z_lo, z_hi)
        centre_x = (rng.uniform(0.25, 0.75) * (cam.width - 1) - cam.cx) / cam.fx * depth
        centre_y = (rng.uniform(0.25, 0.75) * (cam.height - 1) - cam.cy) / cam.fy * depth  # drawn in both worlds
        if street:
            half = (0.5 * rng.uniform(1.6, 2.0), 0.5 * rng.uniform(1.4, 1.8), 0.5 * rng.uniform(3.5, 5.0))
            centre = np.array([centre_x, CAMERA_HEIGHT - half[1], depth])
            heading = rng.uniform(-np.pi, np.pi)
            orientation = _rotation_about_y(heading)
            # a random sign, drawn as Generator.choice([-1.0, 1.0]) draws it, without its overhead
            speed = rng.uniform(0.5, 2.0)
            sign = (-1.0, 1.0)[int(rng.integers(0, 2))]
            # orientation[:, 2] * speed * sign, element by element (the middle one is 0.0 or -0.0)
            velocity = np.array([orientation[0, 2] * speed * sign, orientation[1, 2] * speed * sign,
                                 orientation[2, 2] * speed * sign])
            spin = _rotation_about_y(rng.uniform(-1, 1) * _MAX_SPIN)
        else:
            centre = np.array([centre_x, centre_y, depth])
            half = tuple(0.5 * rng.uniform(0.8, 3.0, 3))
            orientation = random_rotation(rng)
            direction = rng.standard_normal(3)
            velocity = direction / np.linalg.norm(direction) * rng.uniform(0.5, 2.0)
            spin = random_rotation(rng, _MAX_SPIN)
        # Object motion in camera k-1 coordinates: rotate about its centre, then translate
        # (centre - spin @ centre + velocity, element by element; the product stays numpy's).
        (c0, c1, c2), (r0, r1, r2), (v0, v1, v2) = centre.tolist(), (spin @ centre).tolist(), velocity.tolist()
        # np.cumsum of the face areas, normalised by its last entry
        areas = (half[1] * half[2], half[0] * half[2], half[0] * half[1])
        total = areas[0] + areas[1] + areas[2]
        face_cdf = np.array([areas[0] / total, (areas[0] + areas[1]) / total, total / total])
        # Object points live in camera k-1 coordinates; at k the object has moved by obj first.
        (s00, s01, s02), (s10, s11, s12), (s20, s21, s22) = spin.tolist()
        obj = np.array([[s00, s01, s02, (c0 - r0) + v0], [s10, s11, s12, (c1 - r1) + v1],
                        [s20, s21, s22, (c2 - r2) + v2], [0.0, 0.0, 0.0, 1.0]])
        to_curr_moved = to_curr_static @ obj
        half = np.array(half)

        def draw(size: int, limit: int) -> tuple[np.ndarray, np.ndarray]:
            return _object_candidates(
                rng.random((size, 5)), half, face_cdf, orientation, centre, to_prev, to_curr_moved,
                to_curr_static, cam_vector, config.z_min, config.z_max, tau, limit,
            )

        probe = max(64, 2 * n)
        # The probe stops at max(n, 2) kept points: enough (a second draw follows only when fewer),
        # and at least 2 of the probe's >= 64 points pass the acceptance check below as the full
        # count would (every probe is drawn whole either way).
        X_prev, X_curr = draw(probe, max(n, 2))
        acceptance = len(X_prev) / probe
        if acceptance < 0.02:
            continue  # mostly hidden or barely moving: try another object
        kept_prev, kept_curr, count = [X_prev], [X_curr], len(X_prev)
        while count < n:
            X_prev, X_curr = draw(int(1.3 * (n - count) / acceptance) + 32, n - count)
            kept_prev.append(X_prev)
            kept_curr.append(X_curr)
            count += len(X_prev)
        if len(kept_prev) == 1:
            return X_prev[:n], X_curr[:n]
        return np.concatenate(kept_prev)[:n], np.concatenate(kept_curr)[:n]
    raise InfeasibleSettingsError(
        f"noise_sigma={config.noise_sigma!r} px, z_min={config.z_min!r} m, z_max={config.z_max!r} m, camera "
        f"{cam.width}x{cam.height} px: could not place a visibly moving object with {n} points in "
        f"{_MAX_OBJECT_ATTEMPTS} attempts (its motion must show by the outlier threshold max(4, 8*noise_sigma) = "
        f"{tau:g} px); lower noise_sigma, widen the depth range or the image, or give the moving-object kind no "
        f"weight in outlier_mix"
    )
