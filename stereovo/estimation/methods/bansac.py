"""BANSAC (Piedade & Miraldo, "BANSAC: A dynamic BAyesian Network for adaptive SAmple Consensus",
ICCV 2023): per-correspondence inlier beliefs updated after every hypothesis, sampled from, and a
stopping rule built from them. Methods ``bansac`` and ``p-bansac`` (the paper's two variants), as a
sampler and a termination of the shared loop.

**The paper's update** (as the authors' released OpenCV implementation computes it). Every point i
carries two unnormalised state weights, ``phi_in`` and ``phi_out`` (initially ``prior_i`` and
``1 - prior_i``; ``prior_i = 0.5`` without priors). After iteration t, take that iteration's best
hypothesis (one per minimal sample here: the 3-point fit has one solution) with inlier ratio
``r = inliers / N`` and set the classification-table parameter

    c = 0.62 r + 0.5      if r < 0.7143,
    c = 0.2 r + 0.8       otherwise;

then, for every point (the sample's own points included: the paper treats them like any other),

    residual under the gate:  phi_in <- c phi_in + 0.2 (1 - c) phi_out,   phi_out <- 0.8 (1 - c) phi_out
    otherwise:                phi_in <- (1 - c) phi_in,                   phi_out <- c phi_out

and the belief is ``p_i = phi_in / (phi_in + phi_out)``. Hypotheses that are never scored (a
degenerate sample, one the rigidity check drops) update nothing, as an iteration without a model
updates nothing in the paper. The update is linear in ``(phi_in, phi_out)``, so rescaling a point's
pair leaves every later belief unchanged; this module keeps the pair normalised, as the log-odds
``log(phi_in / phi_out)``, so no run is long enough to underflow (the released code keeps raw
single-precision products, which reach zero after a few hundred iterations).

**Sampling**: weights ``ceil(100 p_i)`` (the released code's discretisation: a sure inlier has 100
times the weight of a point the beliefs have all but ruled out, which keeps weight 1); three
distinct points per sample, drawn one after another in proportion to the weights (the released
code draws from a pool of copies and can draw a point twice, which gives a degenerate sample).
The project's option ``bansac_weights="belief"`` samples in proportion to ``p`` itself instead (no
1/100 floor for the points the beliefs have ruled out); not the paper.

**Stopping rule**: count the points with ``p_i < tau`` (``tau`` 0.01 for BANSAC, 0.1 for
P-BANSAC); stop once that count reaches ``N (1 - best inlier ratio so far)``, the outliers the best
model implies. As in the released code the usual adaptive RANSAC bound also applies (for uniform
sampling, from the best support: the paper's code keeps OpenCV's SPRT-based bound), and so does the
``max_iterations`` cap.

**Hypotheses per batch.** The paper draws, fits and updates one hypothesis at a time, which is the
methods' default (``bansac_batch``: :data:`PAPER_BATCH`). With larger batches each hypothesis' update is applied in the
order drawn, the next batch is drawn from the updated beliefs and the stop is checked per batch.

**The compiled search.** With one hypothesis per update the loop's bookkeeping per batch costs more
than the hypothesis; :func:`compiled_bansac_search` (the components' ``search_runner``, taken
wherever :func:`compiled_search_applies`) runs the steps in one numba loop instead
(:mod:`stereovo.estimation.kernels.bansac_runner`) and returns to the loop's own objects only for a
new best (its local refit and bound) or a runner-up refit: the same estimates, counters, beliefs and
generator state as the loop, bit for bit (``tests/stereovo/estimation/methods/test_bansac_runner.py``).
:data:`COMPILED_SEARCH` False runs the loop's steps, the reference.

**Priors** are the initial beliefs when they lie in [0, 1] (the paper's input); larger weights are
first divided by their maximum (the project's priors are weights of any scale). Either way they are
clipped into ``[1e-4, 1 - 1e-4]``: a prior of exactly 1 would make a point an inlier for good.
``prior_ceiling`` (the project's option) instead scales them so the largest is that belief.

**The project's variant** ``bansac_update="verdict-likelihood"`` (not the paper): a Bayesian reading
of a hypothesis' verdicts. The hypothesis is correct with ``delta = prod_{j in S} p_j``; if correct
it calls an outlier an outlier and finds an inlier with chance ``rho`` (``bansac_recall``), if not it
calls any point an inlier with chance ``r``. Bayes' rule with ``P(in | inlier) = delta rho + (1 -
delta) r`` and ``P(in | outlier) = (1 - delta) r`` (complements for "out") updates every point but
the sample's own three; beliefs are clipped to ``[1e-4, 1 - 1e-4]``; sampling is proportional to the
beliefs, in batches of :data:`FEEDBACK_BATCH`; the stop is reached once, under the current beliefs, an
all-inlier sample was drawn with ``confidence``: ``1 - prod_t (1 - prod_{j in S_t} p_j) >= confidence``. Priors are
scaled so the largest is ``prior_ceiling`` (:data:`PRIOR_CEILING` by default).

This module also declares the belief and ``bansac_*`` options and registers ``bansac`` and ``p-bansac``.
It runs past 600 lines because the paper's sampler and stop, the glue of their compiled search
(:mod:`stereovo.estimation.kernels.bansac_runner`) and the project's verdict-likelihood variant share
these options and one builder; splitting them would make the modules import each other.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from stereovo.estimation.estimator_options import EstimatorOptions, OptionReads
from stereovo.estimation.kernels import bansac_runner as runner_kernels
from stereovo.estimation.kernels import beliefs as belief_kernels
from stereovo.estimation.kernels.mahalanobis import point_columns
from stereovo.estimation.kernels.sampling import weighted_triplets
from stereovo.estimation.loop import LoopState, RansacComponents, RansacSearch, local_refit_redundant
from stereovo.estimation.registry import declare_options, method_spec, register_method
from stereovo.estimation.roles.local_optimization import ConsensusRefit
from stereovo.estimation.roles.sample_check import RigidityCheck
from stereovo.estimation.roles.samplers import WeightedSampler
from stereovo.estimation.roles.scoring import InlierCount, MahalanobisResidual
from stereovo.estimation.roles.solvers import DEGENERATE_AREA_RATIO, SAMPLE_SIZE
from stereovo.estimation.roles.termination import AdaptiveTermination
from stereovo.estimation.roles.verification import FullVerification
from stereovo.options import Choice, Integer, Number

BELIEF_FLOOR = 1e-4
BANSAC_THRESHOLD = 0.01  # tau of BANSAC's stop
P_BANSAC_THRESHOLD = 0.1  # tau of P-BANSAC's stop
TABLE_KNEE = 0.7143  # the inlier ratio where the classification table's parameter changes slope
WEIGHT_LEVELS = 100  # sampling weights ceil(100 p): the released code's discretisation
PAPER_BATCH = 1  # hypotheses per batch of the paper's methods: one update per hypothesis
WEIGHTINGS = ("discretised", "belief")  # sampling weights ceil(100 p) (the paper's), or p (the project's option)
WEIGHT_FLOOR = 1e-12  # "belief" weights: a belief that underflowed to 0 can still be drawn
# c = 1 (every point an inlier, r = 1) would send every log-odds to +inf; one part in 1e12 below keeps them finite.
C_MAX = 1.0 - 1e-12
LOG_GATED_IN, LOG_GATED_OUT = math.log(0.2), math.log(0.8)  # the table's split of a gated point's outlier weight

DEFAULT_RECALL = 0.5
# the largest prior's belief: near 1 the verdict-likelihood beliefs lock onto the first consensus
# (docs/algorithms.md, "Measurements behind the code")
PRIOR_CEILING = 0.6
FEEDBACK_BATCH = 4  # hypotheses per batch of the verdict-likelihood variant: the beliefs move between batches


# ----------------------------------------------------------------------------- the paper's update


def classification_parameter(inlier_ratio: float) -> float:
    """The paper's classification-table parameter ``c`` for a hypothesis of inlier ratio ``r`` in [0, 1]."""
    r = float(inlier_ratio)
    return 0.62 * r + 0.5 if r < TABLE_KNEE else 0.2 * r + 0.8


def phi_update(phi_in: np.ndarray, phi_out: np.ndarray, verdicts: np.ndarray, inlier_ratio: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """One iteration's update of the unnormalised state weights (module docstring), as written.

    Args:
        phi_in, phi_out: ``(N,)`` state weights of "inlier" and "outlier".
        verdicts: ``(N,)`` bool, residual under the gate for the iteration's best hypothesis.
        inlier_ratio: that hypothesis' inliers / N.
    Returns:
        the new ``(phi_in, phi_out)``; the beliefs are ``phi_in / (phi_in + phi_out)``.
    """
    c = classification_parameter(inlier_ratio)
    phi_in, phi_out = np.asarray(phi_in, float), np.asarray(phi_out, float)
    new_in = np.where(verdicts, c * phi_in + 0.2 * (1 - c) * phi_out, (1 - c) * phi_in)
    new_out = np.where(verdicts, 0.8 * (1 - c) * phi_out, c * phi_out)
    return new_in, new_out


def log_odds_update(log_odds: np.ndarray, verdicts: np.ndarray, inlier_ratio: float) -> np.ndarray:
    """:func:`phi_update` on ``log(phi_in / phi_out) (N,)``: the same beliefs, never underflowing."""
    c = min(classification_parameter(inlier_ratio), C_MAX)
    log_c, log_1mc = math.log(c), math.log1p(-c)
    gated_in = np.logaddexp(log_c + log_odds, math.log(0.2) + log_1mc) - (math.log(0.8) + log_1mc)
    return np.where(verdicts, gated_in, log_odds + (log_1mc - log_c))


def prior_beliefs(n: int, priors: np.ndarray | None, initial_probability: float,
                  prior_ceiling: float | None) -> np.ndarray:
    """``(n,)`` initial beliefs: the constant without priors; priors as probabilities (divided by
    their maximum if it exceeds 1), or scaled to a maximum of ``prior_ceiling`` if given; clipped
    into ``[BELIEF_FLOOR, 1 - BELIEF_FLOOR]``."""
    if priors is None:
        return np.full(n, float(initial_probability))
    w = np.asarray(priors, dtype=float)
    top = float(w.max())
    if prior_ceiling is not None:
        w = prior_ceiling * w / top
    elif top > 1:
        w = w / top
    return np.clip(w, BELIEF_FLOOR, 1 - BELIEF_FLOOR)


class BansacSampler:
    """The paper's beliefs, sampling weights and stop count (module docstring).

    The update, the weights and their cumulative sums are compiled
    (:mod:`stereovo.estimation.kernels.beliefs`) and kept between draws: the numpy formulation
    (:func:`log_odds_update`, then a fresh :class:`~stereovo.estimation.roles.samplers.WeightedSampler`
    per hypothesis) gives the same draws bit for bit at several times the cost.

    Attributes:
        log_odds: ``(N,)`` ``log(phi_in / phi_out)`` per point.
        threshold: ``tau`` of the stopping rule.
        updates: hypotheses applied so far.
        best_inliers_seen: the largest inlier count of any hypothesis applied (the stop's best
            support when the caller's loop state carries no best consensus).
    """

    def __init__(self, n: int, priors: np.ndarray | None = None, threshold: float = BANSAC_THRESHOLD,
                 initial_probability: float = 0.5, prior_ceiling: float | None = None,
                 weights: str = "discretised") -> None:
        if n < SAMPLE_SIZE:
            raise ValueError(f"need at least {SAMPLE_SIZE} correspondences to sample, got {n}")
        for name, value in (("threshold", threshold), ("initial_probability", initial_probability),
                            ("prior_ceiling", 0.5 if prior_ceiling is None else prior_ceiling)):
            if not 0 < value < 1:
                raise ValueError(f"BansacSampler: {name} must be in (0, 1), got {value!r}")
        if weights not in WEIGHTINGS:
            raise ValueError(f"BansacSampler: weights must be one of {WEIGHTINGS}, got {weights!r}")
        self.n, self.threshold, self.weighting = n, float(threshold), weights
        p = prior_beliefs(n, priors, initial_probability, prior_ceiling)
        self.log_odds = np.ascontiguousarray(np.log(p) - np.log1p(-p))
        self._outlier_log_odds = math.log(self.threshold) - math.log1p(-self.threshold)
        self.updates = self.best_inliers_seen = 0
        self.best_support = 0  # the best consensus' size at the latest update
        self._arrays: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def beliefs(self) -> np.ndarray:
        """``(N,)`` inlier beliefs ``phi_in / (phi_in + phi_out)``."""
        return belief_kernels.logistic_beliefs(self.log_odds)  # the logistic, without overflow at large |log-odds|

    @property
    def sampling_weights(self) -> np.ndarray:
        """``(N,)`` ``ceil(100 p)``, at least 1 (the paper's); ``p`` with ``weights="belief"``."""
        return self._draw_arrays()[0]

    def _draw_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The weights, and what the weighted draw inverts: the weights over their sum (every weight
        is >= 1e-12, so that is :func:`~stereovo.estimation.roles.samplers.normalised_weights`' direct
        quotient) and its inclusive and exclusive cumulative sums; kept until the next update."""
        if self._arrays is None:
            self._arrays = belief_kernels.bansac_draw_arrays(
                self.log_odds, self.weighting == "discretised", float(WEIGHT_LEVELS), WEIGHT_FLOOR
            )
        return self._arrays

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        return WeightedDraw.from_arrays(*self._draw_arrays()[1:]).draw(batch, rng)

    def apply(self, verdicts: np.ndarray) -> None:
        """One hypothesis' update from its ``(N,)`` bool inlier mask."""
        self._apply(np.ascontiguousarray(verdicts, dtype=bool))

    def _apply(self, verdicts: np.ndarray) -> None:
        k = int(np.count_nonzero(verdicts))
        c = min(classification_parameter(k / self.n), C_MAX)
        log_c, log_1mc = math.log(c), math.log1p(-c)
        belief_kernels.bansac_log_odds_update(
            self.log_odds, verdicts, log_c, LOG_GATED_IN + log_1mc, LOG_GATED_OUT + log_1mc, log_1mc - log_c
        )
        self.best_inliers_seen = max(self.best_inliers_seen, k)
        self.updates += 1
        self._arrays = None

    def on_hypotheses(self, R, t, inlier_masks: np.ndarray, residual_sq, state: LoopState) -> None:
        masks = np.ascontiguousarray(inlier_masks, dtype=bool)
        for verdicts in masks:
            self._apply(verdicts)
        best = state.best_inliers
        self.best_support = self.best_inliers_seen if best is None else int(np.count_nonzero(best))

    def outlier_count(self) -> int:
        """Points whose belief is under ``tau``."""
        # p < tau  <=>  log-odds < log(tau / (1 - tau))
        return int(np.count_nonzero(self.log_odds < self._outlier_log_odds))

    def stop_rule_met(self, n_best_inliers: int) -> bool:
        """BANSAC's stop: after at least one update, ``#(p < tau) >= N - n_best_inliers``."""
        return self.updates > 0 and self.outlier_count() >= self.n - int(n_best_inliers)

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        """Chance that one draw from the current weights is three points of ``inliers (N,)`` bool
        (sequential draws without replacement, with the inliers' mean weight removed per draw)."""
        return sequential_all_inlier_probability(self.sampling_weights, inliers)

    def counters(self) -> dict[str, int]:
        return {"bansac_updates": self.updates, "bansac_outlier_beliefs": self.outlier_count()}


class WeightedDraw:
    """:class:`~stereovo.estimation.roles.samplers.WeightedSampler`'s draw for weights that change between
    batches (BANSAC's beliefs, the adaptive environment's agent): the same samples from the same
    generator, without the sampler's validation and with its normalisation compiled.

    Args:
        weights: ``(N,)`` finite weights, each positive and normal (at least
            ``numpy.finfo(float).tiny`` after division by their sum: then ``WeightedSampler`` takes
            the plain quotient ``weights / sum``, computed here in numpy's order); the caller
            guarantees it (this class is for per-batch weights that are valid by construction).
    """

    def __init__(self, weights: np.ndarray) -> None:
        weights = np.ascontiguousarray(weights, dtype=float)
        self.w, self.cdf, self.before = belief_kernels.cumulative_weights(weights, belief_kernels.numpy_sum(weights))

    @classmethod
    def from_arrays(cls, w: np.ndarray, cdf: np.ndarray, before: np.ndarray) -> "WeightedDraw":
        draw = cls.__new__(cls)
        draw.w, draw.cdf, draw.before = w, cdf, before
        return draw

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        """``(batch, 3)`` ordered draws without replacement, P(i) proportional to the weights."""
        u = rng.random((batch, SAMPLE_SIZE))
        samples, suspect = weighted_triplets(u, self.w, self.cdf, self.before)
        if suspect.any():
            for row in np.flatnonzero(suspect):
                samples[row] = exact_weighted_draw(self.w, u[row])
        return samples


def exact_weighted_draw(w: np.ndarray, u: np.ndarray) -> np.ndarray:
    """One ordered draw of three from weights ``w (N,)`` (normalised) and uniforms ``u (3,)``, each
    inverted on the explicitly renormalised weights: the rare fix-up of a draw that rounding put on
    an interval's edge (as :class:`~stereovo.estimation.roles.samplers.WeightedSampler` fixes its own)."""
    w = w.copy()
    picked = np.empty(SAMPLE_SIZE, dtype=np.int64)
    for k in range(SAMPLE_SIZE):
        cdf = np.cumsum(w)
        i = int(np.searchsorted(cdf, u[k] * cdf[-1], side="right"))
        positive = np.flatnonzero(w > 0)
        i = i if i < w.shape[0] and w[i] > 0 else int(positive[np.argmin(np.abs(positive - i))])
        picked[k] = i
        w[i] = 0.0
    return picked


def sequential_all_inlier_probability(w: np.ndarray, inliers: np.ndarray) -> float:
    """Chance that three weighted draws without replacement from ``w (N,)`` all fall in ``inliers``
    (each draw removes the inliers' mean weight)."""
    total, inside = float(w.sum()), float(w[inliers].sum())
    k = int(np.count_nonzero(inliers))
    if k < SAMPLE_SIZE:
        return 0.0
    mean = inside / k
    q = 1.0
    for j in range(SAMPLE_SIZE):
        q *= (inside - j * mean) / (total - j * mean)
    return q


@dataclass
class BansacTermination:
    """BANSAC's stop with the adaptive bound kept (module docstring).

    ``required`` answers 0 once the beliefs' rule is met (the loop then stops), else the bound's
    count; ``max_iterations`` is the bound's cap.
    """

    sampler: BansacSampler
    bound: AdaptiveTermination
    stopped_by_rule: bool = field(default=False, init=False)

    @property
    def max_iterations(self) -> int:
        return self.bound.max_iterations

    def required(self, n_inliers: int, n: int) -> int:
        self.stopped_by_rule = self.sampler.stop_rule_met(n_inliers)
        return 0 if self.stopped_by_rule else self.bound.required(n_inliers, n)

    def counters(self) -> dict[str, int | float]:
        return {**self.bound.counters(), "bansac_stopped_by_rule": int(self.stopped_by_rule)}


# ----------------------------------------------------------------------------- the compiled search


COMPILED_SEARCH = True  # False: the paper's BANSAC steps the shared loop (the reference the runner is held to)
# The classes the compiled search reproduces, bound here: another sampler put in BansacSampler's place
# (the numpy reference the benchmark patches in) is left to the loop.
SEARCHED_SAMPLER, SEARCHED_TERMINATION = BansacSampler, BansacTermination
FIRST_UNIFORM_ROWS = 64  # hypotheses' uniforms drawn per block, doubling up to MAX_UNIFORM_ROWS
MAX_UNIFORM_ROWS = 4096


def compiled_search_applies(c: RansacComponents) -> bool:
    """Whether :func:`compiled_bansac_search` computes exactly what the loop's steps compute for
    ``c``: the paper's sampler in one-hypothesis batches, its termination, the ``probabilistic``
    judge (Mahalanobis count, full verification), with or without the rigidity check, with the
    consensus refit (which draws nothing) or no local optimiser, no listeners."""
    term = c.termination
    return (
        type(c.sampler) is SEARCHED_SAMPLER
        and type(term) is SEARCHED_TERMINATION and term.sampler is c.sampler
        and type(term.bound) is AdaptiveTermination and not term.bound.probability.guided
        and c.batch_size == 1
        and type(c.verifier) is FullVerification
        and type(c.residual_model) is MahalanobisResidual and type(c.quality) is InlierCount and c.threshold_sq > 0
        and (c.sample_check is None or type(c.sample_check) is RigidityCheck)
        and (c.local_optimizer is None or type(c.local_optimizer) is ConsensusRefit)
        and not c.listeners
    )


class _CompiledSearch:
    """One run of :func:`compiled_bansac_search`: the kernel's state arrays beside the search's."""

    def __init__(self, search: RansacSearch) -> None:
        c = self.c = search.components
        self.search, self.sampler, self.term = search, c.sampler, c.termination
        problem = search.problem
        self.n = search.n
        self.state = np.zeros(runner_kernels.STATE_SIZE, dtype=np.int64)
        self.fstate = np.zeros(runner_kernels.FLOAT_STATE_SIZE)
        self.sample = np.zeros(SAMPLE_SIZE, dtype=np.int64)
        self.R, self.t = np.zeros((3, 3)), np.zeros(3)
        self.mask, self.verdicts = np.zeros(self.n, dtype=bool), np.zeros(self.n, dtype=bool)
        runner_up = c.runner_up_fraction if c.local_optimizer is not None else None
        rigidity = 0.0 if c.sample_check is None else float(c.sample_check.threshold_sq)
        discretised = self.sampler.weighting == "discretised"
        draw_arrays = belief_kernels.bansac_draw_arrays(self.sampler.log_odds, discretised, float(WEIGHT_LEVELS),
                                                        WEIGHT_FLOOR)
        level = draw_arrays[0].astype(np.int64)  # each point's weight, where the kernel's search for the next starts
        self.args = (
            discretised, float(WEIGHT_LEVELS), WEIGHT_FLOOR, self.sampler._outlier_log_odds,
            TABLE_KNEE, C_MAX, LOG_GATED_IN, LOG_GATED_OUT,
            problem.points_prev, problem.points_curr, problem.prev, problem.curr, problem.camera.parameters,
            problem.cov_prev, problem.cov_curr, problem.noise_sigma**2, float(c.threshold_sq),
            DEGENERATE_AREA_RATIO, int(c.polish_iterations), rigidity, -1.0 if runner_up is None else float(runner_up),
            point_columns(problem.points_prev, problem.points_curr),
            # nothing known yet of each weight's interval: the kernel's first draw finds them
            runner_kernels.level_edges(float(WEIGHT_LEVELS)), level, np.full(self.n, np.inf), np.full(self.n, -np.inf),
            *draw_arrays,
            self.sample, self.R, self.t, self.mask, self.verdicts,
        )

    def push(self) -> None:
        """The search's and the sampler's state into the kernel's arrays."""
        s, search, sampler = self.state, self.search, self.sampler
        s[runner_kernels.S_DRAWN], s[runner_kernels.S_SCORED], s[runner_kernels.S_CHECKS] = (
            search.drawn, search.scored, search.checks)
        s[runner_kernels.S_DEGENERATE], s[runner_kernels.S_REJECTED] = search.degenerate, search.rejected
        s[runner_kernels.S_UPDATES], s[runner_kernels.S_BEST_SEEN] = sampler.updates, sampler.best_inliers_seen
        s[runner_kernels.S_BEST_SUPPORT] = sampler.best_support
        s[runner_kernels.S_REQUIRED], s[runner_kernels.S_STOPPED] = search.required, self.term.stopped_by_rule
        self.fstate[runner_kernels.F_BEST_SCORE] = search.best_score
        if search.best_score > -np.inf:
            best = int(np.count_nonzero(search.best_inliers))
            s[runner_kernels.S_BEST_COUNT] = best
            # the uniform bound for this support; the beliefs' rule is the kernel's to check
            s[runner_kernels.S_BOUND] = min(self.term.bound.required(best, self.n), self.term.max_iterations)

    def pull(self) -> None:
        """The kernel's counts back into the search and the sampler."""
        s, search, sampler = self.state, self.search, self.sampler
        search.drawn, search.scored, search.checks = (
            int(s[runner_kernels.S_DRAWN]), int(s[runner_kernels.S_SCORED]), int(s[runner_kernels.S_CHECKS]))
        search.degenerate, search.rejected = int(s[runner_kernels.S_DEGENERATE]), int(s[runner_kernels.S_REJECTED])
        sampler.updates, sampler.best_inliers_seen = int(s[runner_kernels.S_UPDATES]), int(s[runner_kernels.S_BEST_SEEN])
        sampler.best_support = int(s[runner_kernels.S_BEST_SUPPORT])
        sampler._arrays = None  # the kernel moved the log-odds
        search.required, self.term.stopped_by_rule = int(s[runner_kernels.S_REQUIRED]), bool(s[runner_kernels.S_STOPPED])

    def run(self) -> None:
        search, rng = self.search, self.search.rng
        rows, saved, u = FIRST_UNIFORM_ROWS, None, np.zeros((0, SAMPLE_SIZE))
        while not search.done:
            if self.state[runner_kernels.S_ROW] >= u.shape[0]:
                # Uniforms for the next hypotheses, as one-hypothesis batches would draw them one row
                # at a time (Generator.random fills its output in order); the rows left unused are
                # given back below, so the generator ends where the loop leaves it.
                saved = rng.bit_generator.state
                u = rng.random((rows, SAMPLE_SIZE))
                rows = min(2 * rows, MAX_UNIFORM_ROWS)
                self.state[runner_kernels.S_ROW] = 0
            self.push()
            event = runner_kernels.bansac_search(self.sampler.log_odds, u, self.state, self.fstate, *self.args)
            self.pull()
            if event in (runner_kernels.NEW_BEST, runner_kernels.RUNNER_UP):
                self.finish_step(event == runner_kernels.NEW_BEST)
        used = int(self.state[runner_kernels.S_ROW])
        if saved is not None and used < u.shape[0]:
            rng.bit_generator.state = saved
            rng.random((used, SAMPLE_SIZE))

    def finish_step(self, new_best: bool) -> None:
        """The rest of a step the kernel handed back, as :meth:`RansacSearch.step` does it for a
        batch of one scored hypothesis: its new best (with the local refit) or its runner-up
        refit, then the feedback and the termination."""
        search, c, n = self.search, self.c, self.n
        R, t = self.R[None].copy(), self.t[None].copy()
        score = float(self.fstate[runner_kernels.F_EVENT_SCORE])
        inliers = self.mask.copy()  # read from the scored (capped) residuals: no point checks
        if new_best:
            search.best_R, search.best_t, search.best_score, search.best_inliers = R[0], t[0], score, inliers
            search.found_at = search.drawn
            if c.local_optimizer is not None and not local_refit_redundant(c, search.drawn, inliers, n):
                search.best_R, search.best_t, search.best_inliers, search.best_score, spent = c.local_optimizer.improve(
                    search.ctx, search.best_R, search.best_t, search.best_inliers, search.best_score, search.rng
                )
                search.local_runs += 1
                search.checks += spent
        else:
            R_j, t_j, inliers_j, score_j, spent = c.local_optimizer.improve(search.ctx, R[0], t[0], inliers, score,
                                                                             search.rng)
            search.runner_up_runs += 1
            search.checks += spent
            if score_j > search.best_score:
                search.runner_up_wins += 1
                search.best_R, search.best_t, search.best_inliers, search.best_score = R_j, t_j, inliers_j, score_j
                search.found_at = search.drawn
        # the feedback, on the verdicts the kernel took as the loop takes them from the uncapped residuals
        search.checks += n
        state = LoopState(search.drawn, search.best_score, samples=self.sample[None].copy(),
                          best_inliers=search.best_inliers)
        self.sampler.on_hypotheses(R, t, self.verdicts[None].copy(), None, state)
        bound = self.term.required(int(np.count_nonzero(search.best_inliers)), n)
        search.required = min(bound, self.term.max_iterations)


def compiled_bansac_search(search: RansacSearch) -> None:
    """Run a fresh search of the paper's BANSAC to its end in the compiled kernel
    (:func:`stereovo.estimation.kernels.bansac_runner.bansac_search`), returning to Python only
    for a new best, a runner-up refit and the next block of uniforms: the same steps as the loop's
    one-hypothesis batches, bit for bit, at a fraction of their cost. Components it does not
    cover (:func:`compiled_search_applies`) are left to the loop, untouched."""
    if compiled_search_applies(search.components):
        _CompiledSearch(search).run()


# ----------------------------------------------------------------------------- the project's variant


def initial_beliefs(n: int, priors: np.ndarray | None, initial_probability: float, prior_ceiling: float) -> np.ndarray:
    """``(n,)`` inlier beliefs: the constant without priors, else priors scaled to a maximum of
    ``prior_ceiling`` (floored at :data:`BELIEF_FLOOR`); the verdict-likelihood variant's and ARS's."""
    return prior_beliefs(n, priors, initial_probability, prior_ceiling)


def verdict_likelihood_update(p: np.ndarray, sample: np.ndarray, verdicts: np.ndarray,
                              recall: float = DEFAULT_RECALL) -> np.ndarray:
    """The verdict-likelihood variant's update of the beliefs ``p (N,)`` (module docstring), a new array.

    Args:
        p: current beliefs in (0, 1).
        sample: the hypothesis' minimal sample, three indices.
        verdicts: ``(N,)`` bool, the hypothesis' inlier mask.
        recall: ``rho``, the share of inliers a correct hypothesis finds.
    """
    delta = float(np.prod(p[sample]))
    r = float(np.count_nonzero(verdicts)) / verdicts.shape[0]
    in_if_inlier, in_if_outlier = delta * recall + (1 - delta) * r, (1 - delta) * r
    l_in = np.where(verdicts, in_if_inlier, 1 - in_if_inlier)
    l_out = np.where(verdicts, in_if_outlier, 1 - in_if_outlier)
    posterior = p * l_in / np.maximum(p * l_in + (1 - p) * l_out, 1e-300)
    posterior[sample] = p[sample]
    return np.clip(posterior, BELIEF_FLOOR, 1 - BELIEF_FLOOR)


class VerdictBeliefSampler:
    """The verdict-likelihood variant: guided sampling on beliefs that every verified hypothesis
    updates by :func:`verdict_likelihood_update` (module docstring).

    Attributes:
        beliefs: ``(N,)`` current inlier beliefs.
        history: ``(T, 3)`` every minimal sample fitted so far (the stopping rule reads them).
    """

    def __init__(self, n: int, priors: np.ndarray | None = None, initial_probability: float = 0.5,
                 prior_ceiling: float = PRIOR_CEILING, recall: float = DEFAULT_RECALL) -> None:
        if n < SAMPLE_SIZE:
            raise ValueError(f"need at least {SAMPLE_SIZE} correspondences to sample, got {n}")
        for name, value in (("initial_probability", initial_probability), ("prior_ceiling", prior_ceiling),
                            ("recall", recall)):
            if not 0 < value <= 1:
                raise ValueError(f"VerdictBeliefSampler: {name} must be in (0, 1), got {value!r}")
        self.n, self.recall = n, float(recall)
        self.beliefs = initial_beliefs(n, priors, initial_probability, prior_ceiling)
        self._history: list[np.ndarray] = []
        self.updates = 0

    @property
    def history(self) -> np.ndarray:
        return np.concatenate(self._history) if self._history else np.zeros((0, SAMPLE_SIZE), dtype=np.int64)

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        return WeightedSampler(self.beliefs).draw(batch, rng)

    def on_hypotheses(self, R, t, inlier_masks: np.ndarray, residual_sq: np.ndarray, state: LoopState) -> None:
        p = self.beliefs
        for sample, verdicts in zip(state.samples, inlier_masks):
            p = verdict_likelihood_update(p, sample, verdicts, self.recall)
        self.beliefs = p
        self.updates += len(inlier_masks)
        self._history.append(np.asarray(state.samples, dtype=np.int64))

    def stop_confidence(self) -> float:
        """``1 - prod_t (1 - prod_{j in S_t} p_j)`` over the samples fitted so far."""
        history = self.history
        if history.shape[0] == 0:
            return 0.0
        all_inlier = np.prod(self.beliefs[history], axis=1)
        return float(-np.expm1(np.sum(np.log1p(-np.minimum(all_inlier, 1 - 1e-12)))))

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        """As :meth:`BansacSampler.all_inlier_probability`, on the beliefs."""
        return sequential_all_inlier_probability(self.beliefs, inliers)

    def counters(self) -> dict[str, float]:
        return {"bansac_updates": self.updates, "bansac_stop_confidence": self.stop_confidence()}


@dataclass
class VerdictConfidenceTermination:
    """The verdict-likelihood variant's stop: once the beliefs say an all-inlier sample was drawn
    with ``confidence``; ``max_iterations`` caps the search, ``min_iterations`` floors it."""

    sampler: VerdictBeliefSampler
    confidence: float = 0.99
    max_iterations: int = 10_000
    min_iterations: int = 1
    stopped_by_rule: bool = field(default=False, init=False)

    def __post_init__(self) -> None:
        if not 0 < self.confidence < 1:
            raise ValueError(f"VerdictConfidenceTermination: confidence must be in (0, 1), got {self.confidence!r}")
        if not 1 <= self.min_iterations <= self.max_iterations:
            raise ValueError(
                f"VerdictConfidenceTermination: need 1 <= min_iterations <= max_iterations, got "
                f"{self.min_iterations} and {self.max_iterations}"
            )

    def required(self, n_inliers: int, n: int) -> int:
        drawn = self.sampler.history.shape[0]
        self.stopped_by_rule = drawn >= self.min_iterations and self.sampler.stop_confidence() >= self.confidence
        return 0 if self.stopped_by_rule else self.max_iterations

    def counters(self) -> dict[str, int]:
        return {"bansac_stopped_by_rule": int(self.stopped_by_rule)}


# ----------------------------------------------------------------------------- the methods


UPDATES = ("paper", "verdict-likelihood")
BELIEF_OPTIONS = ("initial_probability", "prior_ceiling")
declare_options({
    "initial_probability": Number(low=0.0, high=1.0, low_open=True, high_open=True, default=0.5),
    "bansac_recall": Number(low=0.0, high=1.0, low_open=True, default=DEFAULT_RECALL),
    "bansac_update": Choice(choices=UPDATES, default="paper"),
    # None: PAPER_BATCH under the paper's update, FEEDBACK_BATCH under the verdict-likelihood one
    "bansac_batch": Integer(low=1, allow_none=True, default=None),
    "bansac_weights": Choice(choices=WEIGHTINGS, default="discretised"),
})
CEILING_RULE = Number(low=0.0, high=1.0, low_open=True, high_open=True, default=PRIOR_CEILING)
"""``prior_ceiling`` of the belief samplers that cap the priors by default (ars, the verdict-likelihood update)."""


def bansac_options(threshold: float) -> dict:
    """The declarations of ``bansac``'s options, with stop threshold ``threshold`` by default;
    ``prior_ceiling`` None (its default) caps the priors only under the verdict-likelihood update."""
    return {
        "initial_probability": None, "prior_ceiling": dataclasses.replace(CEILING_RULE, allow_none=True, default=None),
        "bansac_update": None, "bansac_batch": None, "bansac_weights": None, "bansac_recall": None,
        "bansac_threshold": Number(low=0.0, high=1.0, low_open=True, high_open=True, default=threshold),
    }


def belief_options(extra: dict) -> dict[str, float]:
    """The belief options of ``ars`` and the verdict-likelihood variant from the method options
    ``extra`` (an unset ceiling: :data:`PRIOR_CEILING`)."""
    ceiling = extra["prior_ceiling"]
    return {"initial_probability": float(extra["initial_probability"]),
            "prior_ceiling": PRIOR_CEILING if ceiling is None else float(ceiling)}


BELIEF_SAMPLER_READS = OptionReads(judge="mahalanobis", refinement="pixel-gated", stop="adaptive", local="always")
"""What a belief sampler on :func:`judged_components` reads: ``probabilistic``'s judge and refinement,
an adaptive stop, and the consensus refit on every new best whatever ``local_refit`` says."""

BANSAC_READS = dataclasses.replace(BELIEF_SAMPLER_READS, batches="belief-updates")
"""``bansac``'s and ``p-bansac``'s: those of :data:`BELIEF_SAMPLER_READS`, with batches of their own
(``bansac_batch``) between belief updates."""


def judged_components(problem, options: EstimatorOptions, priors, order, sampler):
    """The ``probabilistic`` method's recipe (Mahalanobis gate, rigidity check, pixel-gated
    refinement) with ``sampler`` in place of its own."""
    if order is not None:
        raise ValueError("this method samples by inlier beliefs: give priors (or nothing), not an order")
    components = method_spec("probabilistic").build(problem, options, priors, None, {})
    components.sampler = sampler
    # Belief-driven samplers draw from the first consensus found, and a minimal stereo fit finds
    # only part of its inliers: refitting each new best on its consensus gives it its full support
    # (docs/algorithms.md, "Measurements behind the code").
    components.local_optimizer = components.local_optimizer or ConsensusRefit()
    return components


def _build(problem, options, priors, order, extra):
    if extra["bansac_update"] == "verdict-likelihood":
        return _build_verdict_variant(problem, options, priors, order, extra)
    ceiling = extra["prior_ceiling"]
    sampler = BansacSampler(
        problem.n, priors, threshold=float(extra["bansac_threshold"]),
        initial_probability=float(extra["initial_probability"]),
        prior_ceiling=None if ceiling is None else float(ceiling),
        weights=extra["bansac_weights"],
    )
    # the judge without the priors: they would only build the recipe a sampler and a bound that this replaces
    components = judged_components(problem, options, None, order, sampler)
    batch = extra["bansac_batch"]
    components.batch_size, components.first_batch_size = PAPER_BATCH if batch is None else batch, None
    if options.budget is None:
        # the released code keeps the uniform adaptive bound beside the beliefs' stop
        bound = AdaptiveTermination(options.confidence, int(options.max_iterations))
        components.termination = BansacTermination(sampler, bound)
    if COMPILED_SEARCH:
        components.search_runner = compiled_bansac_search
    return components


def _build_verdict_variant(problem, options, priors, order, extra):
    recall = float(extra["bansac_recall"])
    sampler = VerdictBeliefSampler(problem.n, priors, recall=recall, **belief_options(extra))
    components = judged_components(problem, options, priors, order, sampler)
    batch = FEEDBACK_BATCH if extra["bansac_batch"] is None else extra["bansac_batch"]
    components.batch_size, components.first_batch_size = min(int(options.batch_size), batch), None
    if options.budget is None:
        components.termination = VerdictConfidenceTermination(sampler, options.confidence, int(options.max_iterations))
    return components


@register_method(
    "bansac",
    "BANSAC: sampling weights from per-point inlier beliefs that a dynamic Bayesian network updates "
    "after every hypothesis; stops when the beliefs rule out as many points (p < 0.01) as the best "
    "model's outliers, or at the adaptive bound; the probabilistic method's judge",
    "Piedade & Miraldo, ICCV 2023",
    extra_options=bansac_options(BANSAC_THRESHOLD),
    inputs="priors-optional",
    reads=BANSAC_READS,
)
def _build_bansac(problem, options, priors, order, extra):
    return _build(problem, options, priors, order, extra)


@register_method(
    "p-bansac",
    "P-BANSAC: BANSAC with the looser stop (beliefs under 0.1 count as ruled out)",
    "Piedade & Miraldo, ICCV 2023",
    extra_options=bansac_options(P_BANSAC_THRESHOLD),
    inputs="priors-optional",
    reads=BANSAC_READS,
)
def _build_p_bansac(problem, options, priors, order, extra):
    return _build(problem, options, priors, order, extra)
