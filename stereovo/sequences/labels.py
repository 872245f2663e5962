"""Ground-truth labels of a frame pair's matches from depth maps and the true motion.

A match ``prev <-> curr`` is an inlier when the scene agrees with it: the true depth at its k-1
left pixel gives its disparity at k-1 (within ``disparity_tolerance`` px), the point moved by the
true motion lands on its k left pixel (within ``pixel_tolerance`` px on each axis) with its
disparity at k. Otherwise it is labelled by what went wrong (:class:`~stereovo.simulation.OutlierKind`):

- ``MOVING_OBJECT``: its k-1 pixel lies on a moving object (whatever else holds: its motion is
  not the camera's);
- ``RANDOM_MISMATCH``: the temporal match is wrong (the k position disagrees), or no surface;
- ``STEREO_MISMATCH``: the position agrees but a disparity does not (wrong depth).

Depth at a pixel is the depth map's value at the nearest pixel or one of its 8 neighbours,
whichever explains the measured disparity best: a keypoint on a depth edge is measured on one
side of it, and the labels should not call it wrong for that.
"""

from __future__ import annotations

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.simulation import OutlierKind

PIXEL_TOLERANCE = 2.0
"""Largest position error (px, per axis) of an inlier's left pixel at k."""

DISPARITY_TOLERANCE = 1.0
"""Largest disparity error (px) of an inlier at k-1 and at k."""

_OFFSETS = np.array([(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)])


def _best_depth(depth: np.ndarray, ids: np.ndarray, u: np.ndarray, v: np.ndarray, disparity: np.ndarray,
                fb: float) -> tuple[np.ndarray, np.ndarray]:
    """Per match, the 3x3-neighbourhood depth (m; 0 = no surface) that best explains ``disparity``, and its id."""
    h, w = depth.shape
    x = np.clip(np.rint(u).astype(np.int64), 0, w - 1)
    y = np.clip(np.rint(v).astype(np.int64), 0, h - 1)
    ys = np.clip(y[:, None] + _OFFSETS[None, :, 0], 0, h - 1)
    xs = np.clip(x[:, None] + _OFFSETS[None, :, 1], 0, w - 1)
    z = depth[ys, xs].astype(float)
    with np.errstate(divide="ignore"):
        d = np.where(z > 0, fb / np.where(z > 0, z, 1.0), np.inf)
    pick = np.argmin(np.abs(d - disparity[:, None]), axis=1)
    rows = np.arange(u.size)
    return z[rows, pick], ids[ys[rows, pick], xs[rows, pick]].astype(np.int64)


def label_matches(prev: np.ndarray, curr: np.ndarray, camera: StereoCamera, depth_prev: np.ndarray,
                  ids_prev: np.ndarray, motions: dict[int, tuple[np.ndarray, np.ndarray]],
                  pixel_tolerance: float = PIXEL_TOLERANCE,
                  disparity_tolerance: float = DISPARITY_TOLERANCE) -> tuple[np.ndarray, np.ndarray]:
    """Labels of matches ``prev, curr (N, 4)`` (px).

    Args:
        depth_prev, ids_prev: ``(H, W)`` depth (m, 0 = nothing) and object ids of the k-1 left image.
        motions: ``id -> (R, t)`` taking a point of that object from camera k-1 to camera k
            (``x_k = R x_{k-1} + t``); id 0 is the static world (the camera's motion). Ids
            other than 0 are moving objects.

    Returns:
        ``inlier (N,)`` bool and ``kind (N,)`` int8 :class:`OutlierKind` values.
    """
    n = prev.shape[0]
    fb = camera.fx * camera.baseline
    d_prev = prev[:, 0] - prev[:, 2]
    z, ids = _best_depth(depth_prev, ids_prev, prev[:, 0], prev[:, 1], d_prev, fb)
    surface = z > 0
    z_safe = np.where(surface, z, 1.0)
    X = np.column_stack([(prev[:, 0] - camera.cx) * z_safe / camera.fx, (prev[:, 1] - camera.cy) * z_safe / camera.fy,
                         z_safe])
    moved = np.empty_like(X)
    for object_id in np.unique(ids):
        R, t = motions.get(int(object_id), motions[0])
        rows = ids == object_id
        moved[rows] = X[rows] @ np.asarray(R).T + np.asarray(t)
    ahead = moved[:, 2] > 1e-6
    predicted = camera.project(np.where(ahead[:, None], moved, np.array([0.0, 0.0, 1.0])))
    stereo_prev = surface & (np.abs(d_prev - fb / z_safe) <= disparity_tolerance)
    position = ahead & surface & (np.abs(predicted[:, 0] - curr[:, 0]) <= pixel_tolerance) & (
        np.abs(predicted[:, 1] - curr[:, 1]) <= pixel_tolerance)
    stereo_curr = ahead & (np.abs((curr[:, 0] - curr[:, 2]) - (predicted[:, 0] - predicted[:, 2])) <= disparity_tolerance)
    kind = np.full(n, int(OutlierKind.INLIER), dtype=np.int8)
    kind[~(stereo_prev & stereo_curr)] = int(OutlierKind.STEREO_MISMATCH)
    kind[~position] = int(OutlierKind.RANDOM_MISMATCH)
    kind[ids > 0] = int(OutlierKind.MOVING_OBJECT)
    return kind == int(OutlierKind.INLIER), kind
