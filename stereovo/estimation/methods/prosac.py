"""PROSAC's termination: non-randomness and maximality (Chum & Matas 2005, "Matching with PROSAC -
progressive sample consensus", CVPR).

The sampler (:class:`~stereovo.estimation.roles.samplers.ProsacSampler`) grows the
set of top-ranked correspondences it draws from; this object decides when to
stop and how far the set may grow. On every new best model it computes, for
each prefix size n, the model's support ``I_n`` among the n top-ranked
correspondences and picks the termination length ``n*`` minimising the
draws ``k_n`` still needed among the prefixes that pass

- non-randomness: ``I_n >= I_n^min``, the smallest support that a wrong model reaches with
  probability below psi. The paper's definition: ``I_n^min = min{ j : sum_{i=j}^{n} P_n(i) < psi }``
  with ``P_n(i) = C(n - m, i - m) beta^(i - m) (1 - beta)^(n - i)`` (the m sample points agree with
  the model by construction, each of the other n - m by chance with probability beta); the exact
  binomial tail is tabulated once per run;
- maximality: ``k_n = log(eta0) / log(1 - q_n)`` with ``q_n`` the chance that a
  sample from ``U_n`` is all-inlier, ``prod_{j<m} (I_n - j) / (n - j)``;

ties go to the largest such prefix (the most data for the same bound). It then lowers the
sampler's ``n_max`` to ``n*`` and stops once ``k_n*`` samples have been drawn *from* ``U_n*``: the
paper's ``eta = (1 - q_n)^k`` holds for k samples all drawn from ``U_n``, so a draw that took a point
ranked below ``n*`` (made before ``n*`` was lowered) does not count. Every later draw lies in
``U_n*``, so the stop is at ``t + k_n* - (draws so far within U_n*)`` draws in all; while all draws
lie in ``U_n*`` that is ``t >= k_n*``. There is no guard on the inlier
fraction: the non-randomness test is what rejects a chance consensus, and a fraction guard
switches PROSAC's stop off whenever the inlier ratio is low (with a perfect ordering it then
needs RANSAC's thousands of draws instead of a handful). The one practical guard is ``min_n``:
prefixes shorter than it are not considered (their binomial test has too few points to mean much).

This module also declares the ``prosac_*`` options (shared with ``usac``) and registers ``prosac``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import binom, norm

from stereovo.estimation.estimator_options import MAX_COUNT, EstimatorOptions, OptionReads
from stereovo.estimation.loop import LoopState
from stereovo.estimation.recipes import base_components, reprojection_judge
from stereovo.estimation.registry import declare_options, register_method
from stereovo.estimation.roles.samplers import ProsacSampler
from stereovo.estimation.roles.scoring import InlierCount
from stereovo.estimation.roles.solvers import SAMPLE_SIZE
from stereovo.options import Integer, Number


def non_random_minimum(n: np.ndarray, beta: float, psi: float, m: int = SAMPLE_SIZE, exact: bool = True) -> np.ndarray:
    """``I_n^min`` ``(len(n),)``: the support below which a model on ``U_n`` may be random.

    ``exact``: the paper's binomial definition, the smallest ``j`` with
    ``P(m + Binomial(n - m, beta) >= j) < psi``; otherwise its normal approximation
    ``m + (n - m) beta + z_{1-psi} sqrt((n - m) beta (1 - beta))``.
    """
    n = np.maximum(np.asarray(n, dtype=float), m)
    if not exact:
        mu = (n - m) * beta
        sigma = np.sqrt((n - m) * beta * (1 - beta))
        return m + mu + sigma * norm.ppf(1 - psi)
    trials = n - m
    # smallest x with P(X <= x) > 1 - psi; then P(X >= x + 1) < psi, so j = m + x + 1
    x = binom.ppf(1 - psi, trials, beta)
    x = np.where(binom.cdf(x, trials, beta) > 1 - psi, x, x + 1)
    return m + x + 1


def prefix_draws(support: np.ndarray, n: np.ndarray, eta0: float, m: int = SAMPLE_SIZE) -> np.ndarray:
    """``k_n = log(eta0) / log(1 - q_n)``, ``q_n = prod_{j<m} (I_n - j)/(n - j)``; inf when q_n = 0, 1 when q_n = 1."""
    I = np.asarray(support, dtype=float)
    n = np.asarray(n, dtype=float)
    q = np.ones_like(I)
    for j in range(m):
        q = q * np.clip(I - j, 0, None) / np.maximum(n - j, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.log(eta0) / np.log1p(-np.minimum(q, 1.0))
    return np.where(q <= 0, np.inf, np.where(q >= 1, 1.0, k))


@dataclass
class ProsacTermination:
    """PROSAC's stopping rule; a loop listener that lowers ``sampler.n_max`` to ``n*``.

    Args:
        sampler: the PROSAC sampler whose ``order`` ranks the correspondences.
        confidence: ``eta0 = 1 - confidence`` (0.99 -> 0.01; the paper's 0.05 is confidence 0.95).
        max_iterations: hard cap on draws.
        beta: chance that a point is consistent with a wrong model.
        psi: tolerated probability that the chosen support is random.
        min_n: smallest prefix considered for termination.
    """

    sampler: ProsacSampler
    confidence: float = 0.99
    max_iterations: int = 10_000
    beta: float = 0.05
    psi: float = 0.05
    min_n: int = 20

    def __post_init__(self) -> None:
        for name, ok in (
            ("prosac_beta", 0 < self.beta < 1),
            ("prosac_psi", 0 < self.psi < 1),
            ("prosac_min_n", int(self.min_n) == self.min_n and self.min_n >= SAMPLE_SIZE + 1),
        ):
            if not ok:
                raise ValueError(f"option {name} has an invalid value {getattr(self, name.removeprefix('prosac_'))!r}")
        self.k_stop = float(self.max_iterations)  # k_n*: the draws from U_n* that maximality asks for
        self.stop_at = self.max_iterations  # all draws (t) after which PROSAC stops
        self.n_star: int | None = None
        N = self.sampler.order.shape[0]
        self._n = np.arange(1, N + 1)
        self._minimum = non_random_minimum(self._n, self.beta, self.psi)  # depends on n only: once per run
        self.updates = 0

    def on_new_best(self, inliers: np.ndarray, state: LoopState) -> None:
        order = self.sampler.order
        N = order.shape[0]
        support = np.cumsum(inliers[order])  # support[n-1] = I_n
        n = self._n
        ok = (n >= min(self.min_n, N)) & (support >= self._minimum)
        if not np.any(ok):
            return  # no non-random prefix yet: keep drawing (n_max and the bound unchanged)
        k = np.where(ok, prefix_draws(support, n, 1.0 - self.confidence), np.inf)
        best = np.flatnonzero(k == np.min(k))[-1]  # ties: the largest prefix, the most data
        if not np.isfinite(k[best]):
            return
        self.n_star = int(n[best])
        self.k_stop = float(k[best])
        self.sampler.n_max = self.n_star
        # From here on every draw lies in U_n*; the ones before count only if they did.
        within = self.sampler.drawn_within(self.n_star)
        self.stop_at = self.sampler.t + max(int(np.ceil(min(self.k_stop, self.max_iterations))) - within, 0)
        self.updates += 1

    def required(self, n_inliers: int, n: int) -> int:
        return int(np.clip(self.stop_at, 1, self.max_iterations))

    def counters(self) -> dict[str, int | float]:
        """``prosac_n_star``: the termination length (N if never set); ``prosac_k_stop``: its bound
        ``k_n*`` (draws from ``U_n*``); ``prosac_stop_at``: the draws in all at which it stops."""
        return {
            "prosac_n_star": int(self.n_star if self.n_star is not None else self.sampler.order.shape[0]),
            "prosac_k_stop": float(self.k_stop),
            "prosac_stop_at": int(self.stop_at),
            "prosac_updates": int(self.updates),
        }


PROSAC_OPTIONS = ("prosac_beta", "prosac_psi", "prosac_min_n", "prosac_t_n")
declare_options({
    "prosac_beta": Number(low=0.0, high=1.0, low_open=True, high_open=True, default=ProsacTermination.beta),
    "prosac_psi": Number(low=0.0, high=1.0, low_open=True, high_open=True, default=ProsacTermination.psi),
    "prosac_min_n": Integer(low=4, high=MAX_COUNT, default=ProsacTermination.min_n),
    "prosac_t_n": Number(low=1.0, high=1e15, default=200_000.0),
})  # shared with usac, which checks them without an order too


def prosac_sampler(order: np.ndarray, extra: dict) -> ProsacSampler:
    """PROSAC's sampler on ``order`` with the ``prosac_t_n`` of the method options ``extra``."""
    return ProsacSampler(order, t_n=float(extra["prosac_t_n"]))


def prosac_termination(sampler: ProsacSampler, options: EstimatorOptions, extra: dict) -> ProsacTermination:
    """PROSAC's stop for ``sampler`` with the ``prosac_*`` options of ``extra``."""
    return ProsacTermination(
        sampler, options.confidence, int(options.max_iterations),
        beta=float(extra["prosac_beta"]), psi=float(extra["prosac_psi"]), min_n=extra["prosac_min_n"],
    )


@register_method(
    "prosac",
    "progressive sampling from the top of order= (required), PROSAC's non-randomness and maximality stop",
    "Chum & Matas 2005",
    extra_options=PROSAC_OPTIONS,
    inputs="order",
    # its stop listens under a fixed budget too (see below): confidence stays read there
    reads=OptionReads(judge="reprojection", refinement="plain", stop="prosac"),
)
def _build_prosac(problem, options, priors, order, extra):
    if order is None:
        raise ValueError("method 'prosac' needs order=: a permutation of range(N), best correspondence first")
    components = base_components(problem, options, None, None, *reprojection_judge(options, InlierCount()))
    sampler = prosac_sampler(order, extra)
    stop = prosac_termination(sampler, options, extra)
    components.sampler = sampler
    if options.budget is None:
        components.termination = stop
    else:
        components.listeners.append(stop)  # lowers sampler.n_max to n* under a fixed budget too
    return components
