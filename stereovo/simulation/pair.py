"""One frame pair from two camera poses: matches, pixel noise, scores and row order.

:func:`simulate_pair` splits the frame's generator into independent streams
(landmarks, outliers, noise, scores, row order), takes inliers from the world
(:mod:`stereovo.simulation.world`) and outliers from :mod:`stereovo.simulation.outliers`,
adds Gaussian pixel noise (one ``v`` draw shared by both images, redrawn where a row
would leave the image), draws the scores and shuffles the rows.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from stereovo.camera import StereoCamera
from stereovo.geometry import invert_transform
from stereovo.seeding import spawned_generators
from stereovo.simulation.config import SimulationConfig
from stereovo.simulation.frame import Frame, FrameTruth, OutlierKind
from stereovo.simulation.hostile import (
    duplicate_matches,
    far_clutter,
    independent_mismatches,
    repetitive_cluster_size,
    repetitive_texture,
    student_t_scale,
)
from stereovo.simulation.outliers import (
    MAX_REDRAWS,
    moving_object,
    outlier_threshold,
    random_mismatches,
    stereo_mismatches,
)
from stereovo.simulation.scores import draw_scores
from stereovo.simulation.world import visible_landmarks

_STREAMS = 5  # landmarks, outliers, noise, scores, row order


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


_KIND_ORDER = np.array([OutlierKind.INLIER, OutlierKind.RANDOM_MISMATCH, OutlierKind.STEREO_MISMATCH,
                        OutlierKind.MOVING_OBJECT, OutlierKind.INDEPENDENT_MISMATCH, OutlierKind.DUPLICATE_MATCH,
                        OutlierKind.FAR_CLUTTER, OutlierKind.REPETITIVE_TEXTURE], dtype=np.int8)


@functools.lru_cache(maxsize=256)
def _row_kinds(counts: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """``(N,)`` int8 and ``(N,)`` bool, read-only: each :class:`OutlierKind`, in the order of
    ``_KIND_ORDER``, repeated its count, and which rows are inliers. Cached as :func:`_apportion` is
    (a sequence asks for the same rows every frame)."""
    kinds = np.repeat(_KIND_ORDER, counts)
    inlier = kinds == OutlierKind.INLIER
    kinds.flags.writeable = inlier.flags.writeable = False
    return kinds, inlier


def _stream_generators(entropy: np.ndarray, n_streams: int) -> list[np.random.Generator]:
    """Generators of ``np.random.SeedSequence(entropy.tolist()).spawn(n_streams)``, ``entropy``
    four non-negative int64 draws (numpy's seeding, computed by :mod:`stereovo.seeding`)."""
    return spawned_generators(entropy, n_streams)


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
def _noisy_rows(meas, z, sigma, out):
    """``out (N, 4) = meas + sigma * z[:, (0, 1, 2, 1)]``: the ``v`` noise shared by both images.
    (``out`` comes from numpy: see :func:`stereovo.camera._project_rows`.)"""
    n = meas.shape[0]
    for i in range(n):
        out[i, 0] = meas[i, 0] + sigma * z[i, 0]
        out[i, 1] = meas[i, 1] + sigma * z[i, 1]
        out[i, 2] = meas[i, 2] + sigma * z[i, 2]
        out[i, 3] = meas[i, 3] + sigma * z[i, 1]


@njit(cache=True, nogil=True)
def _noisy_invalid_rows(meas, z, sigma, out, u_max, v_max, min_disparity):
    """:func:`_noisy_rows` into ``out``, then the rows of ``out`` that :func:`_valid_rows` refuses
    (int64, ascending: ``np.flatnonzero(~_valid_rows(out, ...))``), in one call."""
    _noisy_rows(meas, z, sigma, out)
    ok = _valid_rows(out, u_max, v_max, min_disparity)
    bad = np.empty(out.shape[0], dtype=np.int64)
    n_bad = 0
    for i in range(out.shape[0]):
        if not ok[i]:
            bad[n_bad] = i
            n_bad += 1
    return bad[:n_bad]


def _add_noise(
    meas: np.ndarray, normal: np.ndarray, config: SimulationConfig, rng: np.random.Generator, free: int = 0
) -> np.ndarray:
    """Noisy copies of valid noise-free measurements ``(N, 4)``.

    ``normal`` ``(N, 3)`` are standard-normal (or Student-t) draws for ``(uL, v, uR)``; the
    ``v`` draw is shared by both images (rectified pair). Rows that leave the
    image or lose their disparity are redrawn (a truncated Gaussian), so every
    measurement stays usable, except the last ``free`` rows (the hostile kinds), which keep
    their first draw: losing the depth is what they are for. A row still outside after
    ``MAX_REDRAWS`` redraws (noise of tens of pixels) keeps its noise-free measurement; a stereo
    mismatch whose noise-free right point lies left of the image (its disparity floor beyond the
    image) has that point moved to the image's left edge, and any other noise-free row the image
    cannot hold takes the widest disparity (``uL = width - 1``, ``uR = 0``). Rows that a draw
    brought into the image keep that draw (frames as they always were).
    """
    sigma, cam = float(config.noise_sigma), config.camera
    limits = (float(cam.width - 1), float(cam.height - 1), float(cam.min_disparity))

    def noisy(rows: np.ndarray, z: np.ndarray) -> np.ndarray:
        out = np.empty((rows.shape[0], 4))
        _noisy_rows(np.ascontiguousarray(rows, dtype=float), np.ascontiguousarray(z, dtype=float), sigma, out)
        return out

    if free:
        out = noisy(meas, normal)
        if free < len(meas):
            out[:-free] = _add_noise(meas[:-free], normal[:-free], config, rng)
        return out
    meas = np.ascontiguousarray(meas, dtype=float)
    out = np.empty((meas.shape[0], 4))
    # the first draw and its check in one compiled call (the common case: no row to redraw)
    bad = _noisy_invalid_rows(meas, np.ascontiguousarray(normal, dtype=float), sigma, out, *limits)
    for _ in range(MAX_REDRAWS):
        if bad.size == 0:
            return out
        out[bad] = noisy(meas[bad], rng.standard_normal((bad.size, 3)))
        bad = np.flatnonzero(~_valid(out, cam))
    if bad.size == 0:
        return out
    bad = ~_valid(out, cam)
    clean = meas[bad]
    lost = ~_valid(clean, cam)
    if lost.any():
        # A stereo mismatch whose disparity floor (min_disparity + 3 sigma) exceeds its uL, with no
        # room to move up either (outliers._move_right_points' last resort): its noise-free right
        # point lies left of the image. Noise often brings it back in (those frames keep that draw);
        # when no draw did, the row takes the largest disparity the image holds (uR = 0, disparity
        # uL > min_disparity, as the true match's) instead of leaving the image.
        clean[lost, 2] = np.maximum(clean[lost, 2], 0.0)
        # Any other row the image cannot hold (none is known: a random stereo point of a camera whose
        # min_disparity is near its width could be one) takes the widest disparity of the image,
        # width - 1 px (above min_disparity: SimulationConfig refuses a camera where it is not).
        other = ~_valid(clean, cam)
        if other.any():
            clean[other, 0], clean[other, 2] = float(cam.width - 1), 0.0
            clean[other, 1] = clean[other, 3] = np.clip(clean[other, 1], 0.0, float(cam.height - 1))
    out[bad] = clean  # vanishingly rare: keep the valid noise-free row
    return out


def _shuffled_rows(order: np.ndarray, prev: np.ndarray, curr: np.ndarray, scores: np.ndarray, inlier: np.ndarray,
                   kind: np.ndarray) -> tuple[np.ndarray, ...]:
    """``prev[order], curr[order], scores[order], inlier[order], kind[order]`` in one compiled pass
    (the values are copied, so they are numpy's; the arrays come from numpy: see
    :func:`stereovo.camera._project_rows`)."""
    n = order.shape[0]
    out = (np.empty((n, 4)), np.empty((n, 4)), np.empty(n), np.empty(n, dtype=bool), np.empty(n, dtype=np.int8))
    if prev.dtype == np.float64 and curr.dtype == np.float64 and scores.dtype == np.float64 \
            and inlier.dtype == np.bool_ and kind.dtype == np.int8 and prev.shape == curr.shape == (n, 4):
        _gather_rows(order, np.ascontiguousarray(prev), np.ascontiguousarray(curr), scores, inlier, kind, *out)
        return out
    return prev[order], curr[order], scores[order], inlier[order], kind[order]


@njit(cache=True, nogil=True)
def _gather_rows(order, prev, curr, scores, inlier, kind, prev_out, curr_out, scores_out, inlier_out, kind_out):
    for i in range(order.shape[0]):
        j = order[i]
        for c in range(4):
            prev_out[i, c] = prev[j, c]
            curr_out[i, c] = curr[j, c]
        scores_out[i] = scores[j]
        inlier_out[i] = inlier[j]
        kind_out[i] = kind[j]


def simulate_pair(
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
    counts = _apportion(n_out, config.outlier_mix)
    n_random, n_stereo, n_moving = counts[:3]
    n_indep, n_dup, n_far, n_rep = (tuple(counts[3:]) + (0, 0, 0, 0))[:4]
    if n_dup and n_in < 2:  # a duplicate needs two inliers to copy: those rows become random mismatches
        n_random, n_dup = n_random + n_dup, 0

    # World-to-camera @ camera-k-1-to-world: how cameras k-1 and k see points given in camera k-1's
    # frame. The second is the relative motion itself (geometry.relative_motion's product).
    to_prev = invert_transform(pose_prev) @ pose_prev
    to_curr = invert_transform(pose_curr) @ pose_prev
    rotation, translation = to_curr[:3, :3].copy(), to_curr[:3, 3].copy()

    # Two spare landmarks guarantee that a random mismatch always has another landmark to borrow.
    # The hostile kinds that start from a landmark take theirs after those (none by default).
    n_pool = n_in + n_random + n_stereo
    n_landmarks = n_pool + n_indep + n_rep
    X_prev, X_curr = visible_landmarks(n_landmarks + 2, config, to_prev, to_curr, landmark_rng)
    if n_landmarks > n_pool:  # the two spares stay at rows n_pool, n_pool + 1, as by default
        X_prev = np.concatenate([X_prev[:n_pool], X_prev[n_landmarks:], X_prev[n_pool:n_landmarks]])
        X_curr = np.concatenate([X_curr[:n_pool], X_curr[n_landmarks:], X_curr[n_pool:n_landmarks]])
    meas_prev, meas_curr = cam.project(X_prev), cam.project(X_curr)
    O_prev, O_curr = moving_object(n_moving, config, to_prev, to_curr, outlier_rng)

    random_rows = np.arange(n_in, n_in + n_random)
    stereo_rows = np.arange(n_in + n_random, n_pool)
    parts_prev = [meas_prev[:n_pool], cam.project(O_prev).reshape(-1, 4)]
    parts_curr = [
        meas_curr[:n_in],
        random_mismatches(random_rows, meas_curr, config, outlier_rng),
        stereo_mismatches(meas_curr[stereo_rows], config, outlier_rng),
        cam.project(O_curr).reshape(-1, 4),
    ]
    # The hostile rows come last and are "free" (not redrawn to keep a depth); duplicates are copied
    # from the inlier rows after the noise, so they hold a placeholder until then.
    n_free = n_indep + n_dup + n_far + n_rep
    if n_free:
        tau = outlier_threshold(config.noise_sigma)
        indep = slice(n_pool + 2, n_pool + 2 + n_indep)
        rep = slice(n_pool + 2 + n_indep, n_landmarks + 2)
        far_prev, far_curr = far_clutter(n_far, cam, rotation, translation, tau, outlier_rng)
        rep_prev, rep_curr = repetitive_texture(
            X_prev[rep], meas_curr[rep], repetitive_cluster_size(n_in), cam, rotation, translation, tau, outlier_rng
        )
        parts_prev += [meas_prev[indep], np.zeros((n_dup, 4)), far_prev, rep_prev]
        parts_curr += [
            independent_mismatches(meas_curr[indep], cam, tau, outlier_rng), np.zeros((n_dup, 4)), far_curr, rep_curr,
        ]
    clean_prev, clean_curr = np.concatenate(parts_prev), np.concatenate(parts_curr)
    kind, inlier = _row_kinds((n_in, n_random, n_stereo, n_moving, n_indep, n_dup, n_far, n_rep))
    assert clean_prev.shape == clean_curr.shape == (N, 4)

    # One (2, N, 3) draw in row order, so the same seed gives the same standard-normal noise at any sigma.
    normal = noise_rng.standard_normal((2, N, 3))
    if config.noise_dof is not None:
        normal = normal * student_t_scale(config.noise_dof, normal.shape, noise_rng)
    prev = _add_noise(clean_prev, normal[0], config, noise_rng, free=n_free)
    curr = _add_noise(clean_curr, normal[1], config, noise_rng, free=n_free)
    if n_dup:
        dup = slice(N - n_far - n_rep - n_dup, N - n_far - n_rep)
        prev[dup], curr[dup] = duplicate_matches(
            prev[:n_in], curr[:n_in], clean_curr[:n_in], n_dup, outlier_threshold(config.noise_sigma), outlier_rng
        )

    scores = draw_scores(inlier, config.score_auc, score_rng)

    order = order_rng.permutation(N)
    rows = _shuffled_rows(order, prev, curr, scores, inlier, kind)
    truth = FrameTruth(
        rotation=rotation,
        translation=translation,
        inlier=rows[3],
        outlier_kind=rows[4],
        pose_prev=np.array(pose_prev, dtype=float),
        pose_curr=np.array(pose_curr, dtype=float),
        outlier_ratio=float(epsilon),
    )
    return Frame(
        index=int(index),
        prev=rows[0],
        curr=rows[1],
        scores=rows[2],
        camera=cam,
        noise_sigma=config.noise_sigma,
        score_auc=config.score_auc,
        truth=truth,
    )
