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
    drop_unread,
    estimate_motion,
    estimate_problem,
    method_spec,
    register_method,
    validate_options,
)
from stereovo.estimation.estimator_options import UNREAD_CANDIDATES, OptionReads
from stereovo.estimation.registry import unread_options
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
@pytest.mark.parametrize("method", ["ransac", "probabilistic", "prosac", "usac", "ars", "msac+polish+lm"])
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


MAHALANOBIS_JUDGED = {"probabilistic", "probabilistic+sprt", "mlesac", "guided-mlesac", "ars", "bansac", "p-bansac"}


def test_threshold_px_is_refused_by_the_methods_judged_by_a_mahalanobis_gate():
    assert _message("probabilistic", threshold_px=2.0) == (
        "method 'probabilistic': threshold_px=2.0 would be ignored: method 'probabilistic' judges by the 3-D "
        "Mahalanobis gate (gate_probability) and selects its final inliers by a Mahalanobis gate too, never by the "
        "stereo reprojection gate whose threshold threshold_px is")
    # the default's own value, given, is refused as any given value is
    assert _message("bansac", threshold_px=None).startswith("method 'bansac': threshold_px=None would be ignored: ")
    refusing = {method for method in available_methods()
                if unread_options(method, validate_options(method, {})[0], ["threshold_px"])}
    assert refusing == MAHALANOBIS_JUDGED
    # read by the reprojection judges, their final refinement, and the clique's re-gating
    for method in ("ransac", "msac", "msac+polish+lm", "inlier-detection"):
        assert estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method=method, threshold_px=2.0).ok


def _accepted(method: str, **options):
    return estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method=method, rng=0, **options)


ONE_BATCH = "no later batch has a runner-up for runner_up_refit to refit"


def test_runner_up_refit_is_refused_where_the_search_draws_one_batch(monkeypatch):
    refit = {"local_refit": True, "runner_up_refit": 0.5}
    assert _message("ransac", budget=64, **refit) == (
        "method 'ransac': runner_up_refit=0.5 would be ignored: a fixed budget (budget=64) draws no more than its "
        f"first batch (batch_size=128): {ONE_BATCH}")
    assert _message("msac", max_iterations=16, **refit) == (
        "method 'msac': runner_up_refit=0.5 would be ignored: an adaptive search capped at max_iterations=16 draws no "
        f"more than its first batch (first_batch_size=16): {ONE_BATCH}")
    assert f"(batch_size=8): {ONE_BATCH}" in _message("msac", max_iterations=8, batch_size=8, **refit)
    assert f"(bansac_batch=8): {ONE_BATCH}" in _message("bansac", budget=8, bansac_batch=8, **refit)
    assert f"(bansac_batch=8, at most batch_size): {ONE_BATCH}" in _message(
        "p-bansac", budget=4, bansac_batch=8, batch_size=4, bansac_update="verdict-likelihood", **refit)
    assert f"(one hypothesis at least): {ONE_BATCH}" in _message("bansac", budget=1, **refit)
    # one hypothesis past the first batch is a second batch, which may have a runner-up
    for method, options in (("ransac", {"budget": 129}), ("ransac", {"budget": 64, "batch_size": 32}),
                            ("msac", {"max_iterations": 17}), ("msac", {"max_iterations": 8, "first_batch_size": 4}),
                            ("bansac", {"budget": 2}), ("bansac", {"budget": 9, "bansac_batch": 8})):
        _accepted(method, **options, **refit)
    assert _accepted("probabilistic", budget=256, batch_size=16, **refit).counters["runner_up_refits"] > 0
    # probabilistic's own runner_up_refit is a default: never refused, also where it cannot run
    assert _accepted("probabilistic", budget=64).counters["runner_up_refits"] == 0
    # run anyway, the refused refit never runs
    monkeypatch.setattr(api, "refuse_unread", lambda *args: None)
    for method, options in (("ransac", {"budget": 64}), ("msac", {"max_iterations": 16}), ("bansac", {"budget": 1})):
        assert _accepted(method, **options, **refit).counters["runner_up_refits"] == 0


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


def test_inlier_detection_reads_confidence_and_no_option_of_a_hypothesis_loop():
    # the RANSAC of its fit inside the clique stops at confidence under a cap of its own; no loop draws
    # hypotheses there for a budget, a cap, batches, minimal fits or a local refit
    options = validate_options("inlier-detection", {})[0]
    assert unread_options("inlier-detection", options, ["confidence"]) == {}
    message = _message("inlier-detection", budget=8)
    assert message.startswith("method 'inlier-detection': budget=8 would be ignored: method 'inlier-detection' "
                              "draws no hypotheses: it takes the maximum clique of consistent matches"), message
    assert estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="inlier-detection", confidence=0.5).ok


def test_defaults_are_never_refused_only_what_the_caller_gave():
    for method in available_methods():
        # a fixed budget where the method reads one: the defaults of the adaptive stop it replaces stay unrefused
        settings = {} if "budget" in unread_options(method, validate_options(method, {})[0], ["budget"]) \
            else {"budget": 8}
        options = validate_options(method, settings)[0]
        assert unread_options(method, options, settings) == {}, method
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


# ----------------------------------------------------------------------------- the parts of the methods

ONE_SET = "method 'preemptive' hands its whole set of hypotheses to the verifier in one batch"
CLIQUE = "method 'inlier-detection' draws no hypotheses: it "
BANSAC_BATCHES = "method 'bansac' draws its own batches between belief updates from the first"


@pytest.mark.parametrize("method, options, name, value, why", [
    ("preemptive", {}, "max_iterations", 50, "method 'preemptive' draws one set of M hypotheses (the budget, else "
                                             "its preemptive_hypotheses), which is its cap"),
    ("preemptive", {"budget": 64}, "max_iterations", 50, "method 'preemptive' draws one set of M hypotheses"),
    ("preemptive", {}, "batch_size", 64, f"{ONE_SET}: batch_size sizes none of its batches"),
    ("preemptive", {}, "first_batch_size", 8, f"{ONE_SET}: first_batch_size sizes none of its batches"),
    ("preemptive", {"local_refit": True, "refine": False, "least_squares_refit": False}, "runner_up_refit", 0.5,
     f"{ONE_SET}: no later batch has a runner-up"),
    ("preemptive", {"refine": True}, "local_refit", True, "method 'preemptive' draws its hypotheses in one batch, "
                                                          "which ends the search: the final refinement refits"),
    ("preemptive", {"fail_at_cap": False}, "confidence", 0.9, "with fail_at_cap=False returns their best whatever "
                                                              "the confidence"),
    ("bansac", {}, "batch_size", 8, f"{BANSAC_BATCHES} (bansac_batch; one hypothesis by default, the paper's): "
                                    "batch_size caps them only under bansac_update='verdict-likelihood', got "
                                    "bansac_update='paper'"),
    ("bansac", {}, "first_batch_size", 8, f"{BANSAC_BATCHES}"),
    ("p-bansac", {"bansac_update": "verdict-likelihood"}, "first_batch_size", 2, "method 'p-bansac' draws its own"),
    ("bansac", {}, "local_refit", False, "method 'bansac' refits every new best on its consensus whatever "
                                         "local_refit says"),
    ("ars", {}, "local_refit", True, "method 'ars' refits every new best on its consensus whatever local_refit says"),
    ("lo-ransac", {}, "local_refit", False, "method 'lo-ransac' runs its own local optimisation on every new best"),
    ("usac", {}, "local_refit", True, "method 'usac' runs its own local optimisation on every new best"),
    ("inlier-detection", {}, "max_iterations", 50, f"{CLIQUE}takes the maximum clique"),
    ("inlier-detection", {}, "fail_at_cap", False, "the clique is its verdict, which no cap fails"),
    ("inlier-detection+lm", {}, "batch_size", 64, "method 'inlier-detection+lm' draws no hypotheses: it fits its "
                                                  "motion on the maximum clique of consistent matches, so batch_size "
                                                  "sizes no batch"),
    ("inlier-detection", {}, "first_batch_size", 8, "so first_batch_size sizes no batch"),
    ("inlier-detection", {}, "polish_iterations", 2, "so no minimal fit is there for polish_iterations to polish"),
    ("inlier-detection", {}, "rigidity_gate_probability", 0.999, "so no minimal sample is there for the rigidity "
                                                                 "check"),
    ("inlier-detection+lm", {}, "local_refit", True, "has no hypothesis loop for a local refit to run in"),
    # the local_refit=True it needs is refused too, and named first
    ("inlier-detection", {"local_refit": True}, "runner_up_refit", 0.5, "local_refit=True would be ignored: method "
     "'inlier-detection' has no hypothesis loop for a local refit to run in; runner_up_refit=0.5 would be ignored: "
     "method 'inlier-detection' has no hypothesis loop"),
    ("inlier-detection", {}, "refine_iterations", 3, "method 'inlier-detection' with refine=False ends with its own "
                                                     "fit: no LM refinement runs for refine_iterations to set"),
    ("inlier-detection", {}, "refine_rounds", 2, "refine=False runs no iterated LM refinement: refine_rounds bounds "
                                                 "its rounds only with refine=True"),
    ("ransac", {}, "refine_rounds", 2, "refine=False runs no iterated LM refinement"),
    ("msac", {"least_squares_refit": False}, "refine_iterations", 3, "refine=False and least_squares_refit=False run "
                                                                     "no final refinement"),
    ("probabilistic", {"refine": False, "least_squares_refit": False}, "refine_iterations", 3, "run no final "
                                                                                               "refinement"),
])
def test_an_option_a_part_of_the_method_never_reads_is_refused_naming_it_its_value_and_why(method, options, name,
                                                                                         value, why):
    message = _message(method, **options, **{name: value})
    assert message.startswith(f"method {method!r}: ") and f"{name}={value!r} would be ignored: " in message, message
    assert why in message, message
    assert message.count("would be ignored") == 1 + ("local_refit=True would be ignored" in why), message


@pytest.mark.parametrize("method, options", [
    ("ransac", {"refine_iterations": 3}),  # the least-squares refit's LM steps
    ("ransac", {"refine": True, "refine_rounds": 2, "refine_iterations": 3}),
    ("preemptive", {"local_refit": True, "refine": False, "least_squares_refit": False}),  # the winner's refit
    ("preemptive", {"budget": 64}), ("preemptive", {"confidence": 0.9}),  # M; the check of fail_at_cap=True
    ("bansac", {"bansac_update": "verdict-likelihood", "batch_size": 2}),  # the cap of its batches
    ("bansac", {"local_refit": True, "runner_up_refit": 0.5}),  # what the runner-up refit needs
    ("lo-ransac", {"local_refit": True, "runner_up_refit": 0.5}),
    ("ars", {"batch_size": 8, "first_batch_size": 2}),  # the loop's schedule
    ("inlier-detection", {"refine": True, "refine_rounds": 2, "refine_iterations": 3, "gate_probability": 0.9}),
])
def test_what_the_parts_of_a_method_read_is_accepted(method, options):
    estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method=method, rng=0, **options)


def test_drop_unread_leaves_out_only_the_options_a_method_would_not_read():
    recipe = {"max_iterations": 500, "polish_iterations": 2, "local_refit": False, "refine": True,
              "refine_rounds": 2}
    assert drop_unread("ransac", recipe) == recipe
    assert drop_unread("preemptive", recipe) == {"polish_iterations": 2, "refine": True, "refine_rounds": 2}
    assert drop_unread("inlier-detection", recipe) == {"refine": True, "refine_rounds": 2}
    assert drop_unread("bansac", recipe) == {"max_iterations": 500, "polish_iterations": 2, "refine": True,
                                             "refine_rounds": 2}
    # among: only those may be left out; the others stay, for the method to refuse
    assert drop_unread("inlier-detection", recipe, among=["local_refit"]) == {
        "max_iterations": 500, "polish_iterations": 2, "refine": True, "refine_rounds": 2}
    with pytest.raises(ValueError, match="max_iterations=500 would be ignored"):
        estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="inlier-detection",
                        **drop_unread("inlier-detection", recipe, among=["local_refit"]))
    # what is left runs as the whole would have, bit for bit (the refusal switched off for the whole)
    kept = estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="preemptive", rng=1,
                           **drop_unread("preemptive", recipe))
    api_refuse = api.refuse_unread
    try:
        api.refuse_unread = lambda *args: None
        whole = estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="preemptive", rng=1, **recipe)
    finally:
        api.refuse_unread = api_refuse
    assert np.array_equal(kept.rotation, whole.rotation) and np.array_equal(kept.inliers, whole.inliers)


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
    with pytest.raises(ValueError, match="OptionReads.batches must be one of .*, got 'lots'"):
        OptionReads(judge="reprojection", refinement="plain", stop="adaptive", batches="lots")


ALTERNATIVES = {"confidence": (0.5, 0.9), "max_iterations": (2, 3), "budget": (5, 6), "batch_size": (3, 4),
                "first_batch_size": (1, 2), "gate_probability": (0.3, 0.5), "refine_gate_probability": (0.3, 0.5),
                "rigidity_gate_probability": (0.9, 0.99), "polish_iterations": (3, 1), "refine_iterations": (1, 2),
                "refine_rounds": (1, 4), "runner_up_refit": (0.2, 0.5), "threshold_px": (1.0, 2.0)}
"""Values of each numeric candidate: the first unlike the method's own is given; the switches get the
opposite of theirs."""

COMPANIONS = {"runner_up_refit": {"local_refit": True}}
"""What a candidate needs beside it to be a valid option (both runs get it)."""

SETTINGS = (
    {"budget": 8, "batch_size": 4},  # the method's own recipe under a budget
    {"budget": 8, "polish_iterations": 2, "refine": True, "refine_iterations": 3, "refine_rounds": 2},  # the env's
    {"budget": 8, "refine": False},
    {"budget": None, "max_iterations": 64, "refine": False, "least_squares_refit": False},
    {"budget": None, "max_iterations": 64, "refine": True},
    {"budget": 1},  # one hypothesis: one batch whatever the method's batches
    {"budget": None, "max_iterations": 8},  # an adaptive search within its first batch (first_batch_size 16)
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
            estimate_problem(problem, method, rng=0, **drop_unread(method, {"budget": 4}), **_inputs(frame, sampling))
        except ValueError:
            continue
        out.append(sampling)
    return out


def _alternative(name: str, options) -> object:
    value = getattr(options, name)
    return (not value) if isinstance(value, bool) else next(v for v in ALTERNATIVES[name] if v != value)


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
                settings = drop_unread(method, settings, order=order)
                options, extra = validate_options(method, settings, priors=sampling == "priors", order=order)
                given = {name: _alternative(name, options) for name in UNREAD_CANDIDATES - set(settings)}
                unread = unread_options(method, options, given, order=order, extra=extra)
                estimates = {}  # the estimates without the option, by the settings they ran with

                def run(frame_index, options):
                    frame, problem = frames[frame_index], problems[frame_index]
                    return estimate_problem(problem, method, rng=np.random.default_rng(frame_index),
                                            **_inputs(frame, sampling), **options)

                for name in unread:
                    base = {**settings, **COMPANIONS.get(name, {})}
                    with pytest.raises(ValueError, match=f"{name}=.* would be ignored"):
                        validate_options(method, {**base, name: given[name]}, priors=sampling == "priors",
                                         order=order)
                    with monkeypatch.context() as patch:
                        patch.setattr(api, "refuse_unread", lambda *args: None)
                        key = tuple(sorted(base.items()))
                        if key not in estimates:
                            estimates[key] = [run(i, base) for i in range(len(frames))]
                        for i, a in enumerate(estimates[key]):
                            b = run(i, {**base, name: given[name]})
                            assert (a.status, a.n_hypotheses, a.n_scored) == (b.status, b.n_hypotheses, b.n_scored), \
                                (method, sampling, settings, name)
                            assert np.array_equal(a.rotation, b.rotation), (method, sampling, settings, name)
                            assert np.array_equal(a.translation, b.translation), (method, sampling, settings, name)
                            assert np.array_equal(a.inliers, b.inliers), (method, sampling, settings, name)
                    checked.add((method, name))
    # each kind of refusal was among those checked, and none of what the methods do read
    loop = {"budget", "polish_iterations", "rigidity_gate_probability", "local_refit", "batch_size"}  # whatever
    # the settings; runner_up_refit too from a second batch on
    assert {("msac", name) for name in UNREAD_CANDIDATES - loop - {"threshold_px"}} <= checked, sorted(checked)
    assert {("probabilistic", name) for name in UNREAD_CANDIDATES - loop - {"gate_probability"}} <= checked
    assert {("inlier-detection", name) for name in UNREAD_CANDIDATES - {"confidence", "gate_probability",
                                                                       "threshold_px"}} <= checked
    assert {(m, "threshold_px") for m in ("probabilistic", "probabilistic+sprt", "mlesac", "guided-mlesac", "ars",
                                          "bansac", "p-bansac")} <= checked
    assert {(m, "runner_up_refit") for m in ("ransac", "usac", "lo-ransac", "ars", "bansac", "p-bansac")} <= checked
    assert {("preemptive", name) for name in ("max_iterations", "batch_size", "first_batch_size", "runner_up_refit",
                                               "local_refit", "confidence")} <= checked
    assert {(m, name) for m in ("bansac", "p-bansac") for name in ("batch_size", "first_batch_size", "local_refit")
            } <= checked
    assert {("ars", "local_refit"), ("lo-ransac", "local_refit"), ("usac", "local_refit"),
            ("lo-ransac+polish+lm", "local_refit"), ("inlier-detection+lm", "budget"), ("prosac", "max_iterations"),
            ("usac", "confidence")} <= checked
    assert not {(m, "gate_probability") for m in ("probabilistic", "mlesac", "bansac", "inlier-detection")} & checked
    assert not {(m, "threshold_px") for m in ("ransac", "msac", "prosac", "preemptive", "inlier-detection")} & checked
    assert not {("prosac", "confidence"), ("inlier-detection", "confidence")} & checked
    assert not ({(m, name) for m in ("msac", "probabilistic") for name in loop}
                | {("ars", name) for name in loop - {"local_refit"}}) & checked
    assert not {("preemptive", "budget"), ("ars", "batch_size"), ("bansac", "gate_probability")} & checked
