"""R-RANSAC with the T(d,d) pre-test (Matas & Chum 2002, "Randomized RANSAC with T(d,d) test",
BMVC; 2004, Image and Vision Computing).

Before a hypothesis is scored on all N correspondences it must explain d
randomly chosen ones (never its own sample, which it fits by construction).
Most contaminated hypotheses fail on the first point and cost one check
instead of N. A good (all-inlier) hypothesis survives only with probability
``alpha``, which stretches the stopping bound to ``log(1 - p) / log(1 - q alpha)``.

``alpha`` is *measured*, not assumed: a minimal fit on noisy stereo points explains only part of
the inliers under a tight gate (about a fifth at w = 0.5), so the textbook ``alpha ~ w^d`` is far
too optimistic and the bound would stop long before a good hypothesis has had its chance. The
verifier tracks the hypotheses whose three sample points are all inliers of the best model so
far (the good ones, as far as the data tell), measures each one's chance of passing (exactly
from its full support when it passed and was scored, unbiased from ``measure_points`` random
points when it failed) and reports their mean.

The pre-test runs compiled (:mod:`stereovo.estimation.kernels.verification`) for the reprojection
residual, so a rejected hypothesis costs its d point checks; other residual models take the
vectorised numpy route with the same draws' distribution.

This module also declares ``tdd_d`` and registers ``r-ransac``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from stereovo.estimation.estimator_options import MAX_COUNT
from stereovo.estimation.kernels.verification import tdd_pretest
from stereovo.estimation.recipes import REPROJECTION_READS, base_components, reprojection_judge
from stereovo.estimation.registry import register_method
from stereovo.estimation.roles.partial import residuals_at
from stereovo.estimation.roles.scoring import InlierCount
from stereovo.estimation.roles.scoring import ReprojectionResidual
from stereovo.estimation.roles.solvers import SAMPLE_SIZE
from stereovo.estimation.roles.termination import SampleProbability, check_bound, iterations_for
from stereovo.estimation.roles.verification import ScoringContext
from stereovo.options import Integer


def random_points_excluding(samples: np.ndarray, n: int, d: int, rng: np.random.Generator) -> np.ndarray:
    """``(H, d)`` distinct random correspondences per row, none of them in that row's ``samples (H, 3)``.

    Uniform over the ``n - 3`` other points: random keys with the sample's own keys set
    to +inf, then the d smallest (``argpartition``), vectorised over the whole batch.
    """
    H = samples.shape[0]
    keys = rng.random((H, n))
    keys[np.arange(H)[:, None], samples] = np.inf
    chosen = np.argpartition(keys, d - 1, axis=1)[:, :d]
    # argpartition leaves the d smallest unordered; order them by key so the
    # "first" point of the test really is a uniformly random one.
    return np.take_along_axis(chosen, np.argsort(np.take_along_axis(keys, chosen, axis=1), axis=1), axis=1)


def pass_probability(consistent: np.ndarray, pool: np.ndarray, d: int) -> np.ndarray:
    """``prod_{j<d} (c - j) / (m - j)``: the chance that d distinct points drawn from a pool of ``m``
    of which ``c`` are consistent all pass; with a random subset of the N - 3 points as the pool it is
    an unbiased estimate of the same chance over all of them (elementwise, ``(H,)``)."""
    c = np.asarray(consistent, dtype=float)
    m = np.asarray(pool, dtype=float)
    p = np.ones(np.broadcast(c, m).shape)
    for j in range(d):
        p = p * np.maximum(c - j, 0.0) / np.maximum(m - j, 1.0)  # np.clip(., 0, None) is this maximum, slower
    return p


@dataclass
class TddVerification:
    """The T(d,d) pre-test, then full verification of the survivors; measures the good-model pass rate.

    Args:
        d: points of the pre-test (d = 1 is the paper's optimum for its cost model).
        measure_points: random points on which a failed good hypothesis' support is estimated.
        max_measured: stop measuring failed good hypotheses once this many good ones are on record.

    Cost accounting: a hypothesis that fails at its j-th pre-test point costs j checks; one that
    passes costs ``N``. Measuring the pass rate adds ``measure_points`` checks per failed good
    hypothesis (a fraction ``q`` of the draws, at most ``max_measured`` of them), counted too.

    Also a loop listener: ``on_new_best`` takes the best model's inlier mask, which decides which
    hypotheses count as good.
    """

    d: int = 1
    measure_points: int = 64
    max_measured: int = 256
    t_m: float = 200.0
    adaptive: bool = True
    min_measured: int = 16
    uses_samples: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if not (isinstance(self.t_m, (int, float)) and np.isfinite(self.t_m) and self.t_m > 0):
            raise ValueError(f"option tdd_t_m must be a positive number, got {self.t_m!r}")
        for name, value, low in (("tdd_d", self.d, 1), ("tdd_measure_points", self.measure_points, 1),
                                 ("tdd_max_measured", self.max_measured, 1), ("tdd_min_measured", self.min_measured, 1)):
            if isinstance(value, bool) or int(value) != value or value < low:
                raise ValueError(f"option {name} must be an integer >= {low}, got {value!r}")
        self.d, self.measure_points, self.max_measured = int(self.d), int(self.measure_points), int(self.max_measured)
        self.n_passed = 0  # hypotheses that survived the pre-test
        self.n_tested = 0
        self.n_measure_checks = 0
        self._best: np.ndarray | None = None
        self._samples = np.empty((0, SAMPLE_SIZE), dtype=np.int64)  # samples of the hypotheses measured
        self._alphas = np.empty(0)  # their measured pass probabilities
        self._good_mask = np.empty(0, dtype=bool)  # which are good under the current best
        self._good = 0
        self._alpha: float | None = None  # cached mean over the good ones
        self.active = True  # the pre-test is on (off once the measured rates say it cannot pay)
        self.n_on = 0  # hypotheses verified with the pre-test on / off
        self.n_off = 0
        self.n_switches = 0
        self._pass_sum = 0.0  # pass probabilities of all verified hypotheses (counted or computed)
        self._optimistic: float | None = None

    # ------------------------------------------------------------------ the measured pass rate

    def on_new_best(self, inliers: np.ndarray, state) -> None:
        self._best = np.asarray(inliers, dtype=bool).copy()
        self._good_mask = self._good_rows(self._samples)
        # the pass chance of a hypothesis explaining the best's whole support: an optimistic alpha
        support = int(np.count_nonzero(self._best))
        self._optimistic = float(pass_probability(max(support - SAMPLE_SIZE, 0), self._best.size - SAMPLE_SIZE, self.d))
        self._refresh()
        self._decide(self._best.size)

    def _refresh(self) -> None:
        self._good = int(np.count_nonzero(self._good_mask))
        self._alpha = float(np.mean(self._alphas[self._good_mask])) if self._good else None

    def pays(self, n: int) -> bool:
        """Matas & Chum's cost model with the measured rates: the pre-test pays iff
        ``(t_M + d + P_pass (N - d)) / alpha < t_M + N``, i.e. the expected cost of finding a good
        hypothesis falls (``P_pass``: the pass rate of all hypotheses, ``alpha``: of good ones).

        Until ``min_measured`` good hypotheses were measured, ``alpha`` is the optimistic chance of a
        hypothesis explaining the best model's whole support: if even that cannot pay, none will.
        Before any best model the paper's test stays on."""
        alpha = self._alpha if self._alpha is not None and self._good >= self.min_measured else self._optimistic
        if alpha is None or self.n_on == 0:  # nothing measured yet: the paper's test stays on
            return True
        if alpha <= 0.0:
            return False
        p_pass = self._pass_sum / max(self.n_on + self.n_off, 1)
        return (self.t_m + self.d + p_pass * (n - self.d)) / alpha < self.t_m + n

    def _decide(self, n: int) -> None:
        if self.adaptive:
            active = self.pays(n)
            self.n_switches += active != self.active
            self.active = active

    def _good_rows(self, samples: np.ndarray) -> np.ndarray:
        best = self._best
        return best[samples[:, 0]] & best[samples[:, 1]] & best[samples[:, 2]]  # np.all over axis 1, faster

    def alpha(self) -> float | None:
        """Measured chance that a good hypothesis passes the pre-test (None before any was measured).

        The mean of the per-hypothesis pass probabilities of the measured hypotheses whose samples
        lie in the current best model's inliers."""
        return self._alpha

    # ------------------------------------------------------------------ verification

    def verify(
        self, ctx: ScoringContext, R: np.ndarray, t: np.ndarray, rng: np.random.Generator, samples: np.ndarray
    ) -> tuple[np.ndarray, int]:
        """Scores ``(H,)`` (``-inf`` = failed the pre-test) and the point checks spent."""
        H, n = R.shape[0], ctx.problem.n
        d = min(self.d, n - SAMPLE_SIZE)
        if d < 1:  # nothing outside the sample to pre-test on
            return ctx.score(R, t), H * n
        samples = np.ascontiguousarray(samples, dtype=np.int64)
        compiled = isinstance(ctx.residual_model, ReprojectionResidual)
        if not self.active:
            return self._verify_fully(ctx, R, t, samples, d)
        if compiled:
            p = ctx.problem
            passed, spent, _ = tdd_pretest(
                np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(t, dtype=float), p.points_prev, p.curr,
                p.camera.parameters, float(ctx.threshold_sq), samples, rng.random((H, d)), True,
            )
            checks = int(np.sum(spent))
        else:
            idx = random_points_excluding(samples, n, d, rng)
            consistent = residuals_at(ctx, R, t, idx) < ctx.threshold_sq  # (H, d)
            passed = np.all(consistent, axis=1)
            first_fail = np.argmax(~consistent, axis=1) + 1  # a failing hypothesis stops at its first miss
            checks = int(np.sum(first_fail[~passed])) + int(np.count_nonzero(passed)) * d
        scores = np.full(H, -np.inf)
        rows = np.flatnonzero(passed)
        sq = None
        if rows.size:
            scores[rows], sq = ctx.score_with_residuals(R[rows], t[rows])
            checks += rows.size * (n - d)  # its d pre-test points were counted above
            row_of = np.full(H, -1, dtype=np.int64)
            row_of[rows] = np.arange(rows.size)
            ctx.remember(R, sq, row_of)
        self.n_passed += int(rows.size)
        self.n_tested += H
        self.n_on += H
        self._pass_sum += float(rows.size)
        checks += self._measure(ctx, R, t, rng, samples, passed, sq, d, compiled)
        self._decide(n)
        return scores, checks

    def _verify_fully(self, ctx, R, t, samples, d) -> tuple[np.ndarray, int]:
        """The pre-test switched off: score every hypothesis on all points. A good one's pass
        probability (for alpha) follows exactly from its support; the pass rate of all hypotheses
        keeps its value from while the test was on (recomputing it would cost a pass over every
        hypothesis' residuals)."""
        H, n = R.shape[0], ctx.problem.n
        scores, sq = ctx.score_with_residuals(R, t)
        self.n_off += H
        self._pass_sum += H * self._pass_sum / max(self.n_on, 1)
        if self._best is not None:
            good = self._good_rows(samples)
            if np.any(good):
                masks = sq[good] < ctx.threshold_sq
                own = np.take_along_axis(masks, samples[good], axis=1).sum(axis=1)
                chance = pass_probability(masks.sum(axis=1) - own, n - SAMPLE_SIZE, d)
                self._samples = np.concatenate([self._samples, samples[good]])
                self._alphas = np.concatenate([self._alphas, chance])
                self._good_mask = np.concatenate([self._good_mask, np.ones(chance.size, dtype=bool)])
                self._refresh()
        self._decide(n)
        return scores, H * n

    def _measure(self, ctx, R, t, rng, samples, passed, passed_sq, d, compiled) -> int:
        """Record the pass probabilities of this batch's good hypotheses; returns the checks spent."""
        if self._best is None:
            return 0
        good = self._good_rows(samples)
        if not np.any(good):
            return 0
        n = ctx.problem.n
        others = n - SAMPLE_SIZE
        found_s, found_a = [], []
        good_passed = good & passed
        if np.any(good_passed):  # exact: their full support is known
            in_batch = np.flatnonzero(passed)
            masks = passed_sq[good_passed[in_batch]] < ctx.threshold_sq
            support = masks.sum(axis=1)
            own = np.take_along_axis(masks, samples[good_passed], axis=1).sum(axis=1)
            found_s.append(samples[good_passed])
            found_a.append(pass_probability(support - own, others, d))
        spent = 0
        good_failed = np.flatnonzero(good & ~passed)
        room = self.max_measured - self._good
        if good_failed.size and room > 0:
            rows = good_failed[:room]
            m = min(self.measure_points, others)
            if compiled:
                p = ctx.problem
                _, _, consistent = tdd_pretest(
                    np.ascontiguousarray(R[rows], dtype=float), np.ascontiguousarray(t[rows], dtype=float),
                    p.points_prev, p.curr, p.camera.parameters, float(ctx.threshold_sq),
                    np.ascontiguousarray(samples[rows]), rng.random((rows.size, m)), False,
                )
            else:
                idx = random_points_excluding(samples[rows], n, m, rng)
                consistent = np.sum(residuals_at(ctx, R[rows], t[rows], idx) < ctx.threshold_sq, axis=1)
            spent = rows.size * m
            found_s.append(samples[rows])
            found_a.append(pass_probability(consistent, m, d))
        if found_s:  # all good under the current best
            self._samples = np.concatenate([self._samples, *found_s])
            self._alphas = np.concatenate([self._alphas, *found_a])
            self._good_mask = np.concatenate([self._good_mask, np.ones(sum(len(a) for a in found_a), dtype=bool)])
            self._refresh()
        self.n_measure_checks += spent
        return spent

    def counters(self) -> dict[str, int | float]:
        """``tdd_tested`` / ``tdd_passed`` / ``tdd_failed`` hypotheses, ``tdd_good_measured`` good ones
        measured, ``tdd_alpha`` their mean pass probability (-1 if none), ``tdd_measure_checks``."""
        alpha = self.alpha()
        return {
            "tdd_tested": self.n_tested,
            "tdd_passed": self.n_passed,
            "tdd_failed": self.n_tested - self.n_passed,
            "tdd_good_measured": self._good,
            "tdd_alpha": -1.0 if alpha is None else alpha,
            "tdd_measure_checks": self.n_measure_checks,
            "tdd_on": self.n_on,
            "tdd_off": self.n_off,
            "tdd_switches": self.n_switches,
        }


@dataclass
class TddTermination:
    """RANSAC's bound with the pre-test's measured pass rate: stop once a good hypothesis would have
    been found with probability ``confidence``.

    Each hypothesis verified with the pre-test on finds a good model with chance ``q alpha``, one
    verified fully (the pre-test switched off because it does not pay) with chance ``q``; the run
    stops when ``(1 - q alpha)^k_on (1 - q)^k_off <= 1 - confidence``. With the pre-test on
    throughout this is ``k = log(1 - p) / log(1 - q alpha)`` (Matas & Chum). ``q``: one draw of the
    sampler is all-inlier (the without-replacement count formula for uniform sampling); ``alpha``:
    the verifier's measured pass probability of a good hypothesis. Until one was measured,
    ``prod_{j<d} (I - 3 - j) / (N - 3 - j)``, the chance for a hypothesis explaining the best model's
    whole support. A loop listener (the draws so far, a guided sampler's q).
    """

    confidence: float = 0.99
    max_iterations: int = 10_000
    d: int = 1
    verifier: TddVerification | None = None
    sampler: object = None

    def __post_init__(self) -> None:
        check_bound(self.confidence, self.max_iterations)
        self.probability = SampleProbability(self.sampler, self.confidence)  # a PROSAC schedule needs it
        self.last_alpha = float("nan")
        self._drawn = 0

    def on_new_best(self, inliers: np.ndarray, state) -> None:
        self.probability.on_new_best(inliers, state)

    def on_batch(self, state) -> None:
        self._drawn = int(state.n_hypotheses)

    def required(self, n_inliers: int, n: int) -> int:
        q = self.probability.of(n_inliers, n)
        v = self.verifier
        alpha = v.alpha() if v is not None else None
        if alpha is None:
            alpha = float(pass_probability(max(n_inliers - SAMPLE_SIZE, 0), n - SAMPLE_SIZE, self.d))
        self.last_alpha = alpha
        if v is None or v.n_off == 0 and v.active:
            return iterations_for(q * alpha, self.confidence, self.max_iterations)
        if not q > 0:
            return self.max_iterations
        # draws so far under each mode, then what the current mode still needs
        log_miss = v.n_on * math.log1p(-min(q * alpha, 1 - 1e-16)) + v.n_off * math.log1p(-min(q, 1 - 1e-16))
        per_draw = q * alpha if v.active else q
        if not per_draw > 0:
            return self.max_iterations
        if per_draw >= 1:
            return min(self._drawn + 1, self.max_iterations)
        remaining = (math.log1p(-self.confidence) - log_miss) / math.log1p(-per_draw)
        return int(min(max(self._drawn + math.ceil(max(remaining, 0.0)), 1), self.max_iterations))

    def counters(self) -> dict[str, int | float]:
        return {"tdd_alpha_used": self.last_alpha}


@register_method(
    "r-ransac",
    "randomized RANSAC: T(d,d) pre-test on d random points before full scoring, bound stretched by 1/alpha",
    "Matas & Chum 2002",
    extra_options={"tdd_d": Integer(low=1, high=MAX_COUNT, default=TddVerification.d)},
    reads=REPROJECTION_READS,  # the T(d,d) stop is adaptive: a fixed budget replaces it
)
def _build_r_ransac(problem, options, priors, order, extra):
    d = extra["tdd_d"]
    components = base_components(problem, options, priors, order, *reprojection_judge(options, InlierCount()))
    verifier = TddVerification(d)
    components.verifier = verifier
    components.listeners.append(verifier)  # the best model's inliers decide which hypotheses are good
    if options.budget is None:
        components.termination = TddTermination(options.confidence, int(options.max_iterations), d, verifier,
                                                components.sampler)
    return components
