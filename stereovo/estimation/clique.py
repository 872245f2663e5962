"""Inlier detection by maximum clique (Hirschmueller et al. 2002; Howard 2008): ALGORITHMS.md section 8.

A rigid motion preserves distances, so two correct matches i, j satisfy
``||X_i - X_j|| = ||Y_i - Y_j||`` up to noise. The consistency graph W links
every such pair; the largest set of mutually consistent matches (a maximum
clique) is taken as the inliers, the motion is fitted on it, and the inliers
are re-selected with the reprojection gate.

Depth-aware threshold (our first-order form of section 8, step 2): the change
of the distance between i and j has variance
``u^T (S_X,i + S_X,j) u + v^T (S_Y,i + S_Y,j) v`` with u, v the unit vectors
from j to i at k-1 and k and S the triangulation covariances, so
``delta_ij = c sqrt(that)`` with c = 3. It tightens the test for near points
and loosens it for far ones, whose depth error grows as Z^2.

Maximum clique: exact Bron-Kerbosch with Tomita pivoting and a size bound
(bitsets as Python ints) when ``N <= exact_max``, capped in time; Howard's
greedy approximation above (start at the node of largest degree, then add the
candidate with the most links to the other candidates). Not a sampling
method: priors and orders have no role, so passing them raises.

Known limitation (tested): a rigidly moving object is a clique of its own;
when it has more points than the static scene, it wins and the estimate is
the object's motion.
"""

from __future__ import annotations

import time

import numpy as np

from stereovo.estimation.loop import RansacReport
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.refinement import ReprojectionRefiner
from stereovo.estimation.reprojection import gauss_newton_steps
from stereovo.estimation.scoring import ReprojectionResidual
from stereovo.estimation.solvers import DEGENERATE_AREA_RATIO, SAMPLE_SIZE, fit_rigid

_ROW_BLOCK = 256  # rows of W built at once: bounds the (block, N, 3) temporaries
# Gates (multiples of the reprojection threshold) of the robust fit on the clique; None = all members.
_SHRINKING_GATE = (None, 10.0, 5.0, 3.0, 2.0, 1.0)


def consistency_matrix(problem: StereoProblem, c: float = 3.0) -> np.ndarray:
    """``(N, N)`` bool W: pairs whose distance changes by less than ``c`` standard deviations.

    Symmetric with a False diagonal (module docstring for the threshold). With
    ``d_ij = X_i - X_j``, ``u^T (S_i + S_j) u = (q_ij + q_ji) / |d_ij|^2`` where
    ``q_ij = d_ij^T S_i d_ij``, so one ``(N, N)`` quadratic form per frame suffices.
    """
    n = problem.n
    length, quad = {}, {}
    for name, P, S in (("prev", problem.points_prev, problem.cov_prev), ("curr", problem.points_curr, problem.cov_curr)):
        length[name] = np.empty((n, n))
        quad[name] = np.empty((n, n))
        for start in range(0, n, _ROW_BLOCK):
            rows = slice(start, min(start + _ROW_BLOCK, n))
            d = P[rows, None, :] - P[None, :, :]  # (b, N, 3)
            length[name][rows] = np.sqrt(np.einsum("bna,bna->bn", d, d))
            quad[name][rows] = np.einsum("bna,bac,bnc->bn", d, S[rows], d, optimize=True)
    var = np.zeros((n, n))
    for name in ("prev", "curr"):
        var += (quad[name] + quad[name].T) / np.maximum(length[name], 1e-12) ** 2
    W = np.abs(length["prev"] - length["curr"]) < c * np.sqrt(var)
    np.fill_diagonal(W, False)
    return W


def greedy_clique(W: np.ndarray) -> np.ndarray:
    """Howard's greedy clique: sorted int indices ``(k,)``; every pair in it is linked in W."""
    n = W.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    Wf = W.astype(np.float32)
    first = int(np.argmax(W.sum(axis=1)))
    clique = [first]
    candidates = W[first].copy()
    while np.any(candidates):
        links = Wf @ candidates.astype(np.float32)  # links of every node to the current candidates
        pick = int(np.argmax(np.where(candidates, links, -1.0)))
        clique.append(pick)
        candidates &= W[pick]
    return np.sort(np.array(clique, dtype=np.int64))


class _Timeout(Exception):
    pass


def exact_clique(W: np.ndarray, time_limit_s: float = 0.5, start: np.ndarray | None = None) -> tuple[np.ndarray, bool]:
    """Maximum clique by Bron-Kerbosch with pivoting and a size bound.

    Args:
        W: ``(N, N)`` symmetric bool adjacency, False diagonal.
        time_limit_s: wall-clock cap (the problem is NP-hard); on expiry the best clique so
            far is returned.
        start: a known clique (e.g. the greedy one) to beat; it prunes the search.

    Returns:
        ``(sorted indices, exact)``: ``exact`` is False when the time cap cut the search.
    """
    n = W.shape[0]
    adjacency = [int.from_bytes(np.packbits(row, bitorder="little").tobytes(), "little") for row in W]
    best = [0, 0]  # bitset, size
    if start is not None and len(start) > 0:
        best = [sum(1 << int(i) for i in start), len(start)]
    deadline = time.perf_counter() + time_limit_s
    calls = [0]

    def bits(x: int):
        while x:
            low = x & -x
            yield low.bit_length() - 1
            x ^= low

    def expand(clique: int, size: int, P: int, X: int) -> None:
        calls[0] += 1
        if calls[0] % 256 == 0 and time.perf_counter() > deadline:
            raise _Timeout
        if P == 0:
            if X == 0 and size > best[1]:
                best[0], best[1] = clique, size
            return
        if size + P.bit_count() <= best[1]:
            return  # cannot beat the best clique found so far
        # Tomita pivot: the vertex of P | X with the most neighbours in P.
        pivot = max(bits(P | X), key=lambda u: (P & adjacency[u]).bit_count())
        for v in bits(P & ~adjacency[pivot]):
            expand(clique | (1 << v), size + 1, P & adjacency[v], X & adjacency[v])
            P &= ~(1 << v)
            X |= 1 << v
            if size + P.bit_count() <= best[1]:
                return

    exact = True
    try:
        expand(0, 0, (1 << n) - 1 if n else 0, 0)
    except _Timeout:
        exact = False
    return np.array(sorted(bits(best[0])), dtype=np.int64), exact


def maximum_consistent_set(
    problem: StereoProblem, c: float = 3.0, exact_max: int = 60, time_limit_s: float = 0.5
) -> tuple[np.ndarray, np.ndarray, bool]:
    """The clique of mutually rigid-consistent matches.

    Returns:
        ``(clique indices (k,), W (N, N), exact)``; ``exact`` tells whether the clique is
        a proven maximum (Bron-Kerbosch finished) rather than the greedy approximation.
    """
    W = consistency_matrix(problem, c)
    clique = greedy_clique(W)
    if problem.n <= exact_max:
        found, exact = exact_clique(W, time_limit_s, start=clique)
        if found.size >= clique.size:
            clique = found
        return clique, W, exact
    return clique, W, False


def _collinear(points: np.ndarray) -> bool:
    """True when ``(k, 3)`` points lie (nearly) on a line: the rotation about it would be free.

    Same bound as the minimal solver's triangle test (ALGORITHMS.md Pitfalls): the second
    singular value of the centred points below ``DEGENERATE_AREA_RATIO`` times the first.
    """
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return bool(s[1] < DEGENERATE_AREA_RATIO * max(s[0], 1e-12))


def detect_inliers(
    problem: StereoProblem,
    threshold_sq: float,
    min_inliers: int = 6,
    refiner: ReprojectionRefiner | None = None,
    c: float = 3.0,
    exact_max: int = 60,
    time_limit_s: float = 0.5,
    fit_iterations: int = 6,
) -> RansacReport:
    """Maximum clique, least-squares fit on it, inliers re-selected by the reprojection gate.

    Args:
        threshold_sq: reprojection gate (px^2).
        refiner: optional final LM refinement with inlier re-selection.
        c, exact_max, time_limit_s: see :func:`maximum_consistent_set`.
        fit_iterations: Gauss-Newton steps of the reprojection fit on the clique.

    Returns:
        The loop's :class:`RansacReport`: one hypothesis (the clique's fit);
        ``n_point_checks`` counts the ``N (N - 1) / 2`` pair tests plus residual evaluations.
    """
    n = problem.n
    clique, W, _ = maximum_consistent_set(problem, c, exact_max, time_limit_s)
    residual_model = ReprojectionResidual(threshold_sq)
    checks = n * (n - 1) // 2
    counts = dict(n_hypotheses=1, n_scored=1, n_degenerate=0, n_local_optimizations=0, best_found_at=1)
    if clique.size < SAMPLE_SIZE:
        return RansacReport(
            np.eye(3), np.zeros(3), np.zeros(n, dtype=bool), -np.inf,
            f"failed: no consensus (largest consistent set has {clique.size} matches, need {SAMPLE_SIZE})",
            n_point_checks=checks, **counts,
        )
    if _collinear(problem.points_prev[clique]) or _collinear(problem.points_curr[clique]):
        return RansacReport(
            np.eye(3), np.zeros(3), np.zeros(n, dtype=bool), -np.inf,
            f"failed: all samples degenerate (the consistent set of {clique.size} matches is collinear)",
            n_point_checks=checks, **{**counts, "n_scored": 0, "n_degenerate": 1},
        )
    # Fit on the clique: Kabsch start, then Huber-weighted reprojection least squares with a
    # shrinking gate over the clique's members (Howard: minimise reprojection error and drop
    # residual outliers). A clique can mix two rigid groups (a moving object joined through far,
    # loosely constrained static points): the robust, shrinking fit follows the larger group
    # instead of settling between them.
    member = np.zeros(n, dtype=bool)
    member[clique] = True
    R, t = fit_rigid(problem.points_prev[clique], problem.points_curr[clique])
    R, t = R[None], t[None]
    huber = float(np.sqrt(threshold_sq))
    for scale in _SHRINKING_GATE:
        if scale is None:
            rows = clique
        else:
            inside = member & (residual_model.squared(problem, R, t)[0] < scale**2 * threshold_sq)
            checks += n
            if np.count_nonzero(inside) < SAMPLE_SIZE:
                break
            rows = np.flatnonzero(inside)
        R, t, _ = gauss_newton_steps(
            problem.camera, R, t, problem.points_prev[rows], problem.points_curr[rows],
            problem.prev[rows], problem.curr[rows], iterations=fit_iterations, huber=huber,
        )
    R, t = R[0], t[0]
    inliers = residual_model.squared(problem, R[None], t[None])[0] < threshold_sq
    checks += n
    if refiner is not None and np.count_nonzero(inliers) >= SAMPLE_SIZE:
        R, t, inliers = refiner.refine(problem, R, t, inliers, residual_model, threshold_sq)
        checks += n * refiner.rounds
    count = int(np.count_nonzero(inliers))
    if count < max(min_inliers, SAMPLE_SIZE):
        return RansacReport(
            np.eye(3), np.zeros(3), np.zeros(n, dtype=bool), float(count),
            f"failed: no consensus (clique fit has {count} inliers, need {min_inliers})",
            n_point_checks=checks, **counts,
        )
    return RansacReport(R, t, inliers, float(count), "ok", n_point_checks=checks, **counts)
