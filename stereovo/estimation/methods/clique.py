"""Inlier detection by maximum clique (Hirschmueller et al. 2002; Howard 2008): docs/algorithms.md, `inlier-detection`.

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

The fit on the clique is robust (Howard: minimise the reprojection error and
drop residual outliers). Far points are loosely constrained by distances, so a
clique may hold a few far outliers, and a least-squares start on all of it can
be degrees off; instead a small RANSAC inside the clique (uniform minimal
samples, the 3-D Mahalanobis chi-square gate, adaptive stop) gives the start,
Huber-weighted reprojection least squares on its inliers follows, then a
shrinking reprojection gate over the clique's members.

Memory is bounded: the graph is a dense ``(M, M)`` bool matrix built in row
blocks (M^2 bytes, plus ``(block, M)`` temporaries), on all N matches when
``N <= graph_max`` (:data:`GRAPH_MAX`, 2000: 4 MB) and otherwise on ``graph_max``
matches drawn at random with the passed generator; the motion fitted on that
clique then re-selects the inliers among all N. Never an N x N allocation.

Known limitation (tested): a rigidly moving object is a clique of its own;
when it has more points than the static scene, it wins and the estimate is
the object's motion.

Counters (``RansacReport.counters``): ``clique_graph_nodes`` (M),
``clique_graph_edges`` (links in W), ``clique_size``, ``clique_exact`` (1 if
Bron-Kerbosch proved the maximum), ``clique_subsampled`` (1 if M < N),
``clique_fit_hypotheses`` (minimal samples of the RANSAC inside the clique) and
``clique_fit_inliers`` (its consensus among the clique).

This module also declares the ``clique_*`` options and registers ``inlier-detection``.
"""

from __future__ import annotations

import time

import numpy as np

from stereovo.estimation.estimator_options import MAX_COUNT, OptionReads
from stereovo.estimation.kernels.rigidity import distance_change_sq, rigid_distance_consistent
from stereovo.estimation.loop import RansacComponents, RansacReport, final_report, run_ransac
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.recipes import final_refiner
from stereovo.estimation.registry import register_estimator
from stereovo.estimation.roles.refinement import ReprojectionRefiner
from stereovo.estimation.roles.reprojection import gauss_newton_steps
from stereovo.estimation.roles.samplers import UniformSampler
from stereovo.estimation.roles.scoring import (
    CHI2_3_95,
    InlierCount,
    MahalanobisResidual,
    ReprojectionResidual,
)
from stereovo.estimation.roles.solvers import SAMPLE_SIZE
from stereovo.estimation.roles.termination import AdaptiveTermination
from stereovo.options import Integer, Number

GRAPH_MAX = 2000
"""Most matches the consistency graph is built on (a 4 MB bool matrix); above, a random subset of
this many (see the module docstring)."""
_ROW_BLOCK = 256  # rows of W built at once: bounds the (block, M) temporaries
# Gates (multiples of the reprojection threshold) of the shrinking fit on the clique's members.
_SHRINKING_GATE = (10.0, 5.0, 3.0, 2.0, 1.0)
_FIT_MAX_HYPOTHESES = 1000  # cap of the RANSAC inside the clique (mostly inliers: it stops far sooner)


def _quadratic_forms(d: np.ndarray, S: np.ndarray) -> np.ndarray:
    """``d^T S d`` for ``d (b, M, 3)`` and symmetric ``S`` broadcastable to ``(b, M, 3, 3)``.

    Written out over S's six entries, so that ``(-d)^T S (-d)`` is bit-identical to ``d^T S d``
    (W comes out exactly symmetric).
    """
    d0, d1, d2 = d[..., 0], d[..., 1], d[..., 2]
    return (S[..., 0, 0] * d0 * d0 + S[..., 1, 1] * d1 * d1 + S[..., 2, 2] * d2 * d2
            + 2.0 * (S[..., 0, 1] * d0 * d1 + S[..., 0, 2] * d0 * d2 + S[..., 1, 2] * d1 * d2))


def consistency_matrix(problem: StereoProblem, c: float = 3.0) -> np.ndarray:
    """``(N, N)`` bool W: pairs whose distance changes by less than ``c`` standard deviations.

    Symmetric with a False diagonal (module docstring for the threshold). With
    ``d_ij = X_i - X_j``, ``u^T (S_i + S_j) u = (d_ij^T S_i d_ij + d_ij^T S_j d_ij) / |d_ij|^2``.
    Built in blocks of rows: N^2 bytes for W plus ``(block, N)`` float temporaries.
    """
    n = problem.n
    W = np.zeros((n, n), dtype=bool)
    frames = ((problem.points_prev, problem.cov_prev), (problem.points_curr, problem.cov_curr))
    for start in range(0, n, _ROW_BLOCK):
        rows = slice(start, min(start + _ROW_BLOCK, n))
        diffs, var = [], 0.0
        for P, S in frames:
            d = P[rows, None, :] - P[None, :, :]  # (b, N, 3)
            sq = np.einsum("bna,bna->bn", d, d)
            q = _quadratic_forms(d, S[rows, None]) + _quadratic_forms(d, S[None, :])
            diffs.append(d)
            var = var + q / np.maximum(sq, 1e-24)
        (x, y) = diffs
        change_sq = distance_change_sq(x[..., 0], x[..., 1], x[..., 2], y[..., 0], y[..., 1], y[..., 2])
        W[rows] = rigid_distance_consistent(change_sq, var, c * c)
    np.fill_diagonal(W, False)
    return W


def greedy_clique(W: np.ndarray) -> np.ndarray:
    """Howard's greedy clique: sorted int indices ``(k,)``; every pair in it is linked in W.

    Start at the node of largest degree; repeatedly add the candidate (a node linked to every
    member) with the most links to the other candidates, the lowest index on ties. The links are
    kept up to date as candidates drop out, so the whole search costs O(d^2) for a first node of
    degree d.
    """
    n = W.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    first = int(np.argmax(W.sum(axis=1)))
    clique = [first]
    idx = np.flatnonzero(W[first])  # every later member is a neighbour of the first
    Wc = W[np.ix_(idx, idx)]
    alive = np.ones(idx.size, dtype=bool)
    links = Wc.sum(axis=1, dtype=np.int64)  # links of each node to the current candidates
    while np.any(alive):
        pick = int(np.argmax(np.where(alive, links, -1)))
        clique.append(int(idx[pick]))
        removed = alive & ~Wc[pick]  # the pick itself too (False diagonal)
        alive &= Wc[pick]
        links -= Wc[:, removed].sum(axis=1, dtype=np.int64)
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


def robust_clique_fit(
    problem: StereoProblem,
    clique: np.ndarray,
    threshold_sq: float,
    rng: np.random.Generator,
    gate_sq: float = CHI2_3_95,
    confidence: float = 0.99,
    fit_iterations: int = 6,
) -> tuple[np.ndarray, np.ndarray, RansacReport, int]:
    """The motion of the clique's majority, robust to the few outliers a clique may hold.

    A RANSAC inside the clique (uniform minimal samples, chi-square Mahalanobis gate ``gate_sq``,
    adaptive stop at ``confidence``, at most 1000 samples) gives the start; Huber-weighted
    reprojection least squares on its inliers, then on the members inside a shrinking
    reprojection gate, refines it (Howard: minimise the reprojection error, drop residual
    outliers). A clique can also mix two rigid groups (a moving object joined through far,
    loosely constrained static points): the start and the shrinking gate follow the larger one.

    Returns:
        ``(R (3, 3), t (3,), inner report, point checks spent)``; when the inner report is not
        ok (every sample of the clique degenerate, e.g. collinear), ``R, t`` are the identity.
    """
    sub = problem.select(clique)
    inner = run_ransac(sub, RansacComponents(
        sampler=UniformSampler(sub.n),
        residual_model=MahalanobisResidual(gate_sq),
        quality=InlierCount(),
        threshold_sq=gate_sq,
        termination=AdaptiveTermination(confidence, _FIT_MAX_HYPOTHESES),
        refiner=None,
        batch_size=64,
        first_batch_size=16,
        polish_iterations=0,
        min_inliers=SAMPLE_SIZE,
        # a fit inside the clique, not a search for consensus: the clique is the method's verdict,
        # and the fit starts from the largest consensus found whatever the cap left unconfirmed
        fail_at_cap=False,
    ), rng)
    checks = inner.n_point_checks
    if inner.status != "ok":
        return np.eye(3), np.zeros(3), inner, checks
    residual_model = ReprojectionResidual(threshold_sq)
    huber = float(np.sqrt(threshold_sq))
    R, t = inner.rotation[None], inner.translation[None]
    rows = np.flatnonzero(inner.inliers)
    for scale in (None, *_SHRINKING_GATE):
        if scale is not None:
            inside = residual_model.squared(sub, R, t)[0] < scale**2 * threshold_sq
            checks += sub.n
            if np.count_nonzero(inside) < SAMPLE_SIZE:
                break
            rows = np.flatnonzero(inside)
        R, t, _ = gauss_newton_steps(
            sub.camera, R, t, sub.points_prev[rows], sub.points_curr[rows], sub.prev[rows], sub.curr[rows],
            iterations=fit_iterations, huber=huber,
        )
    return R[0], t[0], inner, checks


def detect_inliers(
    problem: StereoProblem,
    threshold_sq: float,
    min_inliers: int = 6,
    refiner: ReprojectionRefiner | None = None,
    c: float = 3.0,
    exact_max: int = 60,
    time_limit_s: float = 0.5,
    fit_iterations: int = 6,
    rng: np.random.Generator | None = None,
    graph_max: int = GRAPH_MAX,
    gate_sq: float = CHI2_3_95,
    confidence: float = 0.99,
) -> RansacReport:
    """Maximum clique, robust fit on it, inliers re-selected by the reprojection gate.

    Args:
        threshold_sq: reprojection gate (px^2).
        refiner: optional final LM refinement with inlier re-selection.
        c, exact_max, time_limit_s: see :func:`maximum_consistent_set`.
        fit_iterations: Gauss-Newton steps per stage of the reprojection fit on the clique.
        rng: the generator of the fit's RANSAC and of the graph's subset (default: seed 0).
        graph_max: most matches the graph is built on; above, a random subset of this many.
        gate_sq, confidence: Mahalanobis gate and stopping confidence of the fit's RANSAC.

    Returns:
        The loop's :class:`RansacReport`: one hypothesis (the clique's fit); ``n_point_checks``
        counts the ``M (M - 1) / 2`` pair tests plus residual evaluations; ``counters`` as in the
        module docstring.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    n = problem.n
    nodes = np.arange(n) if n <= graph_max else np.sort(rng.choice(n, size=graph_max, replace=False))
    graph = problem if n <= graph_max else problem.select(nodes)
    found, W, exact = maximum_consistent_set(graph, c, exact_max, time_limit_s)
    clique = nodes[found]
    counters = {
        "clique_graph_nodes": int(graph.n), "clique_graph_edges": int(np.count_nonzero(W)) // 2,
        "clique_size": int(clique.size), "clique_exact": int(exact), "clique_subsampled": int(graph.n < n),
        "clique_fit_hypotheses": 0, "clique_fit_inliers": 0,
    }
    del W
    checks = graph.n * (graph.n - 1) // 2
    counts = dict(n_hypotheses=1, n_scored=1, n_degenerate=0, n_local_optimizations=0, best_found_at=1)

    def failed(reason: str, score: float = -np.inf, **changes) -> RansacReport:
        return RansacReport(np.eye(3), np.zeros(3), np.zeros(n, dtype=bool), score, f"failed: {reason}",
                            n_point_checks=checks, counters=counters, **{**counts, **changes})

    if clique.size < SAMPLE_SIZE:
        return failed(f"no consensus (largest consistent set has {clique.size} matches, need {SAMPLE_SIZE})")
    R, t, inner, spent = robust_clique_fit(problem, clique, threshold_sq, rng, gate_sq, confidence, fit_iterations)
    checks += spent
    counters["clique_fit_hypotheses"] = int(inner.n_hypotheses)
    counters["clique_fit_inliers"] = int(np.count_nonzero(inner.inliers))
    if inner.status != "ok":
        if inner.n_scored == 0:
            return failed(f"all samples degenerate (the consistent set of {clique.size} matches is collinear)",
                          n_scored=0, n_degenerate=1)
        return failed(f"no consensus (the fit on the consistent set of {clique.size} matches: {inner.status})")
    # Howard's re-gating under the fit, then the shared end (refinement, post-condition) of every method
    residual_model = ReprojectionResidual(threshold_sq)
    inliers = residual_model.squared(problem, R[None], t[None])[0] < threshold_sq
    checks += n
    return final_report(
        problem, R, t, inliers, float(np.count_nonzero(inliers)), refiner, residual_model, InlierCount(),
        threshold_sq, max(min_inliers, SAMPLE_SIZE), counters, n_point_checks=checks, **counts,
    )


@register_estimator(
    "inlier-detection",
    "maximum clique of rigid-distance-consistent matches (depth-aware), fit on it, reprojection re-gating",
    "Hirschmueller et al. 2002; Howard 2008",
    extra_options={
        "clique_c": Number(low=0.0, high=1e6, low_open=True, default=3.0),
        "clique_exact_max": Integer(low=0, high=MAX_COUNT, default=60),
        "clique_time_limit_s": Number(low=0.0, high=1e6, low_open=True, unit="s", default=0.5),
        "clique_graph_max": Integer(low=SAMPLE_SIZE, high=20_000, default=GRAPH_MAX),  # 20,000: a 400 MB graph at most
    },
    # the fit's RANSAC reads gate_probability and confidence, with its own cap, batches and minimal fits;
    # Howard's reprojection fit is the last step unless refine adds the LM refinement, so
    # least_squares_refit has no role; no hypothesis loop, so no budget, local refit nor runner-up
    reads=OptionReads(judge="clique", refinement="lm-only", stop="clique-fit", batches="none", local="none"),
)
def _run_inlier_detection(problem, options, priors, order, extra, rng):
    if priors is not None or order is not None:
        raise ValueError(
            "method 'inlier-detection' does not sample hypotheses: priors= and order= have no role in it; pass neither"
        )
    return detect_inliers(
        problem,
        options.reprojection_threshold_sq,
        min_inliers=int(options.min_inliers),
        # Howard's own last step is the reprojection fit on the clique; the LM refinement is an enhancement
        refiner=final_refiner(options) if options.refine else None,
        c=float(extra["clique_c"]),
        exact_max=extra["clique_exact_max"],
        time_limit_s=float(extra["clique_time_limit_s"]),
        rng=rng,
        graph_max=extra["clique_graph_max"],
        gate_sq=options.mahalanobis_threshold_sq,
        confidence=options.confidence,
    )
