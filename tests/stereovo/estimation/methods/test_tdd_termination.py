"""The stop of R-RANSAC with the T(d,d) pretest (TddTermination; Matas & Chum 2002/2004): the bound
stretched by the good models' pass probability, against values worked out by hand."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from stereovo.estimation.methods.tdd import TddTermination


def test_tdd_bound_is_stretched_by_the_pass_probability():
    # N = 20, I = 6, d = 1: a good hypothesis' pre-test point is one of the 17 others, 3 of them inliers:
    # alpha = 3 / 17; k = ceil(log(0.01) / log(1 - 0.017544 * 3 / 17)) = ceil(1485.2) = 1486.
    q = 6 * 5 * 4 / (20 * 19 * 18)
    assert math.ceil(math.log(0.01) / math.log(1 - q * 3 / 17)) == 1486  # the arithmetic itself
    assert TddTermination(confidence=0.99, d=1).required(6, 20) == 1486
    # d = 2: alpha = (3 / 17) * (2 / 16); k = ceil(11897.3) = 11898.
    assert TddTermination(confidence=0.99, d=2, max_iterations=100_000).required(6, 20) == 11898
    # A measured pass probability replaces the fallback: alpha = 1/2 gives ceil(log(0.01) / log(1 - q / 2)) =
    # ceil(522.6) = 523, alpha = 1/4 gives ceil(1047.7) = 1048 (and no measurement yet: the fallback, 1486).
    assert math.ceil(math.log(0.01) / math.log(1 - q / 2)) == 523
    assert math.ceil(math.log(0.01) / math.log(1 - q / 4)) == 1048
    for measured, expected in ((0.5, 523), (0.25, 1048), (None, 1486)):
        # A verifier whose pre-test stayed on for every draw (n_off = 0), with the measured alpha.
        verifier = SimpleNamespace(alpha=lambda measured=measured: measured, active=True, n_on=0, n_off=0)
        assert TddTermination(confidence=0.99, d=1, verifier=verifier).required(6, 20) == expected, measured
    # Plain RANSAC's 261 is the d = 0 limit: the pre-test only ever stretches the bound.
    assert TddTermination(confidence=0.99, d=1).required(300, 300) == 1
    assert TddTermination(confidence=0.99, d=1, max_iterations=900).required(3, 300) == 900


# --- The T(d,d) stopping bound against values derived by hand ---

def _q(i, n):
    return math.comb(i, 3) / math.comb(n, 3)


def _k(q, p=0.99, cap=10_000):
    if q >= 1:
        return 1
    return cap if q <= 0 else min(max(math.ceil(math.log(1 - p) / math.log(1 - q)), 1), cap)


class _Verifier:
    """Stands in for TddVerification in the bound: a measured alpha and the draws with the test on and off."""

    def __init__(self, alpha, n_on, n_off, active):
        self._a, self.n_on, self.n_off, self.active = alpha, n_on, n_off, active

    def alpha(self):
        return self._a


class _Guided:
    """A guided sampler: q is a function of the inlier mask it is given."""

    def all_inlier_probability(self, inliers):
        return 0.5 * float(np.mean(inliers))


def test_tdd_bound_without_a_verifier_by_hand():
    # uniform sampling, no measured alpha: k = log(1 - p) / log(1 - q alpha) with q = C(I, 3) / C(N, 3) and
    # alpha = prod_{j<d} (I - 3 - j) / (N - 3 - j), the chance for a hypothesis explaining the whole support
    for i, n, d in ((60, 100, 1), (60, 100, 2), (20, 150, 1), (40, 50, 3)):
        term = TddTermination(d=d)
        alpha = math.comb(i - 3, d) / math.comb(n - 3, d)
        assert term.required(i, n) == _k(_q(i, n) * alpha)
        assert term.last_alpha == pytest.approx(alpha, rel=1e-12)
        assert term.counters() == {"tdd_alpha_used": term.last_alpha}
        assert term.required(i, n) == _k(_q(i, n) * alpha)  # the cached q
    # a support of only the sample: no point outside it is consistent, alpha = 0, the cap
    term = TddTermination(d=1)
    assert term.required(3, 8) == 10_000 and term.last_alpha == 0.0
    # before any bound: no alpha used yet
    assert math.isnan(TddTermination().counters()["tdd_alpha_used"])


def test_tdd_bound_with_a_guided_sampler_takes_its_q():
    term = TddTermination(d=1, sampler=_Guided())
    mask = np.zeros(100, dtype=bool)
    mask[:40] = True
    term.on_new_best(mask, None)
    alpha = 37 / 97
    assert term.required(40, 100) == _k(0.2 * alpha)


def test_tdd_bound_with_the_test_switched_on_and_off_by_hand():
    # the draws so far under each mode: (1 - q alpha)^k_on (1 - q)^k_off <= 1 - p, then what the current mode
    # needs beyond the draws made: drawn + ceil((log(1 - p) - log_miss) / log(1 - per_draw))
    i, n = 25, 100
    q = _q(i, n)
    for alpha, n_on, n_off, active, drawn in ((0.3, 10, 20, True, 30), (0.3, 10, 1, True, 11), (0.3, 10, 20, False, 30),
                                              (0.3, 50, 0, False, 50), (0.25, 5, 3, True, 0)):
        term = TddTermination(d=1, verifier=_Verifier(alpha, n_on, n_off, active))
        if drawn:
            term.on_batch(SimpleNamespace(n_hypotheses=drawn))
        log_miss = n_on * math.log(1 - q * alpha) + n_off * math.log(1 - q)
        per_draw = q * alpha if active else q
        remaining = (math.log(0.01) - log_miss) / math.log(1 - per_draw)
        assert remaining > 0 and term.required(i, n) == drawn + math.ceil(remaining), (alpha, n_on, n_off, active)
        assert term.last_alpha == alpha
    # with the test on throughout the bound ignores the draws: the plain T(d,d) bound
    term = TddTermination(d=1, verifier=_Verifier(0.3, 50, 0, True))
    assert term.required(i, n) == _k(q * 0.3)
    # the draws so far already suffice: at least one
    term = TddTermination(d=1, verifier=_Verifier(0.3, 10, 1000, False))
    assert term.required(i, n) == 1
    # a good hypothesis that cannot pass the test (alpha = 0) while it is on: never enough, the cap
    assert TddTermination(d=1, verifier=_Verifier(0.0, 10, 5, True)).required(i, n) == 10_000
    assert TddTermination(d=1, verifier=_Verifier(0.3, 10, 5, True)).required(2, n) == 10_000  # q = 0


def test_tdd_bound_when_every_draw_is_good():
    # q = 1 and alpha = 1 (every point an inlier): the next draw is good; the draws' misses are clamped below 1
    for active in (True, False):
        term = TddTermination(d=1, max_iterations=50, verifier=_Verifier(1.0, 5, 2, active))
        assert term.required(20, 20) == 1
        term.on_batch(SimpleNamespace(n_hypotheses=7))
        assert term.required(20, 20) == 8
        term.on_batch(SimpleNamespace(n_hypotheses=50))
        assert term.required(20, 20) == 50
