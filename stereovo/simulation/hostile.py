"""Match errors of real front ends that the default mix never makes: the hostile kinds.

The default outliers (:mod:`stereovo.simulation.outliers`) all keep a resolvable depth in both
frames. Real matchers also emit rows that break that assumption, and a robust estimator must
neither be fooled by them nor crash on them. Each kind below is one such error; its rows are
*free*: they are not redrawn when noise leaves them without depth (zero or negative disparity),
because producing exactly such rows is the point.

- :func:`independent_mismatches` (``"independent"``): the left and right pixels at k are moved
  independently by a few pixels, as when the temporal matcher picks a wrong neighbour in each
  image; the disparity at k can be near zero or negative.
- :func:`duplicate_matches` (``"duplicate"``): one frame k-1 point matched twice, the second
  time to another landmark's frame-k pixels (identical pixels, copied after noise: a front end
  without a mutual check reports the same keypoints twice).
- :func:`far_clutter` (``"far"``): sky-like points at very large depth (disparity 0.05-1 px)
  whose frame-k image drifts by at least the outlier threshold from the static point's (clouds,
  reflections): their triangulation covariance spans kilometres.
- :func:`repetitive_texture` (``"repetitive"``): clusters of wrong matches that are mutually
  consistent, as a periodic facade matched one period over: each cluster has a wrong depth at
  k-1 and moves exactly by a wrong rigid motion (the true one shifted laterally by one texture
  period). A cluster holds at most a third of the frame's inliers, so the true motion keeps the
  largest consensus (otherwise the "outliers" would be the scene).

Heavy-tailed inlier noise (Student-t) is :func:`student_t_scale`, applied by
:mod:`stereovo.simulation.pair` to the noise draws of every row.

Every row here is a detectable outlier as the default kinds are: its noise-free frame-k
measurement lies at least the outlier threshold ``max(4 px, 8 sigma)`` (over ``uL, v, uR``)
from where the true motion puts its frame-k-1 point.
"""

from __future__ import annotations

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.simulation.outliers import MAX_REDRAWS

_INDEPENDENT_SPREAD = 2.0  # independent moves are uniform in +-2 tau per coordinate (uL, uR), +-tau/2 in v
_FAR_DISPARITY_PX = (0.05, 1.0)  # far clutter's disparity range at k-1 (px)
_FAR_DRIFT = (1.0, 3.0)  # its drift at k, in outlier thresholds
_REPETITIVE_PERIOD = (2.0, 4.0)  # the texture period, in outlier thresholds
_REPETITIVE_DEPTH_FACTOR = (1.3, 2.0)  # the wrong depth at k-1 is the true one times or over this


def _in_image(meas: np.ndarray, cam: StereoCamera) -> np.ndarray:
    """``meas (n, 4)`` with every pixel clipped into the image (a front end reports no other)."""
    out = np.array(meas, dtype=float)
    out[:, 0::2] = np.clip(out[:, 0::2], 0.0, cam.width - 1.0)
    out[:, 1::2] = np.clip(out[:, 1::2], 0.0, cam.height - 1.0)
    return out


def _far_from(fake: np.ndarray, true: np.ndarray, tau: float) -> np.ndarray:
    """``(n,)`` bool: the fake frame-k rows lie at least ``tau`` px (over uL, v, uR) from the true ones."""
    d = fake[:, :3] - true[:, :3]
    return np.sqrt(np.sum(d * d, axis=1)) >= tau


def independent_mismatches(
    true_curr: np.ndarray, cam: StereoCamera, tau: float, rng: np.random.Generator
) -> np.ndarray:
    """Frame-k rows ``(n, 4)``: the true ones ``true_curr (n, 4)`` with ``uL`` and ``uR`` moved
    independently (uniform in +-2 tau px each) and ``v`` by up to tau/2 px (both images alike,
    rectified), clipped into the image; moves that stay within ``tau`` px are redrawn."""
    n = true_curr.shape[0]
    out = np.empty((n, 4))
    todo = np.arange(n)
    for _ in range(MAX_REDRAWS):
        if todo.size == 0:
            break
        move = rng.uniform(-1.0, 1.0, (todo.size, 3)) * tau * np.array([_INDEPENDENT_SPREAD, 0.5, _INDEPENDENT_SPREAD])
        fake = true_curr[todo].copy()
        fake[:, 0] += move[:, 0]
        fake[:, 1] += move[:, 1]
        fake[:, 2] += move[:, 2]
        fake[:, 3] = fake[:, 1]
        fake = _in_image(fake, cam)
        out[todo] = fake
        todo = todo[~_far_from(fake, true_curr[todo], tau)]
    if todo.size:  # vanishingly rare (a point pinned in an image corner): move it across the image
        out[todo, 0] = np.where(true_curr[todo, 0] < cam.width / 2, cam.width - 1.0, 0.0)
        out[todo, 2] = out[todo, 0]
    return out


def duplicate_matches(
    noisy_prev: np.ndarray, noisy_curr: np.ndarray, true_curr: np.ndarray, n: int, tau: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` rows that match an inlier's frame k-1 pixels again, to another inlier's frame-k pixels.

    ``noisy_prev, noisy_curr (m, 4)``: the inlier rows after noise; ``true_curr (m, 4)``: their
    noise-free frame-k pixels (for the detectability check). Returns ``(prev, curr)``, each
    ``(n, 4)``, copied from those rows. Needs ``m >= 2``; pairs whose frame-k pixels lie within
    ``tau`` px of each other are redrawn.
    """
    m = noisy_prev.shape[0]
    src = rng.integers(0, m, n)
    dst = (src + rng.integers(1, m, n)) % m
    for _ in range(MAX_REDRAWS):
        near = ~_far_from(true_curr[dst], true_curr[src], tau)
        if not near.any():
            break
        dst[near] = (src[near] + rng.integers(1, m, int(near.sum()))) % m
    return noisy_prev[src].copy(), noisy_curr[dst].copy()


def far_clutter(
    n: int, cam: StereoCamera, rotation: np.ndarray, translation: np.ndarray, tau: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` sky-like rows ``(prev, curr)``, each ``(n, 4)``, noise-free.

    At k-1: a pixel in the upper half of the left image, a disparity log-uniform in 0.05-1 px
    (depths of some 0.4-8 km at the default rig). At k: where the true motion ``(rotation (3, 3),
    translation (3,))`` puts that point, moved by 1-3 ``tau`` px in a random image direction (the
    same shift in both images) and clipped into the image; rows the clipping brings within
    ``tau`` px of the static point are moved to the other side.
    """
    lo, hi = np.log(_FAR_DISPARITY_PX[0]), np.log(_FAR_DISPARITY_PX[1])
    d = np.exp(rng.uniform(lo, hi, n))
    uL = rng.uniform(0.0, cam.width - 1.0, n)
    v = rng.uniform(0.0, 0.5 * (cam.height - 1.0), n)
    prev = np.column_stack([uL, v, uL - d, v])
    z = cam.fx * cam.baseline / d
    X = np.column_stack([(uL - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z])
    P = X @ rotation.T + translation
    P[:, 2] = np.maximum(P[:, 2], 1.0)  # a point behind camera k cannot be imaged: keep it ahead
    static = cam.project(P)
    angle = rng.uniform(-np.pi, np.pi, n)
    length = tau * rng.uniform(*_FAR_DRIFT, n)
    shift = np.column_stack([np.cos(angle), np.sin(angle)]) * length[:, None]
    curr = static.copy()
    curr[:, 0] += shift[:, 0]
    curr[:, 2] += shift[:, 0]
    curr[:, 1] += shift[:, 1]
    curr[:, 3] += shift[:, 1]
    curr = _in_image(curr, cam)
    near = ~_far_from(curr, static, tau)
    if near.any():  # clipped back towards the static point at an image border: go the other way
        back = static[near].copy()
        back[:, [0, 2]] -= shift[near, :1]
        back[:, [1, 3]] -= shift[near, 1:]
        curr[near] = _in_image(back, cam)
    return _in_image(prev, cam), curr


def repetitive_texture(
    X_prev: np.ndarray,
    true_curr: np.ndarray,
    cluster_size: int,
    cam: StereoCamera,
    rotation: np.ndarray,
    translation: np.ndarray,
    tau: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Rows ``(prev, curr)``, each ``(n, 4)`` noise-free, for landmarks ``X_prev (n, 3)`` (camera
    k-1) whose true frame-k pixels are ``true_curr (n, 4)``, in clusters of ``cluster_size``.

    The landmarks are ordered by their image column and cut into clusters (image strips). Within
    a cluster every depth at k-1 is off by one common factor (1.3-2, either way: the stereo match
    one period over), and every point moves by one wrong motion: the true one plus a lateral
    translation that shifts the cluster's mean depth by one texture period (2-4 tau px, either
    towards the image centre). So a cluster is exactly consistent with a rigid motion of its own,
    but for rows that the shift takes out of the image (clipped into it). While a row is still
    within ``tau`` px of the truth the shift is doubled, up to five times.
    """
    n = X_prev.shape[0]
    prev = np.empty((n, 4))
    curr = np.empty((n, 4))
    order = np.argsort(cam.project(X_prev)[:, 0], kind="stable")
    for start in range(0, n, cluster_size):
        rows = order[start : start + cluster_size]
        factor = rng.uniform(*_REPETITIVE_DEPTH_FACTOR)
        if rng.random() < 0.5:
            factor = 1.0 / factor
        X = X_prev[rows] * factor  # the same rays, a wrong depth
        # towards the image centre, so that few rows leave the image (those are clipped into it)
        centre_side = 1.0 if np.mean(true_curr[rows, 0]) < cam.cx else -1.0
        period = tau * rng.uniform(*_REPETITIVE_PERIOD) * centre_side
        shift = np.array([period * float(np.mean(X[:, 2])) / cam.fx, 0.0, 0.0])
        for _ in range(6):
            P = X @ rotation.T + translation + shift
            P[:, 2] = np.maximum(P[:, 2], 1e-3)
            fake = cam.project(P)
            if _far_from(fake, true_curr[rows], tau).all():
                break
            shift = 2.0 * shift
        prev[rows] = cam.project(X)
        curr[rows] = fake
    return _in_image(prev, cam), _in_image(curr, cam)


def repetitive_cluster_size(n_inliers: int) -> int:
    """Rows per repetitive-texture cluster: a third of the inliers, at least 6 (a consensus)."""
    return max(6, n_inliers // 3)


def student_t_scale(dof: float, shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """Factors that turn standard-normal draws of ``shape`` into Student-t draws with ``dof > 2``
    degrees of freedom scaled to unit variance: ``z sqrt(dof / chi2(dof)) sqrt((dof - 2) / dof)``
    (Student 1908). The noise keeps the standard deviation ``noise_sigma`` the estimator is told,
    with heavy tails: at 3 dof, 1.4 % of the coordinates lie beyond 3 sigma (Gaussian: 0.27 %)."""
    return np.sqrt((dof - 2.0) / rng.chisquare(dof, size=shape))
