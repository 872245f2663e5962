"""The seed's qualitative claims about the classical methods, each judged against a run's numbers.

:func:`check_claims` turns a :class:`~stereovo.benchmark.aggregation.BenchmarkSummary` into one
:class:`ClaimCheck` per claim ("guided sampling cuts iterations", "SPRT saves time", ...): its
verdict (:data:`AGREES`, :data:`DISAGREES` or :data:`NOT_MEASURED`), the numbers behind it, the
frames they pool, the reference row and a diagnosis. The thresholds of the verdicts are the
module constants (``CUT_RATIO`` ...). Measured diagnoses that need frames re-simulated come from
:func:`stereovo.benchmark.diagnostics.claim_diagnostics`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping

import numpy as np

from stereovo.benchmark.aggregation import BenchmarkSummary, finite_stat
from stereovo.reporting import format_number, format_percent

AGREES = "agrees"
DISAGREES = "does not agree"
NOT_MEASURED = "not measured"

CUT_RATIO = 0.9  # "cuts iterations" / "saves time": at most 90 % of the reference
COST_RATIO = 1.1  # "costs time": at least 110 % of the reference
ACCURACY_RATIO = 0.9  # "gains accuracy": a median error at most 90 % of the reference ...
SUCCESS_MARGIN = 0.02  # ... or a success rate at least 2 points higher, and nothing worse by more than these
CONSTANT_TIME_SPREAD = 1.5  # "constant time": slowest / fastest per-epsilon median time at most this
UNRELIABLE_DROP = 0.10  # "unreliable": success at the heaviest epsilon 10 points below the lightest ...
UNRELIABLE_MAX = 0.9  # ... and below 90 %
HEAVY_EPSILON = 0.6  # the heaviest contamination in the run must reach this for the contamination claims
ROBUST_MARGIN = 0.05  # "robust": success at the heaviest epsilon within 5 points of RANSAC's (or better)
QUADRATIC_SLOPE = 1.5  # "quadratic": log-log slope of median time vs N at least this


@dataclass(frozen=True)
class ClaimCheck:
    """One qualitative claim of the seed, tested with our numbers."""

    key: str
    claim: str
    source: str
    numbers: str
    verdict: str
    note: str = ""
    reference: str = ""  # which row the claim is judged against, and why that one is the fair reference
    measured_on: str = ""  # the frames (cells) the compared numbers pool
    context: str = ""  # the same comparison between the '+ enhancement' rows, for what the additions change
    diagnosis: str = ""  # a measured figure of the method on these frames that explains the verdict


def thresholds_text() -> str:
    """The verdicts' thresholds in words, as every claims report states them."""
    return (
        f"Thresholds: \"cuts\" / \"saves\" = at most {CUT_RATIO:g}x the reference; \"costs\" = at least"
        f" {COST_RATIO:g}x; \"gains accuracy\" = a median error at most {ACCURACY_RATIO:g}x or success"
        f" +{100 * SUCCESS_MARGIN:g} points, nothing worse by as much; \"constant time\" = slowest/fastest"
        f" per-epsilon median time at most {CONSTANT_TIME_SPREAD:g}x; \"unreliable\" = success at the heaviest"
        f" epsilon below {100 * UNRELIABLE_MAX:g} % and {100 * UNRELIABLE_DROP:g} points below the lightest;"
        f" \"robust\" = success at the heaviest epsilon within {100 * ROBUST_MARGIN:g} points of the reference's;"
        f" \"quadratic\" = log-log slope of median time vs N at least {QUADRATIC_SLOPE:g}."
    )


def _ratio(a: float | None, b: float | None) -> float | None:
    if a is None or b is None or b <= 0:
        return None
    return a / b


def _missing(summary: BenchmarkSummary, *methods: str) -> list[str]:
    return [m for m in methods if m not in summary.overall]


def _not_measured(key: str, claim: str, source: str, why: str, note: str = "") -> ClaimCheck:
    return ClaimCheck(key, claim, source, why, NOT_MEASURED, note)


def _fewer_hypotheses(summary: BenchmarkSummary, key: str, method: str, reference: str, claim: str, source: str,
                      note: str = "") -> ClaimCheck:
    """Mean hypotheses of ``method`` vs ``reference`` at the most informative match-score AUC of the run."""
    absent = _missing(summary, method, reference)
    if absent:
        return _not_measured(key, claim, source, f"{', '.join(absent)} not in this run", note)
    per_a, per_b = summary.by_auc.get(method, {}), summary.by_auc.get(reference, {})
    aucs = sorted(set(per_a) & set(per_b))
    if aucs:
        best = aucs[-1]
        if best <= 0.5:
            return _not_measured(key, claim, source, "the match scores of this run are uninformative (AUC 0.5)", note)
        a, b, where = per_a[best], per_b[best], f"at AUC {best:g}"
    else:
        a, b, where = summary.overall[method], summary.overall[reference], "pooled"
    ma, mb = finite_stat(a, "mean_hypotheses"), finite_stat(b, "mean_hypotheses")
    r = _ratio(ma, mb)
    if r is None:
        return _not_measured(key, claim, source, "no hypothesis counts", note)
    numbers = (
        f"{where}: mean hypotheses {method} {format_number(ma, '.0f')} vs {reference} {format_number(mb, '.0f')} (x{r:.2f}),"
        f" success {format_percent(finite_stat(a, 'success_rate'))} vs {format_percent(finite_stat(b, 'success_rate'))}"
    )
    fa, fb = finite_stat(a, "mean_hypotheses_to_best"), finite_stat(b, "mean_hypotheses_to_best")
    if fa is not None and fb is not None:
        numbers += (f", hypotheses until the final best was found {fa:.0f} vs {fb:.0f}"
                    f" (x{format_number(_ratio(fa, fb), '.2f')})")
    for auc in aucs[:-1]:
        other = _ratio(finite_stat(per_a[auc], "mean_hypotheses"), finite_stat(per_b[auc], "mean_hypotheses"))
        numbers += f"; at AUC {auc:g}: x{format_number(other, '.2f')}"
    if aucs:
        numbers += _per_epsilon(summary, method, reference, aucs[-1])
    return ClaimCheck(key, claim, source, numbers, AGREES if r <= CUT_RATIO else DISAGREES, note)


def _per_epsilon(summary: BenchmarkSummary, method: str, reference: str, auc: float) -> str:
    """``; by epsilon at AUC a: e1 xr1 (success s1 vs s1'), ...``: the hypothesis ratio of each
    contamination of the run at one AUC (empty when the run has a single epsilon)."""
    per_a, per_b = summary.by_epsilon_auc.get(method, {}), summary.by_epsilon_auc.get(reference, {})
    cells = sorted(e for (e, a) in set(per_a) & set(per_b) if a == auc)
    if len(cells) < 2:
        return ""
    parts = []
    for e in cells:
        a, b = per_a[(e, auc)], per_b[(e, auc)]
        r = _ratio(finite_stat(a, "mean_hypotheses"), finite_stat(b, "mean_hypotheses"))
        parts.append(f"{e:g} x{format_number(r, '.2f')} ({format_percent(finite_stat(a, 'success_rate'))}"
                     f" vs {format_percent(finite_stat(b, 'success_rate'))})")
    return f"; by epsilon at AUC {auc:g} (mean hypotheses, success): " + ", ".join(parts)


def _time_vs(summary: BenchmarkSummary, key: str, method: str, reference: str, claim: str, source: str,
             faster: bool, note: str = "") -> ClaimCheck:
    absent = _missing(summary, method, reference)
    if absent:
        return _not_measured(key, claim, source, f"{', '.join(absent)} not in this run", note)
    a, b = summary.overall[method], summary.overall[reference]
    ta, tb = finite_stat(a, "median_time_ms"), finite_stat(b, "median_time_ms")
    r = _ratio(ta, tb)
    if r is None:
        return _not_measured(key, claim, source, "no timings", note)
    pa, pb = finite_stat(a, "mean_point_checks"), finite_stat(b, "mean_point_checks")
    numbers = (
        f"median time {method} {format_number(ta, '.1f')} ms vs {reference} {format_number(tb, '.1f')} ms (x{r:.2f});"
        f" mean point checks {format_number(pa, '.3g')} vs {format_number(pb, '.3g')}"
    )
    if len(summary.epsilons) > 1:
        heavy = summary.epsilons[-1]
        ha = finite_stat(summary.by_epsilon.get(method, {}).get(heavy), "median_time_ms")
        hb = finite_stat(summary.by_epsilon.get(reference, {}).get(heavy), "median_time_ms")
        if ha is not None and hb is not None:
            numbers += f"; at epsilon {heavy:g}: {ha:.1f} ms vs {hb:.1f} ms (x{format_number(_ratio(ha, hb), '.2f')})"
    ok = r <= CUT_RATIO if faster else r >= COST_RATIO
    return ClaimCheck(key, claim, source, numbers, AGREES if ok else DISAGREES, note)


def _accuracy_vs(summary: BenchmarkSummary, key: str, method: str, reference: str, claim: str, source: str,
                 note: str = "") -> ClaimCheck:
    absent = _missing(summary, method, reference)
    if absent:
        return _not_measured(key, claim, source, f"{', '.join(absent)} not in this run", note)
    a, b = summary.overall[method], summary.overall[reference]
    rot = _ratio(finite_stat(a, "median_rot_err_deg"), finite_stat(b, "median_rot_err_deg"))
    trans = _ratio(finite_stat(a, "median_trans_err_m"), finite_stat(b, "median_trans_err_m"))
    sa, sb = finite_stat(a, "success_rate"), finite_stat(b, "success_rate")
    if rot is None or trans is None or sa is None or sb is None:
        return _not_measured(key, claim, source, "no error statistics", note)
    gain = sa - sb
    numbers = (
        f"median rotation error {method} {format_number(finite_stat(a, 'median_rot_err_deg'), '.3g')} deg vs"
        f" {reference} {format_number(finite_stat(b, 'median_rot_err_deg'), '.3g')} deg (x{rot:.2f}); median translation error"
        f" {format_number(finite_stat(a, 'median_trans_err_m'), '.3g')} m vs {format_number(finite_stat(b, 'median_trans_err_m'), '.3g')} m"
        f" (x{trans:.2f}); success {format_percent(sa)} vs {format_percent(sb)}"
    )
    better = rot <= ACCURACY_RATIO or trans <= ACCURACY_RATIO or gain >= SUCCESS_MARGIN
    worse = rot > 1 / ACCURACY_RATIO or trans > 1 / ACCURACY_RATIO or gain <= -SUCCESS_MARGIN
    return ClaimCheck(key, claim, source, numbers, AGREES if better and not worse else DISAGREES, note)


def _constant_time(summary: BenchmarkSummary, key: str, method: str, claim: str, source: str,
                   note: str = "") -> ClaimCheck:
    if _missing(summary, method):
        return _not_measured(key, claim, source, f"{method} not in this run", note)
    per = summary.by_epsilon.get(method, {})
    times = {e: finite_stat(s, "median_time_ms") for e, s in per.items()}
    times = {e: t for e, t in times.items() if t is not None and t > 0}
    if len(times) < 2:
        return _not_measured(key, claim, source, "needs at least two epsilon values", note)
    spread = max(times.values()) / min(times.values())
    hyps = {e: finite_stat(s, "median_hypotheses") for e, s in per.items()}
    numbers = (
        "median time by epsilon: " + ", ".join(f"{e:g}: {t:.1f} ms" for e, t in sorted(times.items()))
        + f" (max/min x{spread:.2f}); median hypotheses: "
        + ", ".join(f"{e:g}: {format_number(h, '.0f')}" for e, h in sorted(hyps.items()))
    )
    ref = summary.by_epsilon.get("ransac", {})
    ref_times = [t for t in (finite_stat(s, "median_time_ms") for s in ref.values()) if t is not None and t > 0]
    if len(ref_times) >= 2:
        numbers += f"; ransac max/min x{max(ref_times) / min(ref_times):.2f}"
    return ClaimCheck(key, claim, source, numbers, AGREES if spread <= CONSTANT_TIME_SPREAD else DISAGREES, note)


def _epsilon_span(summary: BenchmarkSummary, method: str) -> tuple[float, float] | None:
    per = summary.by_epsilon.get(method, {})
    return (min(per), max(per)) if per else None


def _unreliable_when_contaminated(summary: BenchmarkSummary, key: str, method: str, claim: str, source: str,
                                  note: str = "") -> ClaimCheck:
    if _missing(summary, method):
        return _not_measured(key, claim, source, f"{method} not in this run", note)
    span = _epsilon_span(summary, method)
    if span is None or span[1] < HEAVY_EPSILON or span[0] == span[1]:
        return _not_measured(key, claim, source, f"needs epsilon values up to >= {HEAVY_EPSILON:g} and a lighter one", note)
    light, heavy = span
    s_light = finite_stat(summary.by_epsilon[method][light], "success_rate")
    s_heavy = finite_stat(summary.by_epsilon[method][heavy], "success_rate")
    if s_light is None or s_heavy is None:
        return _not_measured(key, claim, source, "no success rates", note)
    numbers = f"success {method} at epsilon {light:g}: {format_percent(s_light)}, at {heavy:g}: {format_percent(s_heavy)}"
    ref = finite_stat(summary.by_epsilon.get("ransac", {}).get(heavy), "success_rate")
    if ref is not None and method != "ransac":
        numbers += f"; ransac at {heavy:g}: {format_percent(ref)}"
    ok = s_heavy < UNRELIABLE_MAX and s_light - s_heavy >= UNRELIABLE_DROP
    return ClaimCheck(key, claim, source, numbers, AGREES if ok else DISAGREES, note)


def _robust_when_contaminated(summary: BenchmarkSummary, key: str, method: str, reference: str, claim: str,
                              source: str, note: str = "") -> ClaimCheck:
    absent = _missing(summary, method, reference)
    if absent:
        return _not_measured(key, claim, source, f"{', '.join(absent)} not in this run", note)
    span = _epsilon_span(summary, method)
    if span is None or span[1] < HEAVY_EPSILON:
        return _not_measured(key, claim, source, f"needs an epsilon value >= {HEAVY_EPSILON:g}", note)
    heavy = span[1]
    s = finite_stat(summary.by_epsilon[method].get(heavy), "success_rate")
    r = finite_stat(summary.by_epsilon.get(reference, {}).get(heavy), "success_rate")
    if s is None or r is None:
        return _not_measured(key, claim, source, f"no success rates at epsilon {heavy:g}", note)
    numbers = (
        f"success at epsilon {heavy:g}: {method} {format_percent(s)} vs {reference} {format_percent(r)};"
        f" overall {format_percent(finite_stat(summary.overall[method], 'success_rate'))}"
        f" vs {format_percent(finite_stat(summary.overall[reference], 'success_rate'))}"
    )
    return ClaimCheck(key, claim, source, numbers, AGREES if s >= r - ROBUST_MARGIN else DISAGREES, note)


def _loglog_slope(points: Mapping[int, float]) -> float:
    x = np.log([float(n) for n in points])
    y = np.log([float(t) for t in points.values()])
    return float(np.polyfit(x, y, 1)[0])


def _quadratic(summary: BenchmarkSummary, key: str, method: str, claim: str, source: str, note: str = "") -> ClaimCheck:
    if _missing(summary, method):
        return _not_measured(key, claim, source, f"{method} not in this run", note)
    per = {n: finite_stat(s, "median_time_ms") for n, s in summary.by_n.get(method, {}).items()}
    per = {n: t for n, t in per.items() if t is not None and t > 0}
    if len(per) < 2:
        return _not_measured(key, claim, source, "needs at least two values of N", note)
    slope = _loglog_slope(per)
    numbers = (
        "median time by N: " + ", ".join(f"{n}: {t:.1f} ms" for n, t in sorted(per.items()))
        + f" (log-log slope {slope:.2f})"
    )
    ref = {n: finite_stat(s, "median_time_ms") for n, s in summary.by_n.get("ransac", {}).items()}
    ref = {n: t for n, t in ref.items() if t is not None and t > 0}
    if len(ref) >= 2 and method != "ransac":
        numbers += f"; ransac slope {_loglog_slope(ref):.2f}"
    return ClaimCheck(key, claim, source, numbers, AGREES if slope >= QUADRATIC_SLOPE else DISAGREES, note)


def _frames_text(stats: Mapping[str, Any] | None, where: str) -> str:
    frames = finite_stat(stats, "frames")
    return f"{frames:.0f} frames {where}" if frames is not None else where


def _measured_on(summary: BenchmarkSummary, key: str, method: str) -> str:
    """The frames behind a claim's numbers, in words (the cells the statistics pool)."""
    per_auc = summary.by_auc.get(method, {})
    heavy = summary.epsilons[-1] if summary.epsilons else None
    if key.endswith("-iterations") and per_auc:
        best = max(per_auc)
        return _frames_text(per_auc[best], f"per method at AUC {best:g}, pooled over every epsilon and N of the run")
    if key in ("preemptive-unreliable", "clique-robust") and heavy is not None:
        return _frames_text(summary.by_epsilon.get(method, {}).get(heavy),
                            f"per method at epsilon {heavy:g} (every AUC and N), beside the lightest epsilon / the overall rate")
    if key == "preemptive-constant-time":
        return "per-epsilon medians, each pooled over every AUC and N"
    if key == "clique-quadratic":
        return "per-N medians, each pooled over every epsilon and AUC"
    return _frames_text(summary.overall.get(method), "per method: every cell of the run")


def _context(check: ClaimCheck, label: str) -> str:
    """The '+ enhancement' comparison as one clause (empty when those rows are not in the run)."""
    if check.verdict == NOT_MEASURED:
        return ""
    return f"{label}: {check.numbers} (on its own it would read: {check.verdict})"


def preemptive_miss_probability(epsilon: float, hypotheses: float) -> float:
    """Probability that none of ``hypotheses`` uniform minimal samples is all-inlier at contamination
    ``epsilon``: ``(1 - (1 - epsilon)^3)^M`` (samples of 3 drawn with replacement, the bound's own model)."""
    return float((1.0 - (1.0 - float(epsilon)) ** 3) ** float(hypotheses))


def _constant_time_diagnosis(summary: BenchmarkSummary) -> str:
    per = summary.by_epsilon.get("preemptive", {})
    checks = {e: finite_stat(st, "median_point_checks") for e, st in per.items()}
    checks = {e: c for e, c in checks.items() if c is not None}
    if len(checks) < 2:
        return ""
    spread = max(checks.values()) / min(checks.values()) if min(checks.values()) > 0 else math.nan
    return ("median point checks by epsilon: " + ", ".join(f"{e:g}: {c:,.0f}" for e, c in sorted(checks.items()))
            + f" (max/min x{spread:.2f}): the preemptive scoring itself is constant; the time spread is work"
            " outside it (the final least-squares refit on the selected inliers, whose number falls with epsilon)")


def _preemptive_diagnosis(summary: BenchmarkSummary) -> str:
    per = summary.by_epsilon.get("preemptive", {})
    if not per:
        return ""
    heavy = max(per)
    m = finite_stat(per[heavy], "median_hypotheses")
    if m is None:
        return ""
    lines = [f"with M = {m:.0f} hypotheses the chance that none is an all-inlier sample is"
             f" {100 * preemptive_miss_probability(heavy, m):.1f} % at epsilon {heavy:g}"]
    for eps in (0.85, 0.9):
        if eps > heavy:
            lines.append(f"{100 * preemptive_miss_probability(eps, m):.0f} % at {eps:g}")
    return (", ".join(lines) + " (the bound's model): below that the fixed budget almost always holds a"
            " good hypothesis, and a failure comes from ranking the hypotheses on blocks of B observations")


def check_claims(summary: BenchmarkSummary, diagnostics: Mapping[str, str] | None = None) -> list[ClaimCheck]:
    """The seed's qualitative claims, one by one, against our numbers.

    Each verdict is :data:`AGREES`, :data:`DISAGREES` or :data:`NOT_MEASURED`
    (a method or an axis the claim needs is absent). The thresholds are the
    module constants (``CUT_RATIO`` ...); the numbers behind each verdict are
    in :attr:`ClaimCheck.numbers`, the frames they pool in ``measured_on``, the
    row each claim is judged against (and why) in ``reference``, the same
    comparison between '+ enhancement' rows in ``context``, and a measured
    figure that explains the verdict in ``diagnosis``: from ``diagnostics``
    (:func:`claim_diagnostics`, keyed by claim key; ``"support"`` is added to
    every claim judged against textbook ``ransac``) or computed from the summary.
    """
    diagnostics = dict(diagnostics or {})
    textbook = (
        "the textbook `ransac` row (minimal fits, inlier count, exact stop, one least-squares refit of the"
        " final inliers): {why}"
    )
    same_recipe = textbook.format(why="the claimed method is that recipe plus the one change the claim is about")
    paper_reference = textbook.format(
        why="the paper compares against plain RANSAC, and the claimed method also runs its paper's recipe without"
            " the project's enhancements"
    )
    checks = [
        _fewer_hypotheses(
            summary, "guided-mlesac-iterations", "guided-mlesac", "mlesac",
            "Guided sampling cuts iterations: Guided-MLESAC draws fewer hypotheses than MLESAC.",
            "Tordoff & Murray 2002/2005",
            "Priors gamma_i are the match scores calibrated to inlier probabilities (P(inlier | score) at an"
            " uninformed inlier share of one half), as Tordoff & Murray's gamma_i are. Judged at the run's most"
            " informative AUC. The adaptive stop is"
            " prior-aware (q is the probability that one draw of the guided sampler is all-inlier), so finding the"
            " best model sooner can cut the hypotheses drawn.",
        ),
        _fewer_hypotheses(
            summary, "guided-ransac-iterations", "ransac+guided", "ransac",
            "Guided sampling cuts iterations: RANSAC with score-weighted sampling draws fewer hypotheses.",
            "Tordoff & Murray 2002",
            "The adaptive stop is prior-aware: q is the all-inlier probability of one weighted draw.",
        ),
        _fewer_hypotheses(
            summary, "prosac-iterations", "prosac", "ransac",
            "PROSAC cuts iterations: sampling from the top-ranked matches first draws fewer hypotheses.",
            "Chum & Matas 2005",
            "PROSAC's own stop (non-randomness and maximality, no inlier-fraction guard).",
        ),
        _time_vs(
            summary, "lo-ransac-time", "lo-ransac", "ransac",
            "Lo-RANSAC costs time.", "Chum, Matas & Kittler 2003; Lebeda, Matas & Chum 2012", faster=False,
        ),
        _accuracy_vs(
            summary, "lo-ransac-accuracy", "lo-ransac", "ransac",
            "Lo-RANSAC gains accuracy.", "Chum, Matas & Kittler 2003; Lebeda, Matas & Chum 2012",
        ),
        _time_vs(
            summary, "r-ransac-time", "r-ransac", "ransac",
            "R-RANSAC (T(d,d) pre-test) saves time.", "Matas & Chum 2002/2004", faster=True,
            note="T(d,d) runs compiled and uses its measured pass probability alpha in the stop (switched off where"
            " it does not pay).",
        ),
        _time_vs(
            summary, "waldsac-time", "waldsac", "ransac",
            "SPRT (WaldSAC) saves time.", "Matas & Chum 2005; Chum & Matas 2008", faster=True,
            note="The SPRT runs compiled, point by point; full scoring is one compiled pass per batch.",
        ),
        _constant_time(
            summary, "preemptive-constant-time", "preemptive",
            "Preemptive RANSAC is constant-time (independent of contamination).", "Nistér 2003/2005",
        ),
        _unreliable_when_contaminated(
            summary, "preemptive-unreliable", "preemptive",
            "Preemptive RANSAC is unreliable when heavily contaminated.", "Nistér 2003/2005",
        ),
        _robust_when_contaminated(
            summary, "clique-robust", "inlier-detection", "ransac+polish+refit+lm",
            "Inlier detection by maximum clique is robust to heavy contamination.",
            "Hirschmüller et al. 2002; Howard 2008",
        ),
        _quadratic(
            summary, "clique-quadratic", "inlier-detection",
            "Inlier detection by maximum clique is quadratic in N.", "Hirschmüller et al. 2002; Howard 2008",
            "The slope is measured over this run's N values only: at small N, per-frame costs that grow"
            " linearly (triangulation, the final refinement) hide the O(N^2) consistency matrix;"
            " probe larger N with --ns 500,1000,2000.",
        ),
    ]
    references = {
        "guided-mlesac-iterations": "the `mlesac` row: the same likelihood and stop, uniform sampling",
        "guided-ransac-iterations": same_recipe,
        "prosac-iterations": paper_reference,
        "lo-ransac-time": paper_reference,
        "lo-ransac-accuracy": paper_reference,
        "r-ransac-time": same_recipe,
        "waldsac-time": same_recipe,
        "preemptive-constant-time": "none (the `ransac` per-epsilon spread is shown beside it)",
        "preemptive-unreliable": "its own success at the lightest epsilon (textbook `ransac` shown beside it)",
        "clique-robust": "the '+ enhancement' row `ransac+polish+refit+lm`: a robustness claim needs a reference"
                         " that is itself robust on this data, and textbook `ransac` is not at the heaviest epsilon"
                         " (its closed-form minimal fits under-count their support, see the diagnosis); textbook"
                         " `ransac` is in the context",
        "clique-quadratic": "none (the textbook `ransac` slope is shown beside it)",
    }
    enhanced = {  # claim key -> (check of the '+ enhancement' pair, label)
        "lo-ransac-time": (_time_vs(summary, "", "lo-ransac+polish+lm", "ransac+polish+refit+lm", "", "", faster=False),
                           "with the project's additions on both sides"),
        "lo-ransac-accuracy": (_accuracy_vs(summary, "", "lo-ransac+polish+lm", "ransac+polish+refit+lm", "", ""),
                               "with the project's additions on both sides"),
        "clique-robust": (_robust_when_contaminated(summary, "", "inlier-detection", "ransac", "", ""),
                          "textbook rows on both sides"),
    }
    support = diagnostics.get("support", "")
    out = []
    for check in checks:
        method = {"guided-mlesac-iterations": "guided-mlesac", "guided-ransac-iterations": "ransac+guided",
                  "prosac-iterations": "prosac", "lo-ransac-time": "lo-ransac", "lo-ransac-accuracy": "lo-ransac",
                  "r-ransac-time": "r-ransac", "waldsac-time": "waldsac"}.get(
            check.key, "preemptive" if check.key.startswith("preemptive") else "inlier-detection")
        diagnosis = diagnostics.get(check.key, "")
        if check.key == "preemptive-unreliable":
            diagnosis = _preemptive_diagnosis(summary)
        if check.key == "preemptive-constant-time":
            diagnosis = _constant_time_diagnosis(summary)
        if support and "textbook" in references[check.key] and check.key != "clique-quadratic":
            diagnosis = "; ".join(d for d in (diagnosis, support) if d)
        pair = enhanced.get(check.key)
        out.append(replace(
            check,
            reference=references[check.key],
            measured_on="" if check.verdict == NOT_MEASURED else _measured_on(summary, check.key, method),
            context=_context(*pair) if pair else "",
            diagnosis="" if check.verdict == NOT_MEASURED else diagnosis,
        ))
    return out
