"""R-RANSAC with the sequential probability ratio test (WaldSAC; Matas & Chum, ICCV 2005): docs/algorithms.md, `waldsac`.

Matas & Chum 2005 ("Randomized RANSAC with sequential probability ratio
test"), Chum & Matas 2008 ("Optimal randomized RANSAC"). Each hypothesis is
checked point by point in random order; the likelihood ratio
``lambda = prod p(x | bad) / p(x | good)`` grows by ``delta / epsilon`` per
consistent point and by ``(1 - delta) / (1 - epsilon)`` per inconsistent one,
and the hypothesis is rejected as soon as ``lambda > A``. ``epsilon`` (inlier
ratio of a good model) and ``delta`` (chance that a point is consistent with a
bad model) are estimated on the fly; every change designs a new test, and the
history of tests gives the stopping rule.

Vectorisation: a batch of hypotheses is checked on the same random
permutation of the points (a fresh one per batch), in chunks that double in
size (16, 32, 64, ...); within a chunk the cumulative log-ratio of every
hypothesis is a ``cumsum`` and each hypothesis stops at its first crossing.
Marginally each hypothesis sees a uniformly random order, which is all the
test's error bounds use; a hypothesis' own three sample points are skipped.

This module also declares the ``sprt_*`` options (shared with ``usac``) and registers ``waldsac``;
:data:`PROBABILISTIC_SPRT` declares ``probabilistic+sprt`` (the project's recipe with this
verification and stop, an enhancement) among the ``+`` variants.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from scipy.optimize import brentq

from stereovo.estimation.estimator_options import MAX_COUNT
from stereovo.estimation.kernels.verification import sprt_verify, sprt_verify_mahalanobis
from stereovo.estimation.loop import LoopState
from stereovo.estimation.recipes import (
    PROBABILISTIC_READS,
    PROBABILISTIC_RECIPE,
    REPROJECTION_READS,
    base_components,
    build_probabilistic,
    reprojection_judge,
)
from stereovo.estimation.registry import declare_options, register_method
from stereovo.estimation.roles.partial import residuals_on
from stereovo.estimation.roles.scoring import InlierCount, MahalanobisResidual, ReprojectionResidual
from stereovo.estimation.roles.termination import SampleProbability, check_bound
from stereovo.estimation.roles.verification import ScoringContext
from stereovo.options import Integer, Number

DELTA_BOUNDS = (1e-3, 0.3)  # clamp delta: at 0 the test takes log 0 and rejects at once; it must stay below epsilon
MIN_A = 2.0  # below this the test rejects almost anything: fall back to full verification


_DESIGNS: dict[tuple[float, float, float, float, float], tuple[float, float, float]] = {}
_DESIGNS_MAX = 4096  # each entry a few floats; cleared when full (runs repeat the same first design)


def sprt_design(epsilon: float, delta: float, t_m: float, m_s: float = 1.0, tol: float = 1e-9) -> tuple[float, float, float]:
    """The SPRT decision threshold for one (epsilon, delta) pair (cached: a pure function of its arguments).

    ``C = (1 - delta) log((1 - delta)/(1 - epsilon)) + delta log(delta/epsilon)``,
    ``K = t_M C / m_S``, ``A`` the fixed point of ``A = K + 1 + log A`` iterated from ``K + 1``.

    Args:
        epsilon, delta: probabilities that a point is consistent with a good / a bad model.
        t_m: time of one hypothesis fit in units of one point check.
        m_s: models per minimal sample (1 for the rigid 3-point fit).

    Returns:
        ``(C, K, A)``; ``A = inf`` (no early rejection) when ``C <= 0`` or ``A < 2``.
    """
    key = (float(epsilon), float(delta), float(t_m), float(m_s), float(tol))
    design = _DESIGNS.get(key)
    if design is None:
        if len(_DESIGNS) >= _DESIGNS_MAX:
            _DESIGNS.clear()
        design = _DESIGNS[key] = _design(*key)
    return design


def _design(epsilon: float, delta: float, t_m: float, m_s: float, tol: float) -> tuple[float, float, float]:
    if not (0 < delta < 1 and 0 < epsilon < 1):
        return 0.0, 0.0, np.inf
    C = (1 - delta) * np.log((1 - delta) / (1 - epsilon)) + delta * np.log(delta / epsilon)
    if not C > 0 or delta >= epsilon:
        return float(C), 0.0, np.inf
    K = t_m * C / m_s
    A = K + 1.0
    for _ in range(100):
        A_next = K + 1.0 + np.log(A)
        if abs(A_next - A) < tol:
            A = A_next
            break
        A = A_next
    if A < MIN_A:
        return float(C), float(K), np.inf
    return float(C), float(K), float(A)


def good_model_exponent(epsilon: float, epsilon_i: float, delta_i: float) -> float:
    """``h > 0`` solving ``epsilon (delta_i/epsilon_i)^h + (1 - epsilon)((1 - delta_i)/(1 - epsilon_i))^h = 1``.

    A test designed for ``epsilon_i`` rejects a good model of true inlier ratio
    ``epsilon`` with probability ``A^-h`` (Wald). ``h = 1`` when ``epsilon = epsilon_i``;
    ``h = 0`` (always rejected) when the good model's log-ratio drifts upwards.

    Solved in log space, ``logaddexp(log eps + h log a, log(1 - eps) + h log b) = 0``: the powers
    ``b^h`` overflow for clean frames (epsilon near 1, b huge), the log never does.
    """
    if not (0 < epsilon_i < 1 and 0 < delta_i < 1):
        return 0.0
    if abs(epsilon - epsilon_i) < 1e-12:
        return 1.0
    if epsilon >= 1.0:  # every point consistent: lambda only falls, the test never rejects
        return np.inf
    if epsilon <= 0.0:
        return 0.0
    log_a, log_b = math.log(delta_i / epsilon_i), math.log1p(-delta_i) - math.log1p(-epsilon_i)
    slope = epsilon * log_a + (1 - epsilon) * log_b
    if slope >= 0 or log_b <= 0:
        return 0.0
    log_eps, log_rest = math.log(epsilon), math.log1p(-epsilon)

    def f(h: float) -> float:  # logaddexp in scalar math (the solver calls it a few dozen times)
        x, y = log_eps + h * log_a, log_rest + h * log_b
        top = max(x, y)
        return top + math.log1p(math.exp(-abs(x - y)))

    hi = 1.0
    while f(hi) <= 0 and hi < 1e6:
        hi *= 2.0
    return float(brentq(f, 1e-12, hi, xtol=1e-12)) if f(hi) > 0 else float(hi)


def rejection_probability(A: float, h: float) -> float:
    """``A^-h``, the chance a test of threshold ``A`` rejects a good model, as ``exp(-h log A)`` (no overflow)."""
    if not np.isfinite(A):
        return 0.0
    if h == np.inf:
        return 0.0
    return float(np.exp(-h * np.log(A)))


@dataclass
class SprtTest:
    """One SPRT design and the hypotheses drawn while it was in force (loop draws)."""

    epsilon: float
    delta: float
    A: float  # inf = full verification (the test is off)
    draws: int = 0

    @property
    def active(self) -> bool:
        return math.isfinite(self.A)

    @functools.cached_property
    def log_steps(self) -> tuple[float, float, float]:
        """``(log(delta / epsilon) < 0, log((1 - delta) / (1 - epsilon)) > 0, log A)`` of an active
        test: once per design (a design is fixed once made; only ``draws`` grows), not per batch."""
        return (float(np.log(self.delta / self.epsilon)), float(np.log1p(-self.delta) - np.log1p(-self.epsilon)),
                float(np.log(self.A)))


@dataclass
class SprtVerification:
    """WaldSAC's verifier: early rejection by the SPRT, adaptive epsilon and delta.

    Args:
        n: number of correspondences N.
        t_m: fit time in point checks. Measured here (batched Kabsch + 2 Gauss-Newton steps
            vs a vectorised residual): about 400 (Mahalanobis) to 1000 (reprojection);
            500 is the default. A grows only like t_M C, the checks per bad model like log A.
        m_s: models per sample (1).
        epsilon0, delta0: the conservative initial design (0.1, 0.01).
        chunk: points in the first chunk; later chunks double.
        delta_tolerance: a relative change of the delta estimate above this redesigns the test.

    Also a loop listener: ``on_new_best`` sets ``epsilon = I / N`` and designs a new test.
    ``history`` holds every test in order; :class:`SprtTermination` reads it.
    """

    n: int
    t_m: float = 500.0
    m_s: float = 1.0
    epsilon0: float = 0.1
    delta0: float = 0.01
    chunk: int = 16
    delta_tolerance: float = 0.05
    history: list[SprtTest] = field(default_factory=list)
    uses_samples: ClassVar[bool] = True

    def __post_init__(self) -> None:
        for name, ok in (
            ("sprt_t_m", self.t_m > 0),
            ("sprt_epsilon0", 0 < self.epsilon0 < 1),
            ("sprt_delta0", 0 < self.delta0 < 1),
            ("sprt_chunk", int(self.chunk) == self.chunk and self.chunk >= 1),
        ):
            if not ok:
                value = getattr(self, name.removeprefix("sprt_"))
                raise ValueError(f"option {name} has an invalid value {value!r}")
        self.chunk = int(self.chunk)
        self.epsilon = float(self.epsilon0)
        self.delta = float(np.clip(self.delta0, *DELTA_BOUNDS))
        self._ratio_sum = 0.0  # sum over rejected hypotheses of consistent / checked
        self._n_rejected = 0
        self.n_accepted = 0
        self.n_tests = 0  # hypotheses put through an active test
        self.n_full = 0  # hypotheses verified fully while the test was off (C <= 0 or A < 2)
        self._design()

    # ------------------------------------------------------------------ design

    @property
    def current(self) -> SprtTest:
        return self.history[-1]

    def _design(self) -> None:
        _, _, A = sprt_design(self.epsilon, self.delta, self.t_m, self.m_s)
        self.history.append(SprtTest(self.epsilon, self.delta, A))

    def on_new_best(self, inliers: np.ndarray, state: LoopState) -> None:
        """A new best model (accepted, so its inlier count is exact): epsilon = I / N, new test."""
        epsilon = float(np.count_nonzero(inliers)) / self.n
        if epsilon != self.epsilon and 0 < epsilon < 1:
            self.epsilon = epsilon
            self._design()

    def counters(self) -> dict[str, int | float]:
        """``sprt_tested`` (through an active test), ``sprt_rejected``, ``sprt_accepted``, ``sprt_full``
        (verified fully while the test was off), ``sprt_designs`` (tests designed), and the final
        test's ``sprt_epsilon``, ``sprt_delta`` and ``sprt_A`` (inf: off)."""
        test = self.current
        return {
            "sprt_tested": self.n_tests,
            "sprt_rejected": self._n_rejected,
            "sprt_accepted": self.n_accepted,
            "sprt_full": self.n_full,
            "sprt_designs": len(self.history),
            "sprt_epsilon": float(test.epsilon),
            "sprt_delta": float(test.delta),
            "sprt_A": float(test.A),
        }

    def _update_delta(self) -> None:
        if self._n_rejected == 0:
            return
        delta_hat = min(max(self._ratio_sum / self._n_rejected, DELTA_BOUNDS[0]), DELTA_BOUNDS[1])
        if abs(delta_hat - self.delta) > self.delta_tolerance * self.delta:
            self.delta = delta_hat
            self._design()

    # ------------------------------------------------------------------ verification

    def verify(
        self, ctx: ScoringContext, R: np.ndarray, t: np.ndarray, rng: np.random.Generator, samples: np.ndarray
    ) -> tuple[np.ndarray, int]:
        """Scores ``(H,)`` (``-inf`` = rejected by the SPRT) and the point checks actually needed.

        A rejected hypothesis costs the points it was checked on up to and including
        the one that crossed ``A`` (its own sample points are skipped, not counted);
        an accepted one costs N, all of which its score uses.
        """
        test = self.current
        H, n = R.shape[0], ctx.problem.n
        if not test.active:
            scores = ctx.score(R, t)
            self.n_accepted += H
            self.n_full += H
            return scores, H * n

        log_consistent, log_inconsistent, log_A = test.log_steps
        self.n_tests += H

        perm = rng.permutation(n)
        if isinstance(ctx.residual_model, (ReprojectionResidual, MahalanobisResidual)):
            return self._verify_compiled(ctx, R, t, samples, perm, log_consistent, log_inconsistent, log_A)
        own = np.zeros((H, n), dtype=bool)
        own[np.arange(H)[:, None], samples] = True
        own = own[:, perm]  # in checking order

        sq_all = np.empty((H, n))  # residuals, filled for every point a hypothesis reached
        alive = np.ones(H, dtype=bool)
        log_lambda = np.zeros(H)
        checked = np.zeros(H, dtype=np.int64)
        consistent = np.zeros(H, dtype=np.int64)
        start, size = 0, self.chunk
        while start < n and np.any(alive):
            stop = min(start + size, n)
            live = np.flatnonzero(alive)
            cols = perm[start:stop]
            sq = residuals_on(ctx, R[live], t[live], cols)  # (L, c)
            sq_all[live[:, None], cols[None, :]] = sq
            skip = own[live, start:stop]
            inside = (sq < ctx.threshold_sq) & ~skip
            step = np.where(skip, 0.0, np.where(inside, log_consistent, log_inconsistent))
            running = log_lambda[live, None] + np.cumsum(step, axis=1)
            crossed = running > log_A
            rejected = np.any(crossed, axis=1)
            # Count only up to the first crossing: points after it were never needed.
            last = np.where(rejected, np.argmax(crossed, axis=1), stop - start - 1)
            rows = np.arange(live.size)
            checked[live] += np.cumsum(~skip, axis=1)[rows, last]
            consistent[live] += np.cumsum(inside, axis=1)[rows, last]
            log_lambda[live] = running[:, -1]
            alive[live[rejected]] = False
            start, size = stop, 2 * size

        return self._conclude(ctx, R, alive, checked, consistent, sq_all)

    def _verify_compiled(self, ctx, R, t, samples, perm, log_consistent, log_inconsistent, log_A):
        """The SPRT point by point in one compiled pass (reprojection or 3-D Mahalanobis residuals):
        a rejected hypothesis costs exactly the points it was checked on."""
        p = ctx.problem
        R, t = np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(t, dtype=float)
        samples, perm = np.ascontiguousarray(samples, dtype=np.int64), np.ascontiguousarray(perm, dtype=np.int64)
        steps = (float(log_consistent), float(log_inconsistent), float(log_A))
        if isinstance(ctx.residual_model, MahalanobisResidual):
            # capped at the gate where the quality saturates there, as full scoring is
            cap = float(ctx.threshold_sq) if ctx.quality.saturates else 0.0
            alive, checked, consistent, sq_all = sprt_verify_mahalanobis(
                R, t, p.points_prev, p.points_curr, p.camera.parameters, p.noise_sigma**2, cap,
                float(ctx.threshold_sq), samples, perm, *steps,
            )
        else:
            alive, checked, consistent, sq_all = sprt_verify(
                R, t, p.points_prev, p.curr, p.camera.parameters, float(ctx.threshold_sq), samples, perm, *steps,
            )
        return self._conclude(ctx, R, alive, checked, consistent, sq_all)

    def _conclude(self, ctx, R, alive, checked, consistent, sq_all):
        """Scores of the accepted hypotheses, the delta estimate from the rejected ones, the checks."""
        H, n = R.shape[0], ctx.problem.n
        scores = np.full(H, -np.inf)
        rows = np.flatnonzero(alive)
        n_alive = int(rows.size)
        if n_alive:
            scores[rows] = ctx.quality.score(sq_all[rows], ctx.threshold_sq)
            row_of = np.full(H, -1, dtype=np.int64)
            row_of[rows] = np.arange(n_alive)
            ctx.remember(R, sq_all[rows], row_of)
            dead = ~alive
            checked, consistent = checked[dead], consistent[dead]
        self.n_accepted += n_alive
        rejected_checks = 0
        if n_alive < H:  # checked, consistent: of the rejected hypotheses only
            self._ratio_sum += float(np.sum(consistent / np.maximum(checked, 1)))
            self._n_rejected += H - n_alive
            rejected_checks = int(np.sum(checked))
        self._update_delta()
        return scores, rejected_checks + n_alive * n


@dataclass
class SprtTermination:
    """Stop when ``eta = prod_i (1 - P_g (1 - alpha_i))^{k_i} < eta0`` (Chum & Matas, "Optimal randomized RANSAC", PAMI 2008).

    ``P_g`` is the all-inlier probability of one draw of ``sampler`` for the best model's inliers
    (the without-replacement count formula for uniform sampling), ``alpha_i = A_i^-h_i`` the chance that test i rejected a good model, ``k_i`` the draws
    made under test i. Also a loop listener: ``on_batch`` charges each batch's draws to the
    test that was in force when the batch began (tests change only between batches).
    """

    verifier: SprtVerification
    confidence: float = 0.99
    max_iterations: int = 10_000
    sampler: object = None

    def __post_init__(self) -> None:
        check_bound(self.confidence, self.max_iterations)
        self.probability = SampleProbability(self.sampler, self.confidence)  # a PROSAC schedule needs it
        self._last_drawn = 0
        self._test_index = 0
        # alpha_i depends on the tests and on I_best only: cached per inlier count (the loop asks with
        # the count before and after a new best's local optimisation, so one entry would thrash)
        self._alphas_by_count: dict[int, tuple[list[SprtTest], list[float]]] = {}
        # the last answers: the loop asks after every batch, and between redesigns only the current
        # test's draws change, which the bound does not read (it needs the draws of the past tests)
        self._answers: dict[tuple, tuple] = {}

    def on_new_best(self, inliers: np.ndarray, state: LoopState) -> None:
        """The sampler's all-inlier chance for the new best (the verifier redesigns the test)."""
        self.probability.on_new_best(inliers, state)

    def on_batch(self, state: LoopState) -> None:
        self.verifier.history[self._test_index].draws += state.n_hypotheses - self._last_drawn
        self._last_drawn = state.n_hypotheses
        self._test_index = len(self.verifier.history) - 1

    def _good_model_rejection(self, n_inliers: int, n: int, history: list[SprtTest]) -> list[float]:
        """``alpha_i = A_i^-h_i`` of every test for a good model of inlier ratio ``I / N`` (0 if the test is off)."""
        tests, alphas = self._alphas_by_count.setdefault(n_inliers, ([], []))
        if len(self._alphas_by_count) > 16:  # counts from long-gone bests
            for count in list(self._alphas_by_count)[:-16]:
                del self._alphas_by_count[count]
        # The verifier only appends tests, so the cached prefix is normally still the history's; a
        # history whose kept prefix was replaced (another verifier's, or a test swapped) starts over.
        if len(tests) > len(history) or not all(a is b for a, b in zip(tests, history)):
            tests.clear()
            alphas.clear()
        epsilon = n_inliers / n
        for test in history[len(alphas) :]:
            h = good_model_exponent(epsilon, test.epsilon, test.delta) if test.active else 0.0
            alphas.append(rejection_probability(test.A, h) if test.active else 0.0)
            tests.append(test)
        return alphas

    def required(self, n_inliers: int, n: int) -> int:
        p_good = self.probability.of(n_inliers, n)
        if p_good <= 0:
            return self.max_iterations
        history = self.verifier.history
        # The bound reads the tests (fixed once designed) and the draws of all but the current one,
        # which change only at a redesign: the answer is kept per (I, N, P_g) with the tests and
        # draws it was computed for (the objects themselves, so a replaced test never matches).
        key = (n_inliers, n, p_good, self.confidence, self.max_iterations)
        tests, draws = tuple(history), tuple(test.draws for test in history[:-1])
        kept = self._answers.get(key)
        if kept is not None and kept[1] == draws and len(kept[0]) == len(tests) and all(
            a is b for a, b in zip(kept[0], tests)
        ):
            return kept[2]
        if len(self._answers) > 64:
            self._answers.clear()
        answer = self._bound(n_inliers, n, p_good, history)
        self._answers[key] = (tests, draws, answer)
        return answer

    def _bound(self, n_inliers: int, n: int, p_good: float, history: list[SprtTest]) -> int:
        alphas = self._good_model_rejection(n_inliers, n, history)
        log_eta = 0.0
        done = 0
        for test, alpha in zip(history[:-1], alphas[:-1]):
            log_eta += test.draws * np.log1p(-min(p_good * (1 - alpha), 1 - 1e-16))
            done += test.draws
        p_find = p_good * (1 - alphas[-1])
        if p_find >= 1:
            return min(done + 1, self.max_iterations)
        if p_find <= 0:
            # The current test rejects every good model, so only the past tests can have found one:
            # stop at once if they already reached the confidence, otherwise sampling cannot help.
            if log_eta <= np.log1p(-self.confidence):
                return int(np.clip(done, 1, self.max_iterations))
            return self.max_iterations
        k_current = (np.log1p(-self.confidence) - log_eta) / np.log1p(-p_find)
        return int(np.clip(done + np.ceil(max(k_current, 0.0)), 1, self.max_iterations))


SPRT_OPTIONS = ("sprt_t_m", "sprt_epsilon0", "sprt_delta0", "sprt_chunk")
declare_options({
    "sprt_t_m": Number(low=0.0, high=1e15, low_open=True, default=SprtVerification.t_m),
    "sprt_epsilon0": Number(low=0.0, high=1.0, low_open=True, high_open=True, default=SprtVerification.epsilon0),
    "sprt_delta0": Number(low=0.0, high=1.0, low_open=True, high_open=True, default=SprtVerification.delta0),
    "sprt_chunk": Integer(low=1, high=MAX_COUNT, default=SprtVerification.chunk),
})  # shared with usac


def sprt_verifier(problem, extra: dict) -> SprtVerification:
    """The SPRT verification of ``problem`` with the ``sprt_*`` options of ``extra``."""
    return SprtVerification(
        problem.n, t_m=float(extra["sprt_t_m"]), epsilon0=float(extra["sprt_epsilon0"]),
        delta0=float(extra["sprt_delta0"]), chunk=extra["sprt_chunk"],
    )


def with_sprt(components, problem, options, extra):
    """``components`` with the SPRT as verifier and, for an adaptive search, the SPRT-aware stop (its
    sampler's all-inlier chance kept: prior-aware with priors or a PROSAC order)."""
    verifier = sprt_verifier(problem, extra)
    components.verifier = verifier
    components.listeners.append(verifier)
    if options.budget is None:
        components.termination = SprtTermination(verifier, options.confidence, int(options.max_iterations),
                                                 components.sampler)
    return components


@register_method(
    "waldsac",
    "randomized RANSAC with the SPRT: early rejection, adaptive epsilon/delta, SPRT-aware stopping",
    "Matas & Chum 2005; Chum & Matas 2008",
    extra_options=SPRT_OPTIONS,
    reads=REPROJECTION_READS,  # the SPRT-aware stop is adaptive: a fixed budget replaces it
)
def _build_waldsac(problem, options, priors, order, extra):
    components = base_components(problem, options, priors, order, *reprojection_judge(options, InlierCount()))
    return with_sprt(components, problem, options, extra)


def build_probabilistic_sprt(problem, options, priors, order, extra):
    """``probabilistic+sprt``: the project's recipe with :func:`with_sprt`."""
    # The SPRT bounds its error on good models (alpha = A^-h, folded into the stop), so the cost of a
    # contaminated frame falls with the points checked per bad hypothesis (docs/performance.md).
    return with_sprt(build_probabilistic(problem, options, priors, order, extra), problem, options, extra)


PROBABILISTIC_SPRT = {
    "name": "probabilistic+sprt",
    "description": "probabilistic with the SPRT's early rejection (adaptive epsilon/delta, each hypothesis checked "
                   "point by point under the 3-D Mahalanobis gate until rejected) and the SPRT-aware stop; "
                   "the project's recipe otherwise",
    "reference": "Brink et al.; Matas & Chum 2005; Chum & Matas 2008",
    "extra_options": SPRT_OPTIONS,
    "defaults": PROBABILISTIC_RECIPE,
    "reads": PROBABILISTIC_READS,  # probabilistic's judge and refinement; the SPRT-aware stop is adaptive
}
"""``probabilistic+sprt``'s registration (:func:`~stereovo.estimation.registry.register_method`'s
arguments, with :func:`build_probabilistic_sprt`): the methods package registers it last, among the
``+`` variants, whose rows follow the papers' in the reports."""
