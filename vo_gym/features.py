"""Per-correspondence features: what a real stereo VO front end knows about each match.

One module computes them, so the environment, the heuristic agents and the
trainers all see the very same numbers. Nothing here
reads a ground-truth label: the inputs are the two stereo measurements of each
match, its match score, the camera, the sensor's pixel noise and, optionally,
the motion estimated for the previous frame pair.

Layout (``FEATURE_NAMES``, version ``FEATURE_LAYOUT_VERSION``), one float32
row per correspondence, every value clipped to ``[-FEATURE_BOUND, FEATURE_BOUND]``:

====  ======================  =====================================================================
 col  name                    definition
====  ======================  =====================================================================
   0  match_score             the descriptor match score in (0, 1), higher = better match
   1  score_rank              rank of the score within the frame, 0 = best, 1 = worst
   2  u_prev                  left-image column at k-1, mapped to [-1, 1] over the image width
   3  v_prev                  left-image row at k-1, mapped to [-1, 1] over the image height
   4  disparity_prev          disparity ``uL - uR`` at k-1 divided by ``fx / 10`` (= 10 b / z)
   5  u_curr                  as ``u_prev`` at k
   6  v_curr                  as ``v_prev`` at k
   7  disparity_curr          as ``disparity_prev`` at k
   8  log_depth_prev          ``log(z / 10 m)`` of the point triangulated at k-1
   9  log_depth_curr          ``log(z / 10 m)`` at k
  10  log_depth_std_prev      ``log(sigma_z / 1 m)``, depth std of the k-1 point (``sigma^2 J J^T``)
  11  cv_residual             ``log(1 + r / sigma)``, r the RMS stereo reprojection error (px) of the
                              k-1 point moved by the previous frame's motion (constant-velocity
                              prediction); 0 when no previous motion is known
  12  cv_available            1 when ``previous_motion`` was given, else 0 (same for every row)
  13  rigid_consistency       fraction of anchor matches j whose 3-D distance to i is preserved
                              between k-1 and k: ``| |X_k,i - X_k,j| - |X_k-1,i - X_k-1,j| | <
                              3 sqrt(s_i^2 + s_j^2)``, ``s^2`` the summed traces of both
                              triangulation covariances (Hirschmueller's consistency degree);
                              the anchors are all other matches, or the MAX_ANCHORS best-scored
====  ======================  =====================================================================

A match without depth (disparity at or below ``camera.min_disparity`` at k-1
or k: an *unusable row*, which the estimator treats as an outlier and never
samples) gets finite features that say so: its measured columns (score, rank,
coordinates, disparities) as usual, ``log_depth_prev``, ``log_depth_curr`` and
``log_depth_std_prev`` at ``+FEATURE_BOUND`` (as if infinitely far; a real point
would have to lie beyond 220 km), ``cv_residual`` 0 and ``rigid_consistency`` 0,
and it is no anchor of the other rows' consistency degree.
:func:`usable_rows` gives the mask; the environment's observation ``mask`` is 0
on such rows. No exception is raised for them.

The rigid-consistency degree is O(N A): one float32 pairwise-distance
computation per frame between all N matches and A anchors, ``A = N`` for
``N <= MAX_ANCHORS`` and otherwise the ``MAX_ANCHORS`` matches of highest
match score (deterministic, no random draw, and like every column
equivariant to a permutation of the rows). Anchoring on the best-scored
matches also enriches the anchors in inliers: on the simulator's frames the
degree separates inliers from outliers as well as or better than the full
O(N^2) count, at half the cost for N = 500.

A learned agent's checkpoint records ``FEATURE_NAMES`` and
``FEATURE_LAYOUT_VERSION``; :func:`check_feature_layout` refuses another layout.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numba import njit

from stereovo.camera import StereoCamera
from stereovo.estimation.estimator_options import ESTIMATOR_OPTION_RULES
from stereovo.estimation.problem import StereoProblem, as_measurements
from stereovo.estimation.roles.reprojection import reprojection_sq
from stereovo.estimation.kernels.rigidity import distance_change_sq_jit, rigid_distance_consistent_jit
from stereovo.options import real_array
from vo_gym.ordering import descending_order, finite_descending_order

__all__ = [
    "FEATURE_NAMES",
    "FEATURE_LAYOUT_VERSION",
    "N_FEATURES",
    "FEATURE_BOUND",
    "MAX_ANCHORS",
    "compute_features",
    "feature_index",
    "check_feature_layout",
    "rigid_consistency_degree",
    "usable_rows",
]

FEATURE_NAMES: tuple[str, ...] = (
    "match_score",
    "score_rank",
    "u_prev",
    "v_prev",
    "disparity_prev",
    "u_curr",
    "v_curr",
    "disparity_curr",
    "log_depth_prev",
    "log_depth_curr",
    "log_depth_std_prev",
    "cv_residual",
    "cv_available",
    "rigid_consistency",
)
"""Column names of :func:`compute_features`' output, in order."""

FEATURE_LAYOUT_VERSION: int = 1
"""Bumped whenever a column is added, removed, reordered or redefined."""

N_FEATURES: int = len(FEATURE_NAMES)

FEATURE_BOUND: float = 10.0
"""Every feature is clipped to ``[-FEATURE_BOUND, FEATURE_BOUND]`` (the observation Box)."""

MAX_ANCHORS: int = 256
"""Above this many matches the consistency degree is counted against this many best-scored ones."""

_DEPTH_REF_M = 10.0
_DISPARITY_REF = 10.0  # disparity * _DISPARITY_REF / fx == _DISPARITY_REF * baseline / depth
_CONSISTENCY_GATE = 3.0
_INDEX = {name: i for i, name in enumerate(FEATURE_NAMES)}


def feature_index(name: str) -> int:
    """Column of the feature called ``name`` (see :data:`FEATURE_NAMES`)."""
    try:
        return _INDEX[name]
    except KeyError:
        raise ValueError(f"unknown feature {name!r}; features are {list(FEATURE_NAMES)}") from None


def check_feature_layout(names: Sequence[str], version: int) -> None:
    """Refuse a feature layout other than this module's (e.g. one recorded in a checkpoint).

    Raises:
        ValueError: naming what differs.
    """
    if int(version) != FEATURE_LAYOUT_VERSION or tuple(names) != FEATURE_NAMES:
        raise ValueError(
            f"feature layout mismatch: got version {version} with {len(tuple(names))} features "
            f"{list(names)}, this vo_gym computes version {FEATURE_LAYOUT_VERSION} with {N_FEATURES} "
            f"features {list(FEATURE_NAMES)}"
        )


_NOISE_SIGMAS: dict[float, float] = {}  # floats that passed the rule (an environment asks for one every frame)


def _checked_noise_sigma(noise_sigma) -> float:
    """The estimator's own rule for noise_sigma (the one options contract), so both accept the same
    values; a float that passed it once is not checked again (the rule's answer is the same)."""
    if type(noise_sigma) is float and noise_sigma in _NOISE_SIGMAS:
        return _NOISE_SIGMAS[noise_sigma]
    checked = ESTIMATOR_OPTION_RULES["noise_sigma"].check("noise_sigma", noise_sigma, prefix="")
    if type(noise_sigma) is float and len(_NOISE_SIGMAS) < 64:
        _NOISE_SIGMAS[noise_sigma] = checked
    return checked


def _validate_motion(previous_motion) -> tuple[np.ndarray, np.ndarray] | None:
    if previous_motion is None:
        return None
    if type(previous_motion) is tuple and len(previous_motion) == 2:
        # the common case (an environment's last motion): float64 arrays of the right shapes, whose
        # twelve values are read as floats (numpy's isfinite on each costs more than the test)
        R, t = previous_motion
        if (type(R) is np.ndarray and type(t) is np.ndarray and R.dtype == np.float64 and t.dtype == np.float64
                and R.shape == (3, 3) and t.shape == (3,)
                and all(map(math.isfinite, R.ravel().tolist())) and all(map(math.isfinite, t.tolist()))):
            return R, t
    try:
        R, t = previous_motion
    except (TypeError, ValueError):
        raise ValueError("previous_motion must be None or a pair (R (3, 3), t (3,))") from None
    R, t = np.asarray(R, dtype=float), np.asarray(t, dtype=float)
    if R.shape != (3, 3) or t.shape != (3,) or not (np.isfinite(R).all() and np.isfinite(t).all()):
        raise ValueError(f"previous_motion must be finite (R (3, 3), t (3,)), got shapes {R.shape} and {t.shape}")
    return R, t


def rigid_consistency_degree(
    points_prev: np.ndarray,
    points_curr: np.ndarray,
    spread: np.ndarray,
    priority: np.ndarray | None = None,
    gate: float = _CONSISTENCY_GATE,
    priority_order: np.ndarray | None = None,
) -> np.ndarray:
    """Fraction ``(N,)`` of other matches with which each match keeps its 3-D distance.

    Args:
        points_prev, points_curr: ``(N, 3)`` triangulated points at k-1 and k (m).
        spread: ``(N,)`` per-match std (m) of a distance change, e.g. the root of
            the summed covariance traces at k-1 and k.
        priority: ``(N,)``; above :data:`MAX_ANCHORS` matches the fraction is over the
            ``MAX_ANCHORS`` matches of highest priority (ties by row), None = evenly spaced rows.
        gate: pair (i, j) is consistent when the distance change is below
            ``gate * sqrt(spread_i^2 + spread_j^2)``.
        priority_order: ``np.argsort(-priority, kind="stable")`` if the caller has it already.
    """
    n = points_prev.shape[0]
    if n < 2:
        return np.zeros(n, dtype=np.float32)
    if n <= MAX_ANCHORS:
        anchors = np.arange(n)
    elif priority is None:
        anchors = np.linspace(0, n - 1, MAX_ANCHORS).round().astype(np.int64)
    else:
        order = descending_order(np.asarray(priority)) if priority_order is None else priority_order
        anchors = np.sort(order[:MAX_ANCHORS])
    s2 = np.square(np.asarray(spread, dtype=float))
    count = _consistent_pairs(
        np.ascontiguousarray(points_prev, dtype=float), np.ascontiguousarray(points_curr, dtype=float),
        s2, np.ascontiguousarray(anchors, dtype=np.int64), float(gate * gate),
    )
    return _anchor_fractions(count, np.ascontiguousarray(anchors, dtype=np.int64), np.empty(n, dtype=np.float32))


@njit(cache=True, nogil=True, error_model="numpy")
def _anchor_fractions(count, anchors, out):
    """``out (N,) float32 = (count - is_anchor) / (A - is_anchor)`` (a match is trivially consistent
    with itself, and is no other anchor of its own), for the counts ``(N,)`` of the A ``anchors``: the
    int64 differences, their float64 quotient and its float32 rounding, as numpy computes them."""
    a = anchors.shape[0]
    is_anchor = np.zeros(count.shape[0], dtype=np.bool_)
    for k in range(a):
        is_anchor[anchors[k]] = True
    for i in range(count.shape[0]):
        own = 1 if is_anchor[i] else 0
        out[i] = np.float32((count[i] - own) / (a - own))
    return out


# The single-precision screen of :func:`_consistent_pairs` (see its doc).
_SCREEN_ULPS = 64.0  # its error bound on the distance change, in float32 ulps of the largest centred coordinate
_SCREEN_MARGIN = 1e-5  # its relative margin on the squared gate
_SCREEN_MAX_COORDINATE = 1e15  # beyond it (or on non-finite points) every pair takes the test itself
_SCREEN_MIN_GATE = 1e-8  # as when the gate's root is below this times the largest coordinate


@njit(cache=True, nogil=True)
def _consistent_pairs(points_prev, points_curr, s2, anchors, gate_sq):
    """``(N,)`` counts of anchors j that pass the rigid-distance test (:mod:`stereovo.estimation.kernels.rigidity`)
    with ``var = s2_i + s2_j``: ``(|Q_i - Q_j| - |P_i - P_j|)^2 < gate_sq (s2_i + s2_j)``.

    The counts are exactly those of the test itself (:func:`_consistent_pairs_exact`), with most pairs
    decided by a single-precision screen (eight lanes a vector instead of four, float32 roots). The
    screen's points are each frame's points less their box centre, rounded to float32; with ``L`` the
    largest centred coordinate and ``u = 2^-24``, its distance change ``D`` is within ``40 L u`` of the
    exact one (rounding ``2 L u`` and differencing ``2 L u`` a coordinate, the norm ``3 u`` of at most
    ``2 sqrt(3) L``, for each distance, then their difference). With ``E = 64 L u`` a pair with
    ``(|D| + E)^2 < c (1 - 1e-5)`` (``c = gate_sq var``) passes and one with ``(|D| - E)^2 > c (1 +
    1e-5)`` fails in exact arithmetic, with a relative margin far above the screen's own float32
    rounding of ``c`` and of the squares (a few ``u``). The test in double precision errs by at most
    about ``10 2^-53 M`` on the change (``M`` the largest coordinate), inside that margin wherever
    ``sqrt(c) > 1e-8 M``; the kernel checks that, and finite coordinates below 1e15, once per call and
    otherwise runs the test on every pair. The pairs the screen leaves undecided (those near the gate)
    take the test itself. So each count is the test's (``tests/vo_gym/test_features.py`` compares
    them on frames and on pairs placed at the gate).
    """
    n, a = points_prev.shape[0], anchors.shape[0]
    largest = 0.0
    finite = True
    low_p, high_p = np.full(3, np.inf), np.full(3, -np.inf)
    low_q, high_q = np.full(3, np.inf), np.full(3, -np.inf)
    for i in range(n):
        for j in range(3):
            u, v = points_prev[i, j], points_curr[i, j]
            finite = finite and abs(u) <= _SCREEN_MAX_COORDINATE and abs(v) <= _SCREEN_MAX_COORDINATE  # NaN fails
            largest = max(largest, abs(u), abs(v))
            low_p[j], high_p[j] = min(low_p[j], u), max(high_p[j], u)
            low_q[j], high_q[j] = min(low_q[j], v), max(high_q[j], v)
    smallest_s2 = np.inf
    for i in range(n):
        smallest_s2 = min(smallest_s2, s2[i])
    if not (n > 0 and finite and math.sqrt(gate_sq * 2.0 * smallest_s2) > _SCREEN_MIN_GATE * largest):  # NaN s2 too
        return _consistent_pairs_exact(points_prev, points_curr, s2, anchors, gate_sq)
    centre_p, centre_q = 0.5 * (low_p + high_p), 0.5 * (low_q + high_q)
    p32 = np.empty((n, 3), dtype=np.float32)
    q32 = np.empty((n, 3), dtype=np.float32)
    spread = 0.0
    for i in range(n):
        for j in range(3):
            p32[i, j] = points_prev[i, j] - centre_p[j]
            q32[i, j] = points_curr[i, j] - centre_q[j]
            spread = max(spread, abs(points_prev[i, j] - centre_p[j]), abs(points_curr[i, j] - centre_q[j]))
    bound = np.float32(_SCREEN_ULPS * spread * 2.0**-24)
    below, above = np.float32(1.0 - _SCREEN_MARGIN), np.float32(1.0 + _SCREEN_MARGIN)
    gate32 = np.float32(gate_sq)
    zero = np.float32(0.0)
    s32 = s2.astype(np.float32)
    px, py, pz = p32[anchors, 0].copy(), p32[anchors, 1].copy(), p32[anchors, 2].copy()
    qx, qy, qz = q32[anchors, 0].copy(), q32[anchors, 1].copy(), q32[anchors, 2].copy()
    s2_anchor32 = s32[anchors]
    # the test's own double-precision inputs, gathered alike
    dpx, dpy, dpz = points_prev[anchors, 0].copy(), points_prev[anchors, 1].copy(), points_prev[anchors, 2].copy()
    dqx, dqy, dqz = points_curr[anchors, 0].copy(), points_curr[anchors, 1].copy(), points_curr[anchors, 2].copy()
    s2_anchor = s2[anchors]
    # The test is symmetric bit for bit (the differences of a swapped pair are negated exactly, the
    # variances added in either order), and so is the screen: a pair of two anchors is tested once,
    # from the row of the later anchor, and its result also counted for the earlier one (``later``
    # holds those counts). That spares a quarter of the pairs at N = 500, A = 256. Anchors named
    # twice (no caller's) take every pair from both sides.
    position = np.full(n, -1, dtype=np.int64)
    for k in range(a):
        if position[anchors[k]] >= 0:
            position[:] = -1
            break
        position[anchors[k]] = k
    later = np.zeros(a, dtype=np.int64)
    undecided = np.zeros(a, dtype=np.uint8)
    counts = np.zeros(n, dtype=np.int64)
    for i in range(n):
        p0, p1, p2 = p32[i, 0], p32[i, 1], p32[i, 2]
        q0, q1, q2 = q32[i, 0], q32[i, 1], q32[i, 2]
        s2i = s32[i]
        c = 0
        left = 0
        own = position[i]
        # an anchor's row: the anchors before it, then its own pair (a loop from 0: one that starts
        # further on runs at half the speed)
        stop = own + 1 if own >= 0 else a
        for k in range(stop):
            x0, x1, x2 = px[k] - p0, py[k] - p1, pz[k] - p2
            y0, y1, y2 = qx[k] - q0, qy[k] - q1, qz[k] - q2
            change = abs(np.sqrt(y0 * y0 + y1 * y1 + y2 * y2) - np.sqrt(x0 * x0 + x1 * x1 + x2 * x2))
            gate = gate32 * (s2i + s2_anchor32[k])
            high = change + bound
            low = max(change - bound, zero)
            passes = high * high < gate * below
            fails = low * low > gate * above
            c += passes
            flag = not (passes or fails)
            undecided[k] = flag + 2 * passes  # one array written: a second stops the vectors
            left += flag
        if own >= 0:
            before = later[own]  # the later anchors' pairs with this one, so far
            for k in range(stop):
                later[k] += undecided[k] >> 1
        if left:
            d0, d1, d2 = points_prev[i, 0], points_prev[i, 1], points_prev[i, 2]
            e0, e1, e2 = points_curr[i, 0], points_curr[i, 1], points_curr[i, 2]
            ds2 = s2[i]
            for k in range(stop):
                if undecided[k] & 1:
                    change_sq = distance_change_sq_jit(dpx[k] - d0, dpy[k] - d1, dpz[k] - d2,
                                                       dqx[k] - e0, dqy[k] - e1, dqz[k] - e2)
                    result = rigid_distance_consistent_jit(change_sq, ds2 + s2_anchor[k], gate_sq)
                    c += result
                    if own >= 0:
                        later[k] += result
        if own >= 0:
            later[own] = before  # its own pair is counted once, in c
        counts[i] = c
    for k in range(a):
        if position[anchors[k]] == k:
            counts[anchors[k]] += later[k]
    return counts


@njit(cache=True, nogil=True)
def _consistent_pairs_exact(points_prev, points_curr, s2, anchors, gate_sq):
    """:func:`_consistent_pairs` with every pair through the rigid-distance test itself (its reference).

    One pass over the N x A pairs; the anchors' coordinates are gathered first so the
    inner loop reads contiguous memory.
    """
    n, a = points_prev.shape[0], anchors.shape[0]
    px, py, pz = points_prev[anchors, 0].copy(), points_prev[anchors, 1].copy(), points_prev[anchors, 2].copy()
    qx, qy, qz = points_curr[anchors, 0].copy(), points_curr[anchors, 1].copy(), points_curr[anchors, 2].copy()
    s2_anchor = s2[anchors]
    counts = np.zeros(n, dtype=np.int64)
    for i in range(n):
        p0, p1, p2 = points_prev[i, 0], points_prev[i, 1], points_prev[i, 2]
        q0, q1, q2 = points_curr[i, 0], points_curr[i, 1], points_curr[i, 2]
        s2i = s2[i]
        c = 0
        for k in range(a):
            change_sq = distance_change_sq_jit(px[k] - p0, py[k] - p1, pz[k] - p2, qx[k] - q0, qy[k] - q1, qz[k] - q2)
            c += rigid_distance_consistent_jit(change_sq, s2i + s2_anchor[k], gate_sq)
        counts[i] = c
    return counts


@njit(cache=True, nogil=True)
def _plain_columns(out, scores, by_score, prev, curr, u_scale, v_scale, disparity_scale, cov_prev, cov_curr, spread):
    """In place, the columns without a transcendental function, in one pass, each value computed as
    numpy's column-wise formulation computes it (in float64, stored to float32): the score, its rank
    ``rank / max(n - 1, 1)``, ``u * u_scale - 1``, ``v * v_scale - 1`` and ``(uL - uR) * disparity_scale``
    at k-1 and k; and ``spread = sqrt(trace(cov_prev) + trace(cov_curr))`` (each trace summed in
    ``np.trace``'s order)."""
    n = out.shape[0]
    denominator = float(max(n - 1, 1))
    for position in range(n):
        out[by_score[position], 1] = float(position) / denominator
    for i in range(n):
        out[i, 0] = scores[i]
        out[i, 2] = prev[i, 0] * u_scale - 1.0
        out[i, 3] = prev[i, 1] * v_scale - 1.0
        out[i, 4] = (prev[i, 0] - prev[i, 2]) * disparity_scale
        out[i, 5] = curr[i, 0] * u_scale - 1.0
        out[i, 6] = curr[i, 1] * v_scale - 1.0
        out[i, 7] = (curr[i, 0] - curr[i, 2]) * disparity_scale
        spread[i] = math.sqrt((cov_prev[i, 0, 0] + cov_prev[i, 1, 1] + cov_prev[i, 2, 2])
                              + (cov_curr[i, 0, 0] + cov_curr[i, 1, 1] + cov_curr[i, 2, 2]))


def usable_rows(features: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: the rows of :func:`compute_features`' output that have a depth (the
    others carry ``log_depth_prev = +FEATURE_BOUND``, see the module doc)."""
    return np.asarray(features)[:, _INDEX["log_depth_prev"]] < FEATURE_BOUND


def compute_features(
    prev: np.ndarray,
    curr: np.ndarray,
    scores: np.ndarray,
    camera: StereoCamera,
    noise_sigma: float,
    previous_motion: tuple[np.ndarray, np.ndarray] | None = None,
    problem: StereoProblem | None = None,
) -> np.ndarray:
    """Features ``(N, N_FEATURES)`` float32 of N putative stereo matches (layout in the module doc).

    Args:
        prev, curr: ``(N, 4)`` stereo measurements ``(uL, vL, uR, vR)`` in pixels at k-1 and k.
        scores: ``(N,)`` match scores.
        camera: the rectified stereo rig.
        noise_sigma: the sensor's pixel noise std (px, > 0), a known sensor spec.
        previous_motion: ``(R, t)`` estimated for the previous frame pair
            (``x_k = R x_{k-1} + t``), the constant-velocity prediction of this one; None if unknown.
        problem: the same frame's :class:`StereoProblem` (same measurements, camera and noise),
            if the caller built one for the estimator: its triangulated points and covariances
            are reused instead of recomputed.

    Rows without depth get the finite, flagged features of the module doc; they raise nothing.

    Raises:
        ValueError: on malformed input (shapes, NaN/inf, complex values, non-positive noise), or
            a ``problem`` of another frame.
    """
    if not isinstance(camera, StereoCamera):
        raise ValueError(f"camera must be a StereoCamera, got {type(camera).__name__}")
    # The problem's own arrays were validated when it was built (the environment's case).
    own_arrays = problem is not None and prev is problem.prev and curr is problem.curr
    if not own_arrays:
        prev = as_measurements("prev", prev)
        curr = as_measurements("curr", curr)
    n = prev.shape[0]
    if curr.shape[0] != n:
        raise ValueError(f"prev and curr must have the same number of rows, got {n} and {curr.shape[0]}")
    scores = real_array("scores", scores, (n,), what=f"a finite ({n},) array of numbers")
    by_score = finite_descending_order(scores)  # best first; also picks the consistency anchors
    if by_score is None:
        raise ValueError(f"scores must be finite, got NaN or inf in {np.count_nonzero(~np.isfinite(scores))} row(s)")
    noise_sigma = _checked_noise_sigma(noise_sigma)
    motion = _validate_motion(previous_motion)

    out = np.zeros((n, N_FEATURES), dtype=np.float32)
    if n == 0:
        return out
    if problem is not None:
        if not (
            (problem.camera is camera or problem.camera == camera) and problem.noise_sigma == noise_sigma
            and (own_arrays or (np.array_equal(problem.prev, prev) and np.array_equal(problem.curr, curr)))
        ):
            raise ValueError("problem must be built from the same prev, curr, camera and noise_sigma")
        points_prev, points_curr = problem.points_prev, problem.points_curr
        cov_prev, cov_curr = problem.cov_prev, problem.cov_curr
        usable = problem.usable  # None: every row has depth
    else:  # the estimator's own rule for which rows have a depth (NaN rows and unresolvable disparities too)
        problem = StereoProblem.build(prev, curr, camera, noise_sigma)
        points_prev, points_curr = problem.points_prev, problem.points_curr
        cov_prev, cov_curr = problem.cov_prev, problem.cov_curr
        usable = problem.usable

    u_scale, v_scale = 2.0 / max(camera.width - 1, 1), 2.0 / max(camera.height - 1, 1)
    spread = np.empty(n)  # the root of the summed covariance traces at k-1 and k
    _plain_columns(out, scores, by_score, prev, curr, u_scale, v_scale, _DISPARITY_REF / camera.fx,
                   cov_prev, cov_curr, spread)
    sq = None
    if motion is not None:
        R, t = motion
        sq = reprojection_sq(camera, R[None], t[None], points_prev, curr)[0]  # inf behind the camera
    # The logarithms' arguments in one compiled pass (quotients, a maximum and a root: correctly
    # rounded either way), numpy's log over the three rows at once (its vector loop gives each value
    # whatever its place in a contiguous array, tests/vo_gym/test_features.py) and its log1p, then
    # the float32 columns in one pass. One errstate for both (the logarithms cannot overflow, so
    # ignoring it there changes no warning).
    arguments = np.empty((3 if sq is None else 4, n))
    _log_arguments(points_prev, points_curr, cov_prev, sq, float(noise_sigma), arguments)
    with np.errstate(over="ignore", invalid="ignore"):  # NaN on rows without depth, overwritten below
        np.log(arguments[:3], out=arguments[:3])
        if sq is not None:
            np.log1p(arguments[3], out=arguments[3])
    _log_columns(arguments, out)
    if usable is None:
        out[:, 13] = rigid_consistency_degree(points_prev, points_curr, spread, priority=scores, priority_order=by_score)
    else:
        # among the rows with depth only (they alone are anchors); the others are flagged
        rows = np.flatnonzero(usable)
        out[rows, 13] = rigid_consistency_degree(points_prev[rows], points_curr[rows], spread[rows], priority=scores[rows])
        out[~usable, 8:11] = FEATURE_BOUND
        out[~usable, 11] = 0.0
        out[~usable, 13] = 0.0
        out[~usable, 2:8] = np.nan_to_num(out[~usable, 2:8], nan=0.0)  # a NaN row's pixels say nothing
    _clip_in_place(out, FEATURE_BOUND)  # returns nothing: boxing an array costs a dtype lookup
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _log_arguments(points_prev, points_curr, cov_prev, sq, noise_sigma, arguments):
    """Rows of ``arguments (3 or 4, N)``: ``z_prev / 10``, ``z_curr / 10``, ``np.maximum(var_z_prev,
    1e-300)`` (a NaN stays NaN) and, with ``sq`` (N,) (None: no fourth row), ``np.sqrt(sq / 4) /
    noise_sigma``; each value as numpy's column expression computes it."""
    for i in range(points_prev.shape[0]):
        arguments[0, i] = points_prev[i, 2] / _DEPTH_REF_M
        arguments[1, i] = points_curr[i, 2] / _DEPTH_REF_M
        v = cov_prev[i, 2, 2]
        arguments[2, i] = v if (v >= 1e-300 or v != v) else 1e-300
    if sq is not None:
        for i in range(sq.shape[0]):
            arguments[3, i] = np.sqrt(sq[i] / 4.0) / noise_sigma


@njit(cache=True, nogil=True)
def _log_columns(logs, out):
    """Columns 8 to 12 of ``out (N, F)`` float32 from ``logs (3 or 4, N)``: the two log-depths,
    ``0.5 *`` the log-variance, and with a fourth row the prediction residual and the flag 1."""
    for i in range(out.shape[0]):
        out[i, 8] = np.float32(logs[0, i])
        out[i, 9] = np.float32(logs[1, i])
        out[i, 10] = np.float32(0.5 * logs[2, i])
        if logs.shape[0] > 3:
            out[i, 11] = np.float32(logs[3, i])
            out[i, 12] = np.float32(1.0)


@njit(cache=True, nogil=True)
def _clip_in_place(out, bound):
    """``np.clip(out, -bound, bound, out=out)`` of a float32 array in one pass, numpy's values
    (``np.maximum``, then ``np.minimum``: a NaN stays NaN; the bound is a float32 number)."""
    low, high = np.float32(-bound), np.float32(bound)
    flat = out.reshape(-1)
    for i in range(flat.shape[0]):
        x = flat[i]
        if x < low:
            x = low
        if x > high:
            x = high
        flat[i] = x
