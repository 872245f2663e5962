"""One frame's in-frame search, steered batch by batch: what the adaptive environment and
:class:`agents.LearnedEstimator` both run.

:class:`InFrameSearch` holds the shared loop of one frame pair
(:class:`stereovo.estimation.loop.RansacSearch`, the method's judge under a fixed cap) with a
sampler that draws from the caller's priors and records every verified hypothesis
(:class:`AgentPriorSampler`). The caller reads :meth:`InFrameSearch.observation` (the frame
features plus the loop's evidence per correspondence, and the global loop state), answers with
logits and a stop flag (:meth:`InFrameSearch.step`), and ends the frame with
:meth:`InFrameSearch.finish`: the hypothesis with the largest belief-weighted support
``sum_i w_i [i inlier]`` under the last answer's weights ``w = softmax(logits)`` is refined and
reported. No ground truth is read anywhere here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from stereovo.estimation import EstimatorOptions, StereoProblem
from stereovo.estimation.loop import LoopState, RansacSearch
from stereovo.estimation.api import MotionEstimate
from stereovo.estimation.registry import MethodSpec
from stereovo.estimation.kernels.beliefs import numpy_sum
from stereovo.estimation.methods.bansac import WeightedDraw
from stereovo.estimation.roles.termination import FixedBudget
from vo_gym.action_box import exp_shifted
from vo_gym.features import FEATURE_BOUND, FEATURE_NAMES, N_FEATURES

__all__ = [
    "LOOP_FEATURE_NAMES", "GLOBAL_FEATURE_NAMES", "ADAPTIVE_FEATURE_NAMES", "AgentPriorSampler", "InFrameSearch",
]

LOOP_FEATURE_NAMES: tuple[str, ...] = ("best_residual", "vote_fraction", "log_votes", "in_best")
"""Per-correspondence columns appended to the frame features (:data:`vo_gym.features.FEATURE_NAMES`):

- ``best_residual``: ``log(1 + e^2 / T^2)`` of the match's squared residual ``e^2`` under the current
  best model, ``T^2`` the estimator's gate (0 before the first hypothesis; the bound where the
  judge gives a row no residual: a row without depth under a 3-D judge);
- ``vote_fraction``: share of the frame's scored hypotheses that counted it an inlier;
- ``log_votes``: ``log(1 + count)`` of the same;
- ``in_best``: 1 if it is in the current best model's consensus."""

ADAPTIVE_FEATURE_NAMES: tuple[str, ...] = FEATURE_NAMES + LOOP_FEATURE_NAMES

GLOBAL_FEATURE_NAMES: tuple[str, ...] = (
    "spent", "best_support", "scored_any", "best_cv_rotation", "best_cv_translation", "cv_available", "weighted_best",
)
"""The ``globals`` vector: hypotheses spent / cap; the best model's support / N; 1 once a hypothesis
was scored; ``log(1 + angle / 0.1 deg)`` and ``log(1 + |dt| / 5 cm)`` of the best model's motion against
the previous frame's (constant-velocity prediction; 0 without one); 1 when a previous motion is known;
the belief-weighted support of the hypothesis the frame would end on now, under the last action."""


_LOG1P_COUNTS = np.log1p(np.arange(65, dtype=np.float64))  # grown by observation_rows when a frame scores more


def observation_rows(features: np.ndarray, best_column: np.ndarray | None, best_inliers: np.ndarray,
                     votes: np.ndarray, scored: int, rows: int) -> np.ndarray:
    """The observation's ``(rows, F + 4)`` float32 block (:meth:`InFrameSearch.observation`): the frame
    features ``(N, F)``, then :data:`LOOP_FEATURE_NAMES` from ``best_column`` (``log1p(e^2 / T^2)``
    under the best model, None before the first one, when it and ``in_best`` are 0), ``best_inliers``
    ``(N,)`` bool and ``votes`` ``(N,)`` int64 of ``scored`` hypotheses, clipped to the bound; rows past
    N are 0.

    One compiled pass instead of a dozen numpy calls on ``(N, 4)`` and ``(N, 18)`` arrays, the values
    numpy's: the vote share is the same float64 quotient, ``log1p`` of a count is read from a table
    numpy computed (counts are integers up to ``scored``), the clip compares as ``np.maximum`` /
    ``np.minimum`` do and the float32 casts round alike (``tests/vo_gym/test_in_frame.py``).
    """
    global _LOG1P_COUNTS
    if scored >= _LOG1P_COUNTS.shape[0]:
        _LOG1P_COUNTS = np.log1p(np.arange(max(scored + 1, 2 * _LOG1P_COUNTS.shape[0]), dtype=np.float64))
    n = features.shape[0]
    has_best = best_column is not None
    column = best_column if has_best else np.zeros(n)
    inliers = best_inliers if has_best else np.zeros(n, dtype=bool)
    # the first n rows are all written below (by the kernel or numpy's columns): only the padding is zeroed
    out = np.empty((rows, features.shape[1] + len(LOOP_FEATURE_NAMES)), dtype=np.float32)
    out[n:] = 0.0
    if not _observation_rows(out, features, column, inliers, votes, scored, _LOG1P_COUNTS, FEATURE_BOUND):
        # a count outside the table (no search's: a row votes at most once a hypothesis): numpy's columns
        loop = np.zeros((n, len(LOOP_FEATURE_NAMES)), dtype=np.float64)
        if has_best:
            loop[:, 0] = best_column
            loop[:, 3] = best_inliers
        loop[:, 1] = votes / max(scored, 1)
        loop[:, 2] = np.log1p(votes)
        out[:n, : features.shape[1]] = features
        out[:n, features.shape[1]:] = np.minimum(np.maximum(loop, -FEATURE_BOUND, out=loop), FEATURE_BOUND, out=loop)
    return out


@njit(cache=True, nogil=True)
def _observation_rows(out, features, best_column, best_inliers, votes, scored, log1p_counts, bound):
    """In place into ``out``'s first N rows (see :func:`observation_rows`); False, with ``out``
    unfinished, when a count lies outside ``log1p_counts``."""
    n, f = features.shape
    for i in range(n):
        if not 0 <= votes[i] < log1p_counts.shape[0]:
            return False
    share = float(max(scored, 1))
    for i in range(n):
        for j in range(f):
            out[i, j] = features[i, j]
        loop = (best_column[i], votes[i] / share, log1p_counts[votes[i]], 1.0 if best_inliers[i] else 0.0)
        for j in range(4):
            x = loop[j]
            if x < -bound:  # np.maximum(x, -bound): NaN stays NaN
                x = -bound
            if x > bound:
                x = bound
            out[i, f + j] = np.float32(x)
    return True


@njit(cache=True, nogil=True)
def _global_row(out, drawn, max_hypotheses, best_inliers, scored, has_previous, cv_rotation, cv_translation,
                weighted, bound):
    """:data:`GLOBAL_FEATURE_NAMES` into ``out (7,)`` float32 from the loop's state and the floats the
    caller computed, as the float64 row numpy clipped (``np.maximum`` / ``np.minimum``: NaN stays NaN)
    and cast: the quotients of integers are the same float64 quotients as Python's."""
    best = 0
    for i in range(best_inliers.shape[0]):
        if best_inliers[i]:
            best += 1
    row = (drawn / max_hypotheses, best / best_inliers.shape[0], 1.0 if scored > 0 else 0.0, cv_rotation,
           cv_translation, 1.0 if has_previous else 0.0, weighted)
    for j in range(7):
        x = row[j]
        if x < -bound:
            x = -bound
        if x > bound:
            x = bound
        out[j] = np.float32(x)


MASK_ROWS_START = 16  # rows of a frame's mask buffers at first (doubled when a frame scores more)


class AgentPriorSampler:
    """The loop's sampler of an in-frame search: guided draws from the caller's current priors; the
    feedback hook records every verified hypothesis of the frame for the observation and the final
    selection."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.weights = np.full(n, 1.0 / n)
        self._sampler: WeightedDraw | None = None  # built on the first draw (the search sets weights first)
        self.votes = np.zeros(n, dtype=np.int64)
        # every scored hypothesis' inlier mask, in order (rows [0, scored)), and the same as 0.0 / 1.0:
        # select() reads them each step, and numpy's product of the bool masks casts them so first
        # (rows past `scored` are never read: uninitialised; 16 rows, since a larger buffer of float64
        # comes from fresh pages on every frame)
        self._all_masks = np.empty((MASK_ROWS_START, n), dtype=bool)
        self._all_masks_f64 = np.empty((MASK_ROWS_START, n))
        self._scored = 0
        self.R: list[np.ndarray] = []
        self.t: list[np.ndarray] = []
        self.samples: list[np.ndarray] = []
        self.last_samples = np.zeros((0, 3), dtype=np.int64)
        self.last_masks = np.zeros((0, n), dtype=bool)
        self.last_residuals: np.ndarray | None = None  # (H, N) squared residuals of the last batch

    def set_weights(self, weights: np.ndarray, draw: WeightedDraw | None = None) -> None:
        """``weights (N,)``: a softmax of bounded logits (all positive and normal), so the draw skips
        ``WeightedSampler``'s validation and gives its samples (:class:`WeightedDraw`); ``draw``, when
        given, is ``WeightedDraw(weights)`` built by the caller (:func:`normalised_priors`)."""
        self.weights = weights
        self._sampler = WeightedDraw(weights) if draw is None else draw

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        if self._sampler is None:
            self._sampler = WeightedDraw(self.weights)
        return self._sampler.draw(batch, rng)

    def on_hypotheses(self, R, t, inlier_masks, residual_sq, state: LoopState) -> None:
        self.R.append(R)
        self.t.append(t)
        self.samples.append(state.samples)
        self.last_samples, self.last_masks = state.samples, inlier_masks
        self.last_residuals = residual_sq
        end = self._scored + inlier_masks.shape[0]
        if end > self._all_masks.shape[0]:
            grown = np.empty((max(2 * self._all_masks.shape[0], end), self.n), dtype=bool)
            grown[: self._scored] = self._all_masks[: self._scored]
            self._all_masks = grown
            grown_f64 = np.empty(grown.shape)
            grown_f64[: self._scored] = self._all_masks_f64[: self._scored]
            self._all_masks_f64 = grown_f64
        if inlier_masks.dtype == np.bool_ and inlier_masks.ndim == 2 and inlier_masks.shape[1] == self.n:
            # the votes (np.count_nonzero(masks, axis=0)) and the masks' copies in one compiled pass
            _record_masks(inlier_masks, self.votes, self._all_masks, self._all_masks_f64, self._scored)
        else:
            self.votes += np.count_nonzero(inlier_masks, axis=0)
            self._all_masks[self._scored:end] = inlier_masks
            self._all_masks_f64[self._scored:end] = self._all_masks[self._scored:end]
        self._scored = end

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        w = self.weights / self.weights.sum()
        inside = float(w[inliers].sum())
        return inside**3

    def n_scored(self) -> int:
        return self._scored

    @property
    def scored_masks(self) -> np.ndarray:
        """``(H, N)`` bool, the inlier masks of every hypothesis scored in this frame, in order."""
        return self._all_masks[: self._scored]

    def select(self, weights: np.ndarray) -> int | None:
        """Index of the scored hypothesis with the largest ``weights``-weighted support (``argmax`` of
        ``scored_masks @ weights``: the float64 copy of the masks is what numpy's product would cast them
        to, so the same BLAS product)."""
        if not self._scored:
            return None
        return int(np.argmax(self._all_masks_f64[: self._scored] @ weights))

    def hypothesis(self, h: int) -> tuple[np.ndarray, np.ndarray]:
        """Copies of scored hypothesis ``h``'s ``R (3, 3)`` and ``t (3,)`` (``np.concatenate(self.R)[h]``
        without joining the batches)."""
        for R, t in zip(self.R, self.t):
            if h < R.shape[0]:
                return R[h].copy(), t[h].copy()
            h -= R.shape[0]
        raise IndexError("no such scored hypothesis")

    def weighted_support(self, h: int, weights: np.ndarray) -> float:
        """``scored_masks[h] @ weights``: hypothesis ``h``'s ``weights``-weighted support (as :meth:`select`)."""
        return float(self._all_masks_f64[h] @ weights)


@njit(cache=True, nogil=True)
def _record_masks(masks, votes, all_masks, all_masks_f64, start):
    """``votes += masks.sum(0)`` and ``all_masks[start:start + H] = masks`` (bool and float64) for
    ``masks (H, N)`` bool."""
    for h in range(masks.shape[0]):
        for i in range(masks.shape[1]):
            m = masks[h, i]
            all_masks[start + h, i] = m
            all_masks_f64[start + h, i] = 1.0 if m else 0.0
            if m:
                votes[i] += 1


def normalised_priors(weights: np.ndarray) -> WeightedDraw:
    """``weights /= weights.sum()`` in place for a contiguous float64 ``weights (N,)`` of positive
    normal values (numpy's pairwise sum and quotients), and ``WeightedDraw(weights)``'s tables of the
    result, in one compiled pass: the same weights and draw as the two numpy calls and the class."""
    tables = np.empty((3, weights.shape[0]))
    _normalised_tables(weights, tables)
    return WeightedDraw.from_arrays(tables[0], tables[1], tables[2])


@njit(cache=True, nogil=True, error_model="numpy")
def _normalised_tables(weights, tables):
    """``weights /= sum`` in place, then rows ``(w, cdf, before)`` of ``tables (3, N)`` as
    :class:`WeightedDraw` builds them (``w = weights / sum(weights)``, its running sums)."""
    n = weights.shape[0]
    total = numpy_sum(weights)
    for i in range(n):
        weights[i] = weights[i] / total
    total = numpy_sum(weights)
    running = 0.0
    for i in range(n):
        w = weights[i] / total
        tables[0, i] = w
        tables[2, i] = running
        running += w
        tables[1, i] = running


class InFrameSearch:
    """The search of one frame pair, stepped by the caller's logits and stop (module doc).

    Args:
        problem: the frame's :class:`StereoProblem` (every row usable: the caller restricts a frame
            with rows without depth to its usable sub-problem first).
        features: ``(N, N_FEATURES)`` frame features of the same rows (:func:`vo_gym.features.compute_features`).
        spec: the judging method's :class:`MethodSpec` (``method_spec("msac")`` in the environment).
        options: its :class:`EstimatorOptions`; their stopping rule is replaced by the caller's stop
            under the cap ``max_hypotheses``.
        previous_motion: ``(R, t)`` of the previous frame pair (the constant-velocity prediction the
            globals compare the best model with), None if unknown.
        rng: the generator of the loop's draws.
        extra: the method's own options (validated, :func:`stereovo.estimation.validate_options`).
    """

    def __init__(self, problem: StereoProblem, features: np.ndarray, spec: MethodSpec, options: EstimatorOptions,
                 max_hypotheses: int, previous_motion: tuple[np.ndarray, np.ndarray] | None,
                 rng: np.random.Generator, extra: dict | None = None) -> None:
        self.problem, self.features, self.max_hypotheses = problem, features, int(max_hypotheses)
        self.previous_motion = previous_motion
        components = spec.build(problem, options, None, None, dict(extra or {}))
        self.sampler = components.sampler = AgentPriorSampler(problem.n)
        components.termination = FixedBudget(self.max_hypotheses)
        # the caller decides when to stop: no stopping rule of the method listens in
        components.listeners = [x for x in components.listeners if not hasattr(x, "required")]
        self.search = RansacSearch(problem, components, rng)
        self.best_residual: np.ndarray | None = None
        self._best_column: tuple[np.ndarray | None, np.ndarray | None] = (None, None)  # (residual, its column)
        self._best_distance: tuple = (None, None, 0.0, 0.0)  # (best_R, best_t, globals 3 and 4 of them)
        self.weights = np.full(problem.n, 1.0 / problem.n)
        # a stopping step's empty batch, shared by the frame's steps (an empty array holds nothing to change)
        self._no_samples, self._no_masks = np.zeros((0, 3), dtype=np.int64), np.zeros((0, problem.n), bool)

    @property
    def drawn(self) -> int:
        """Hypotheses drawn so far in this frame."""
        return self.search.drawn

    @property
    def scored_inliers(self) -> np.ndarray:
        """``(H, N)`` bool inlier masks of the scored hypotheses, in drawing order."""
        return self.sampler.scored_masks.copy()

    def step(self, logits: np.ndarray, stop: bool, batch_size: int) -> tuple[int, bool, bool]:
        """Set the priors ``softmax(logits)`` (``(N,)`` finite) and draw a batch unless ``stop``.

        A stop before any scored hypothesis is ignored; the batch is cut at the cap.

        Returns:
            ``(drawn in this step, stopped, done)``: ``done`` when the caller stopped or the cap is reached.
        """
        draw = None
        if type(logits) is np.ndarray and logits.dtype == np.float64 and logits.ndim == 1 and logits.shape[0]:
            weights = exp_shifted(logits)  # np.exp(logits - logits.max()) in one pass and numpy's exp
            draw = normalised_priors(weights)  # weights /= weights.sum() and the draw's tables
        else:  # e.g. an agent's float32 logits: numpy's float32 arithmetic
            weights = np.exp(logits - logits.max())
            weights /= weights.sum()
        self.weights = weights
        search, sampler = self.search, self.sampler
        drawn = 0
        stopping = bool(stop) and search.scored > 0
        sampler.last_samples, sampler.last_masks = self._no_samples, self._no_masks
        if not stopping:
            batch = min(int(batch_size), self.max_hypotheses - search.drawn)
            sampler.set_weights(weights, draw)
            before = search.best_score
            search.step(batch)
            drawn = batch
            if search.best_score != before:
                self.best_residual = self._best_residuals()
        return drawn, stopping, stopping or search.drawn >= self.max_hypotheses

    def _best_residuals(self) -> np.ndarray:
        """``(N,)`` squared residuals of the loop's best model: the batch's row when the best is a
        hypothesis of the last batch as it was scored (same bytes; the loop's residuals of a batch are
        each hypothesis' own, bit for bit), else computed."""
        search, sampler = self.search, self.sampler
        R, t, residual_sq = sampler.R[-1], sampler.t[-1], sampler.last_residuals
        if residual_sq is not None and residual_sq.shape == (R.shape[0], self.problem.n):
            best_R, best_t = search.best_R.tobytes(), search.best_t.tobytes()
            for i in range(R.shape[0]):
                if R[i].tobytes() == best_R and t[i].tobytes() == best_t:
                    return residual_sq[i]
        return search.ctx.residuals(search.best_R[None], search.best_t[None])[0]

    def finish(self, method: str) -> MotionEstimate:
        """Select the hypothesis of largest belief-weighted support, refine it, report it (``time_s`` 0)."""
        search, sampler = self.search, self.sampler
        chosen = sampler.select(self.weights)
        if chosen is not None:
            masks = sampler.scored_masks
            R, t = sampler.hypothesis(chosen)
            search.choose(R, t, masks[chosen].copy(), float(np.count_nonzero(masks[chosen])))
        return MotionEstimate.from_report(search.finish(), method, 0.0)

    def all_samples(self) -> np.ndarray:
        """``(H, 3)`` every minimal sample scored in this frame, in drawing order."""
        return np.concatenate(self.sampler.samples) if self.sampler.samples else np.zeros((0, 3), dtype=np.int64)

    def observation(self, max_correspondences: int | None = None) -> dict[str, np.ndarray]:
        """``{"features" (M, F + 4), "mask" (M,), "globals" (7,)}``, float32 / int8, rows past N padded with 0.

        ``M`` is ``max_correspondences`` (default N); layout :data:`ADAPTIVE_FEATURE_NAMES` and
        :data:`GLOBAL_FEATURE_NAMES`, every value clipped to ``[-FEATURE_BOUND, FEATURE_BOUND]``.
        """
        search, sampler = self.search, self.sampler
        n = self.problem.n
        M = n if max_correspondences is None else int(max_correspondences)
        scored = sampler.n_scored()
        best_column = None
        if self.best_residual is not None:
            # the best model's column changes only with the best model: kept for the steps between
            if self._best_column[0] is not self.best_residual:
                # a row without depth has no residual under the 3-D judges (NaN): no fit, so the bound
                residual = np.where(np.isnan(self.best_residual), np.inf, self.best_residual)
                self._best_column = (self.best_residual, np.log1p(residual / search.components.threshold_sq))
            best_column = self._best_column[1]
        features = observation_rows(self.features, best_column, search.best_inliers, sampler.votes, scored, M)
        mask = np.ones(M, dtype=np.int8)
        mask[n:] = 0
        has_previous = self.previous_motion is not None
        cv_rotation = cv_translation = weighted = 0.0
        if has_previous and scored:
            # the best model's distance from the prediction changes only with the best model (the
            # loop replaces best_R and best_t, never writes into them): kept for the steps between
            if self._best_distance[0] is not search.best_R or self._best_distance[1] is not search.best_t:
                R_prev, t_prev = self.previous_motion
                # np.trace adds the diagonal left to right; np.linalg.norm of a vector is sqrt(x.dot(x))
                (d0, _, _), (_, d1, _), (_, _, d2) = (search.best_R @ R_prev.T).tolist()
                cos = (((d0 + d1) + d2) - 1) / 2
                dt = search.best_t - t_prev
                self._best_distance = (search.best_R, search.best_t,
                                       math.log1p(math.degrees(math.acos(min(max(cos, -1.0), 1.0))) / 0.1),
                                       math.log1p(math.sqrt(float(dt.dot(dt))) / 0.05))
            cv_rotation, cv_translation = self._best_distance[2], self._best_distance[3]
        chosen = sampler.select(self.weights)
        if chosen is not None:
            weighted = sampler.weighted_support(chosen, self.weights)
        g = np.empty(len(GLOBAL_FEATURE_NAMES), dtype=np.float32)
        _global_row(g, search.drawn, self.max_hypotheses, search.best_inliers, scored, has_previous, cv_rotation,
                    cv_translation, weighted, FEATURE_BOUND)
        return {"features": features, "mask": mask, "globals": g}
