"""An option a method would not read with the other options is refused by the estimator itself, naming it,
its value and why, never accepted and ignored; only options the caller gave count.

Each method declares what its recipe reads when it registers (``MethodSpec.reads``: its judge, final
refinement and stop). The property test checks the declarations against the recipes: every option they
refuse leaves the method's estimates bit for bit unchanged when it is run anyway (the refusal switched off).
"""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation import (
    PreparedEstimator,
    StereoProblem,
    api,
    available_methods,
    estimate_motion,
    estimate_problem,
    method_spec,
    register_method,
    validate_options,
)
from stereovo.estimation.estimator_options import UNREAD_CANDIDATES, OptionReads
from stereovo.estimation.registry import split_options, unread_options
from stereovo.simulation import SimulationConfig, simulate_frame

FRAME = simulate_frame(SimulationConfig(n_correspondences=80, outlier_ratio=0.4), np.random.default_rng(5))
ORDER = np.argsort(-FRAME.scores, kind="stable")
FIXED_BUDGET = ("a fixed budget (budget=64) draws exactly that many hypotheses per frame")
ADAPTIVE = "(budget=None switches to the adaptive stop)"


def _message(method: str, **options) -> str:
    with pytest.raises(ValueError) as err:
        estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method=method, rng=0, **options)
    return str(err.value)


# ----------------------------------------------------------------------------- the messages

def test_confidence_under_a_fixed_budget_is_refused_naming_it_its_value_and_why():
    assert _message("ransac", budget=64, confidence=0.5) == (
        f"method 'ransac': confidence=0.5 would be ignored: {FIXED_BUDGET}: no adaptive stop runs for confidence "
        f"to set {ADAPTIVE}")
    # read, and accepted, by the adaptive stop
    assert estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="ransac", confidence=0.5).ok


@pytest.mark.parametrize("name, value, why", [
    ("max_iterations", 5, "above any cap: max_iterations caps an adaptive search"),
    ("first_batch_size", 4, "in batches of batch_size: first_batch_size sizes an adaptive search's first batch"),
    ("fail_at_cap", False, ": the budget is the stop itself, never a cap reached before a stop, so no estimate "
                           "fails at it"),
])
@pytest.mark.parametrize("method", ["ransac", "probabilistic", "prosac", "usac", "bansac", "msac+polish+lm"])
def test_the_adaptive_stops_options_are_refused_under_a_fixed_budget_by_every_loop_method(method, name, value, why):
    inputs = {"order": ORDER} if method == "prosac" else {}
    message = _message(method, budget=64, **inputs, **{name: value})
    assert message.startswith(f"method {method!r}: {name}={value!r} would be ignored: {FIXED_BUDGET}"), message
    assert why in message and message.endswith(ADAPTIVE), message


def test_several_unread_options_are_named_together_and_a_bad_value_is_named_first():
    message = _message("msac", budget=64, confidence=0.5, least_squares_refit=False, refine=True,
                       gate_probability=0.5)
    assert message.startswith("method 'msac': confidence=0.5 would be ignored: ")
    assert "; least_squares_refit=False would be ignored: refine=True ends with the iterated LM refinement; " in message
    assert "; gate_probability=0.5 would be ignored: method 'msac' judges by the stereo reprojection gate" in message
    assert "confidence must be a finite number in (0, 1), got 1.5" in _message("msac", budget=64, confidence=1.5)
    assert "unknown option(s) ['confidance']" in _message("msac", budget=64, confidance=0.5, confidence=0.5)


def test_least_squares_refit_is_refused_where_the_lm_refinement_replaces_it_and_where_no_refit_runs():
    assert _message("ransac", refine=True, least_squares_refit=False) == (
        "method 'ransac': least_squares_refit=False would be ignored: refine=True ends with the iterated LM "
        "refinement; least_squares_refit chooses the final step only with refine=False")
    # the variant's own refine=True, a default, leaves it unread too
    assert "least_squares_refit=True would be ignored" in _message("ransac+lm", least_squares_refit=True)
    # inlier-detection ends with its own fit: the LM refinement or nothing
    for refine in (False, True):
        assert _message("inlier-detection", refine=refine, least_squares_refit=True) == (
            "method 'inlier-detection': least_squares_refit=True would be ignored: method 'inlier-detection' ends "
            "with its own fit, refined only by the iterated LM refinement of refine=True: no least-squares refit "
            "runs for least_squares_refit to choose")
    assert estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="ransac", least_squares_refit=False).ok


def test_the_gate_quantiles_are_refused_where_no_such_gate_is():
    assert _message("msac", gate_probability=0.5) == (
        "method 'msac': gate_probability=0.5 would be ignored: method 'msac' judges by the stereo reprojection "
        "gate (threshold_px), not by the 3-D Mahalanobis gate whose quantile gate_probability is")
    for method in ("msac", "mlesac", "inlier-detection"):
        assert f"refine_gate_probability=0.5 would be ignored: method {method!r} has no pixel-gated final " \
               "refinement" in _message(method, refine_gate_probability=0.5)
    assert "no final refinement runs for its pixel gate" in _message(
        "probabilistic", refine=False, least_squares_refit=False, refine_gate_probability=0.5)
    # read where the gate is: the 3-D gate of probabilistic, MLESAC and the clique's fit; probabilistic's pixel gate
    for method, options in (("probabilistic", {"gate_probability": 0.9, "refine_gate_probability": 0.9}),
                            ("mlesac", {"gate_probability": 0.9}), ("inlier-detection", {"gate_probability": 0.9})):
        estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method=method, **options)


def test_the_prosac_stop_reads_confidence_under_a_budget_and_usac_only_given_an_order():
    assert estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="prosac", order=ORDER, budget=64,
                           confidence=0.5).n_hypotheses == 64
    estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="usac", order=ORDER, budget=64, confidence=0.5)
    assert _message("usac", budget=64, confidence=0.5).startswith("method 'usac': confidence=0.5 would be ignored")
    # validate_options without the sampling input keeps it (an order may come); told there is none, refuses it
    validate_options("usac", {"budget": 64, "confidence": 0.5})
    validate_options("usac", {"budget": 64, "confidence": 0.5}, order=True)
    with pytest.raises(ValueError, match="confidence=0.5 would be ignored"):
        validate_options("usac", {"budget": 64, "confidence": 0.5}, priors=True)


def test_inlier_detection_reads_confidence_whatever_the_budget():
    # the RANSAC of its fit inside the clique stops at it; no loop draws a budget there
    assert unread_options("inlier-detection", validate_options("inlier-detection", {"budget": 8})[0],
                          ["confidence"]) == {}


def test_defaults_are_never_refused_only_what_the_caller_gave():
    for method in available_methods():
        assert unread_options(method, validate_options(method, {"budget": 8})[0], ["budget"]) == {}
    # probabilistic's recipe sets refine=True, under which its default least_squares_refit is unread
    estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="probabilistic", budget=16)
    estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="ransac+lm", budget=16)


def test_every_entry_point_refuses_alike():
    problem = StereoProblem.build(FRAME.prev, FRAME.curr, FRAME.camera, 0.5)
    expected = _message("ransac", budget=8, fail_at_cap=False)
    for call in (lambda: validate_options("ransac", {"budget": 8, "fail_at_cap": False}),
                 lambda: estimate_problem(problem, "ransac", budget=8, fail_at_cap=False),
                 lambda: PreparedEstimator("ransac", budget=8, fail_at_cap=False).estimate(problem)):
        with pytest.raises(ValueError) as err:
            call()
        assert str(err.value) == expected
    # a prepared usac reads confidence under its budget with an order only, and says so without one
    prepared = PreparedEstimator("usac", budget=8, confidence=0.5)
    assert prepared.estimate(problem, order=ORDER).n_hypotheses == 8
    with pytest.raises(ValueError, match="method 'usac': confidence=0.5 would be ignored"):
        prepared.estimate(problem)
    with pytest.raises(ValueError, match="would be ignored"):  # refused again, not remembered as accepted
        prepared.estimate(problem)


# ----------------------------------------------------------------------------- the declarations

def test_every_method_declares_what_it_reads_and_the_variants_keep_their_bases():
    for name in available_methods():
        reads = method_spec(name).reads
        assert isinstance(reads, OptionReads), name
        assert reads == method_spec(name.split("+", 1)[0]).reads, name  # probabilistic+sprt: probabilistic's
    with pytest.raises(TypeError, match="reads"):
        register_method("no-reads", "a method that forgets to declare what it reads", "nobody")
    with pytest.raises(ValueError, match="OptionReads.judge must be one of"):
        OptionReads(judge="vibes", refinement="plain", stop="adaptive")


ALTERNATIVES = {"confidence": 0.5, "max_iterations": 2, "first_batch_size": 1, "gate_probability": 0.3,
                "refine_gate_probability": 0.3}
"""A value unlike the defaults of each numeric candidate; the switches get the opposite of theirs."""

SETTINGS = (
    {"budget": 8, "batch_size": 4},  # the method's own recipe under a budget
    {"budget": 8, "polish_iterations": 2, "refine": True, "refine_iterations": 3, "refine_rounds": 2},  # the env's
    {"budget": 8, "refine": False},
    {"budget": None, "max_iterations": 64, "refine": False, "least_squares_refit": False},
    {"budget": None, "max_iterations": 64, "refine": True},
)


def _frames() -> list:
    frames = []
    for outliers in ("default", "hostile"):
        config = SimulationConfig(n_correspondences=60, outlier_ratio=0.6, outliers=outliers)
        frames += [simulate_frame(config, np.random.default_rng([11, k])) for k in (1, 2)]
    return frames


def _inputs(frame, sampling: str) -> dict:
    return {"none": {}, "priors": {"priors": np.exp(frame.scores)},
            "order": {"order": np.argsort(-frame.scores, kind="stable")}}[sampling]


def _samplings(method: str, problem: StereoProblem, frame) -> list[str]:
    """The sampling inputs the method runs with (the belief samplers declare any but refuse an order)."""
    out = []
    for sampling in ("none", "priors", "order"):
        try:
            estimate_problem(problem, method, rng=0, budget=4, **_inputs(frame, sampling))
        except ValueError:
            continue
        out.append(sampling)
    return out


def _alternative(name: str, options) -> object:
    value = getattr(options, name)
    return (not value) if isinstance(value, bool) else ALTERNATIVES[name]


def test_every_option_a_method_is_refused_leaves_its_estimates_unchanged(monkeypatch):
    """Refusing an option that a method does read would take a setting away: this catches a declaration
    that drifts from its recipe. The second run gets the option with the refusal switched off, i.e. the
    estimate it would have given."""
    frames = _frames()
    problems = [StereoProblem.build(f.prev, f.curr, f.camera, 0.5) for f in frames]
    checked = set()
    for method in available_methods():
        spec = method_spec(method)
        for sampling in _samplings(method, problems[0], frames[0]):
            for settings in SETTINGS:
                # what of the settings the method itself would not read is left out, as a caller must
                order = sampling == "order"
                settings = {k: v for k, v in settings.items()
                            if k not in unread_options(method, split_options(spec, settings)[0], settings, order)}
                options, _ = validate_options(method, settings, priors=sampling == "priors", order=order)
                given = {name: _alternative(name, options) for name in UNREAD_CANDIDATES - set(settings)}
                unread = unread_options(method, options, given, order=order)
                for name in unread:
                    with pytest.raises(ValueError, match=f"{name}=.* would be ignored"):
                        validate_options(method, {**settings, name: given[name]}, priors=sampling == "priors",
                                         order=order)
                    with monkeypatch.context() as patch:
                        patch.setattr(api, "refuse_unread", lambda *args: None)
                        for i, (frame, problem) in enumerate(zip(frames, problems)):
                            a, b = (estimate_problem(problem, method, rng=np.random.default_rng(i),
                                                     **_inputs(frame, sampling), **run)
                                    for run in (settings, {**settings, name: given[name]}))
                            assert (a.status, a.n_hypotheses, a.n_scored) == (b.status, b.n_hypotheses, b.n_scored), \
                                (method, sampling, settings, name)
                            assert np.array_equal(a.rotation, b.rotation), (method, sampling, settings, name)
                            assert np.array_equal(a.translation, b.translation), (method, sampling, settings, name)
                            assert np.array_equal(a.inliers, b.inliers), (method, sampling, settings, name)
                    checked.add((method, name))
    # each kind of refusal was among those checked, and none of what the methods do read
    assert {("msac", name) for name in UNREAD_CANDIDATES} <= checked, sorted(checked)
    assert {("probabilistic", name) for name in UNREAD_CANDIDATES - {"gate_probability"}} <= checked
    assert {("inlier-detection", "least_squares_refit"), ("inlier-detection", "refine_gate_probability"),
            ("prosac", "max_iterations"), ("usac", "confidence")} <= checked
    assert not {(m, "gate_probability") for m in ("probabilistic", "mlesac", "bansac", "inlier-detection")} & checked
    assert not {("prosac", "confidence"), ("inlier-detection", "confidence")} & checked
