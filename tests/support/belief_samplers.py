"""The numpy formulation of BANSAC's and ARS's samplers as they were before their updates were
compiled (commit f05dc62): the reference that
``tests/stereovo/estimation/kernels/test_beliefs.py`` holds the compiled samplers to, bit for bit,
and that ``scripts/bench_belief_samplers.py`` times them against.

Only the sampler classes are kept here; the formulas they call (``log_odds_update``,
``baysac_failure_update``, ``prior_beliefs``) are still the modules' own numpy functions.

The logistic takes its ``exp`` from the C library (:func:`libm_exp`), as the compiled kernels do:
numpy's own float64 ``exp`` is vectorised where the CPU has AVX-512 and then differs from the C
library's in the last bit for about 5 % of arguments (measured on an AMD EPYC), which moved a
belief across a weight level's rounding edge in 2 of 5302 cases; on CPUs without AVX-512 the two
are the same function.
"""

from __future__ import annotations

import math

import numpy as np

from stereovo.estimation.methods.ars import CANDIDATES, baysac_failure_update
from stereovo.estimation.methods.bansac import (
    BANSAC_THRESHOLD,
    WEIGHT_FLOOR,
    WEIGHT_LEVELS,
    WEIGHTINGS,
    initial_beliefs,
    log_odds_update,
    prior_beliefs,
    sequential_all_inlier_probability,
)
from stereovo.estimation.roles.solvers import SAMPLE_SIZE
from stereovo.estimation.roles.samplers import WeightedSampler

_TRIPLES = np.array([(a, b, c) for a in range(CANDIDATES) for b in range(a + 1, CANDIDATES)
                     for c in range(b + 1, CANDIDATES)], dtype=np.int64)


def libm_exp(x):
    """``exp`` of each element by the C library (Python's ``math.exp``): what numba compiles ``math.exp`` to."""
    return np.vectorize(math.exp, otypes=[float])(x)


def reference_logistic(log_odds):
    """``exp(-logaddexp(0, -l))`` with numpy's ``logaddexp`` and the C library's ``exp``."""
    return libm_exp(-np.logaddexp(0.0, -np.asarray(log_odds, dtype=float)))


class ReferenceBansacSampler:
    """BANSAC's sampler in numpy: a new ``WeightedSampler`` after every update."""

    def __init__(self, n, priors=None, threshold=BANSAC_THRESHOLD, initial_probability=0.5, prior_ceiling=None,
                 weights="discretised"):
        assert weights in WEIGHTINGS
        self.n, self.threshold, self.weighting = n, float(threshold), weights
        p = prior_beliefs(n, priors, initial_probability, prior_ceiling)
        self.log_odds = np.log(p) - np.log1p(-p)
        self.updates = self.best_inliers_seen = 0
        self.best_support = 0
        self._sampler = None

    @property
    def beliefs(self):
        return reference_logistic(self.log_odds)

    @property
    def sampling_weights(self):
        if self.weighting == "belief":
            return np.maximum(self.beliefs, WEIGHT_FLOOR)
        return np.maximum(np.ceil(WEIGHT_LEVELS * self.beliefs), 1.0)

    def draw(self, batch, rng):
        if self._sampler is None:
            self._sampler = WeightedSampler(self.sampling_weights)
        return self._sampler.draw(batch, rng)

    def apply(self, verdicts):
        k = int(np.count_nonzero(verdicts))
        self.log_odds = log_odds_update(self.log_odds, verdicts, k / self.n)
        self.best_inliers_seen = max(self.best_inliers_seen, k)
        self.updates += 1
        self._sampler = None

    def on_hypotheses(self, R, t, inlier_masks, residual_sq, state):
        for verdicts in inlier_masks:
            self.apply(verdicts)
        best = state.best_inliers
        self.best_support = self.best_inliers_seen if best is None else int(np.count_nonzero(best))

    def outlier_count(self):
        return int(np.count_nonzero(self.log_odds < math.log(self.threshold) - math.log1p(-self.threshold)))

    def stop_rule_met(self, n_best_inliers):
        return self.updates > 0 and self.outlier_count() >= self.n - int(n_best_inliers)

    def all_inlier_probability(self, inliers):
        return sequential_all_inlier_probability(self.sampling_weights, inliers)

    def counters(self):
        return {"bansac_updates": self.updates, "bansac_outlier_beliefs": self.outlier_count()}


class ReferenceArsSampler:
    """ARS's sampler in numpy: a lexsort, the 56 candidate products and a set of tuples per draw."""

    def __init__(self, n, priors=None, initial_probability=0.5, prior_ceiling=0.6):
        self.n = n
        self.beliefs = initial_beliefs(n, priors, initial_probability, prior_ceiling)
        self._tie_break = None
        self._tried = set()
        self._pending = {}
        self._best_support = -1
        self.successes = 0

    def _most_probable_untried(self):
        p = self.beliefs
        k = min(CANDIDATES, self.n)
        top = np.lexsort((self._tie_break, -p))[:k]
        triples = top[_TRIPLES[np.all(_TRIPLES < k, axis=1)]]
        value = np.prod(p[triples], axis=1)
        for j in np.argsort(-value, kind="stable"):
            key = tuple(sorted(int(i) for i in triples[j]))
            if key not in self._tried:
                return triples[j]
        return triples[int(np.argmax(value))]

    def draw(self, batch, rng):
        if self._tie_break is None:
            self._tie_break = rng.permutation(self.n)
        out = np.empty((batch, SAMPLE_SIZE), dtype=np.int64)
        for row in range(batch):
            sample = self._most_probable_untried()
            key = tuple(sorted(int(i) for i in sample))
            self._tried.add(key)
            self._pending[key] = self.beliefs[sample].copy()
            self.beliefs = baysac_failure_update(self.beliefs, sample)
            out[row] = sample
        return out

    def on_hypotheses(self, R, t, inlier_masks, residual_sq, state):
        support = np.count_nonzero(inlier_masks, axis=1)
        for sample, count in zip(state.samples, support):
            key = tuple(sorted(int(i) for i in sample))
            before = self._pending.pop(key, None)
            if count > self._best_support:
                self._best_support = int(count)
                if before is not None:
                    self.beliefs[sample] = before
                    self.successes += 1
        self._pending.clear()

    def all_inlier_probability(self, inliers):
        return float(np.all(inliers[self._most_probable_untried()]))

    def counters(self):
        return {"ars_successes": self.successes, "ars_tried": len(self._tried)}
