"""USAC: the universal RANSAC framework's composition of PROSAC sampling, SPRT verification and LO+.

``usac`` draws by PROSAC when given ``order=`` (else uniformly, or by ``priors=``), verifies with
the SPRT of :mod:`stereovo.estimation.methods.sprt`, refines every new best with the LO+ of
:mod:`stereovo.estimation.methods.lo` and stops at the earliest of SPRT's and PROSAC's bounds
(:class:`EarliestTermination`). It takes the ``sprt_*``, ``lo_*`` and ``prosac_*`` options under
the declarations of those modules (the ``prosac_*`` ones are checked without an order too).

Raguram, Chum, Pollefeys, Matas & Frahm, "USAC: A Universal Framework for Random Sample Consensus",
IEEE TPAMI 2013.
"""

from __future__ import annotations

from dataclasses import dataclass

from stereovo.estimation.estimator_options import OptionReads
from stereovo.estimation.methods.lo import LO_OPTIONS, inner_ransac_lo
from stereovo.estimation.methods.prosac import PROSAC_OPTIONS, prosac_sampler, prosac_termination
from stereovo.estimation.methods.sprt import SPRT_OPTIONS, SprtTermination, sprt_verifier
from stereovo.estimation.recipes import base_components, reprojection_judge
from stereovo.estimation.registry import register_method
from stereovo.estimation.roles.scoring import TruncatedQuadratic


@dataclass
class EarliestTermination:
    """Stop as soon as any of several rules allows it (USAC: SPRT's bound and PROSAC's); the rules
    listen through it, in their order."""

    rules: tuple

    @property
    def max_iterations(self) -> int:
        return min(rule.max_iterations for rule in self.rules)

    def required(self, n_inliers: int, n: int) -> int:
        return min(rule.required(n_inliers, n) for rule in self.rules)

    def on_new_best(self, inliers, state) -> None:
        for rule in self.rules:
            if hasattr(rule, "on_new_best"):
                rule.on_new_best(inliers, state)

    def on_batch(self, state) -> None:
        for rule in self.rules:
            if hasattr(rule, "on_batch"):
                rule.on_batch(state)

    def counters(self) -> dict[str, int | float]:
        """The rules' own counters, merged."""
        merged: dict[str, int | float] = {}
        for rule in self.rules:
            if callable(getattr(rule, "counters", None)):
                merged.update(rule.counters())
        return merged


@register_method(
    "usac",
    "USAC-like: PROSAC sampling if order= (else uniform/guided), SPRT verification, LO+, SPRT/PROSAC stop",
    "Raguram et al. 2013",
    extra_options=SPRT_OPTIONS + LO_OPTIONS + PROSAC_OPTIONS,
    # given an order, PROSAC's stop listens under a fixed budget too (see below); LO+ on every new best
    reads=OptionReads(judge="reprojection", refinement="plain", stop="prosac-given-order", local="own"),
)
def _build_usac(problem, options, priors, order, extra):
    components = base_components(problem, options, priors, None, *reprojection_judge(options, TruncatedQuadratic()))
    verifier = sprt_verifier(problem, extra)
    components.verifier = verifier
    components.local_optimizer = inner_ransac_lo(extra)
    components.listeners.append(verifier)
    rules = []
    if options.budget is None:
        rules.append(SprtTermination(verifier, options.confidence, int(options.max_iterations), components.sampler))
    if order is not None:
        components.sampler = prosac_sampler(order, extra)
        prosac_stop = prosac_termination(components.sampler, options, extra)
        if options.budget is None:
            rules.append(prosac_stop)
        else:
            components.listeners.append(prosac_stop)  # lowers sampler.n_max to n* under a fixed budget too
    if rules:
        components.termination = EarliestTermination(tuple(rules)) if len(rules) > 1 else rules[0]
    return components
