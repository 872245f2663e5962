"""estimate_motion / estimate_problem: the estimate's contract (malformed input, hopeless frames,
determinism, budgets, counters), every registered method on simulated frames, and fuzzing."""

from __future__ import annotations

import math
import re
import warnings
import zlib
from functools import lru_cache

import numpy as np
import pytest
from hypothesis import given, strategies as st

from stereovo import available_methods, estimate_motion
from stereovo.benchmark.runner import METHOD_INPUTS, score_inputs
from stereovo.estimation import drop_unread, method_spec, StereoProblem, estimate_problem, validate_options
from stereovo.geometry import random_rotation, rotation_error, se3_exp
from stereovo.metrics import is_success, frame_metrics
from stereovo.simulation import SimulationConfig, simulate_frame
from tests.support.frames import CAMERA, noise_free_pair
from tests.support.fuzz import (FUZZ, MALFORMED_KINDS, WEIRD_NUMBERS, WELL_FORMED_KINDS, corrupted, fuzz_frame,
                                measurements, names_an_argument)
from tests.support.methods import CLASSICAL
from tests.support.rows import spoil_rows


CORE_METHODS = ["ransac", "msac", "probabilistic"]


motions = st.tuples(
    st.floats(-0.15, 0.15), st.floats(-0.15, 0.15), st.floats(-0.15, 0.15),
    st.floats(-1.0, 1.0), st.floats(-0.5, 0.5), st.floats(-2.0, 0.5), st.integers(0, 2**31),
)


N_FRAMES = 200


def success_rate(method: str, epsilon: float) -> float:
    config = SimulationConfig(n_correspondences=500, outlier_ratio=epsilon, noise_sigma=0.5, outlier_mix=(0.8, 0.2, 0.0))
    seeds = np.random.SeedSequence(2024).spawn(N_FRAMES)
    ok = []
    for i, seed in enumerate(seeds):
        frame = simulate_frame(config, np.random.default_rng(seed))
        est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=i, noise_sigma=0.5)
        r_err = rotation_error(est.rotation, frame.truth.rotation)
        t_err = np.linalg.norm(est.translation - frame.truth.translation)
        ok.append(est.ok and bool(is_success(r_err, t_err, np.linalg.norm(frame.truth.translation))))
    return float(np.mean(ok))


@lru_cache(maxsize=None)
def frames(n: int = 300, epsilon: float = 0.5, count: int = 20, seed: int = 100) -> tuple:
    config = SimulationConfig(n_correspondences=n, outlier_ratio=epsilon)
    return tuple(simulate_frame(config, seed + i) for i in range(count))


def method_inputs(method: str, frame) -> dict:
    """What a caller gives each method: match scores as priors (guided) or as an order (PROSAC)."""
    if method == "guided-mlesac":
        return {"priors": frame.scores}
    if method in ("prosac", "usac"):
        return {"order": np.argsort(-frame.scores, kind="stable")}
    return {}


def succeeded(estimate, frame) -> bool:
    """Rotation within 1 degree and translation within max(5 cm, 5 %) of the truth."""
    t_true = frame.truth.translation
    return (
        estimate.ok
        and np.degrees(rotation_error(estimate.rotation, frame.truth.rotation)) < 1.0
        and np.linalg.norm(estimate.translation - t_true) < max(0.05, 0.05 * np.linalg.norm(t_true))
    )


def run(method: str, frame, rng=0, **options):
    return estimate_motion(
        frame.prev, frame.curr, frame.camera, method=method, rng=rng, noise_sigma=frame.noise_sigma,
        **method_inputs(method, frame), **options,
    )


def inputs_for(method: str, n: int) -> dict:
    """Neutral priors / order of length n for the methods that require one."""
    if method == "guided-mlesac":
        return {"priors": np.ones(n)}
    if method in ("prosac", "usac"):
        return {"order": np.arange(n)}
    return {}


def _check_estimate(est, n: int) -> None:
    R, t, inliers = np.asarray(est.rotation), np.asarray(est.translation), np.asarray(est.inliers)
    assert R.shape == (3, 3) and t.shape == (3,)
    assert np.all(np.isfinite(R)) and np.all(np.isfinite(t))
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-6) and abs(np.linalg.det(R) - 1.0) < 1e-6
    assert inliers.dtype == bool and inliers.shape == (n,)
    assert est.status == "ok" or est.status.startswith("failed")
    if not est.ok:
        assert np.array_equal(R, np.eye(3)) and np.array_equal(t, np.zeros(3))


SHARED_FUZZ_OPTIONS = ("budget", "max_iterations", "confidence", "noise_sigma", "refine", "batch_size",
                       "min_inliers", "threshold_px", "polish_iterations")


FRAMES = [simulate_frame(SimulationConfig(n_correspondences=150, outlier_ratio=eps, outliers="hostile"), seed)
          for seed, eps in ((11, 0.5), (12, 0.8))]


@pytest.fixture(scope="module")
def rendered_frame():
    """One frame pair of a rendered drive through the ORB front end (real matcher errors)."""
    from tests.support.images import rendered

    sequence = rendered(preset="car", n_frames=2, resolution="vga", seed=3)
    frame = sequence.frame(1)
    sequence.close()
    return frame


@given(motions)
def test_noise_free_motion_recovered_to_1e9(m):
    wx, wy, wz, tx, ty, tz, seed = m
    R, _ = se3_exp(np.array([0, 0, 0, wx, wy, wz]))
    t = np.array([tx, ty, tz])
    prev, curr = noise_free_pair(np.random.default_rng(seed), R, t)
    for method in CORE_METHODS:
        est = estimate_motion(prev, curr, CAMERA, method=method, rng=seed)
        assert est.ok, est.status
        assert rotation_error(est.rotation, R) < 1e-9
        assert np.linalg.norm(est.translation - t) < 1e-9
        assert est.inliers.all()


def test_probabilistic_final_inliers_recall_the_true_inliers():
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=500, outlier_ratio=0.5), np.random.default_rng(4))
    est = estimate_motion(frame.prev, frame.curr, frame.camera, rng=0)
    truth = frame.truth.inlier
    assert est.ok
    assert np.mean(est.inliers[truth]) > 0.95
    assert np.mean(est.inliers[~truth]) < 0.02
    with pytest.raises(ValueError, match="refine_gate_probability"):
        estimate_motion(frame.prev, frame.curr, frame.camera, refine_gate_probability=1.0)


def test_available_methods_lists_core_methods_with_descriptions():
    methods = available_methods()
    for name in CORE_METHODS:
        assert name in methods and len(methods[name]) > 10


@pytest.mark.parametrize(
    "prev,curr,message",
    [
        (np.zeros((5, 3)), np.zeros((5, 3)), r"shape \(N, 4\)"),
        (np.tile([600.0, 100, 590, 100], (5, 1)), np.tile([600.0, 100, 590, 100], (4, 1)),
         "same number of rows, got 5 and 4$"),
        (np.tile([600.0, 100, 590, 100], (5, 1)) + 1j, np.tile([600.0, 100, 590, 100], (5, 1)), "prev must be real"),
        (np.tile([600.0, 100, 590, 100], (5, 1)), np.tile([600.0, 100, 590, 100], (5, 1)).astype(complex),
         "curr must be real"),
        (np.full((5, 4), "a"), np.ones((5, 4)), "prev must be a numeric"),
    ],
)
def test_malformed_input_raises_clear_value_error(prev, curr, message):
    with pytest.raises(ValueError, match=message):
        estimate_motion(prev, curr, CAMERA)


def test_rows_without_depth_are_not_malformed_input():
    """A frame whose rows all lack depth is a failed estimate, not a ValueError (DESIGN section 3)."""
    est = estimate_motion(np.tile([600.0, 100, 600, 100], (8, 1)), np.tile([600.0, 100, 590, 100], (8, 1)), CAMERA)
    assert not est.ok and est.n_unusable == 8 and "0 of 8 usable" in est.status and est.covariance is None


def test_bad_method_option_priors_and_order_raise():
    prev, curr = noise_free_pair(np.random.default_rng(0), np.eye(3), np.array([0, 0, -1.0]), 30)
    with pytest.raises(ValueError, match="unknown method"):
        estimate_motion(prev, curr, CAMERA, method="nope")
    with pytest.raises(ValueError, match="unknown option"):
        estimate_motion(prev, curr, CAMERA, threshhold=3)
    with pytest.raises(ValueError, match="confidence"):
        estimate_motion(prev, curr, CAMERA, confidence=1.5)
    with pytest.raises(ValueError, match="refine_rounds"):
        estimate_motion(prev, curr, CAMERA, refine_rounds=0)
    with pytest.raises(ValueError, match="first_batch_size"):
        estimate_motion(prev, curr, CAMERA, first_batch_size=0)
    with pytest.raises(ValueError, match="rigidity_gate_probability"):
        estimate_motion(prev, curr, CAMERA, rigidity_gate_probability=1.0)
    with pytest.raises(ValueError, match="priors must have shape"):
        estimate_motion(prev, curr, CAMERA, priors=np.ones(3))
    with pytest.raises(ValueError, match=r"non-negative, got minimum -2.5"):
        estimate_motion(prev, curr, CAMERA, priors=np.r_[np.ones(29), -2.5])
    with pytest.raises(ValueError, match="NaN or inf"):
        estimate_motion(prev, curr, CAMERA, priors=np.r_[np.ones(29), np.inf])
    with pytest.raises(ValueError, match="at least 3 positive"):
        estimate_motion(prev, curr, CAMERA, priors=np.r_[np.ones(2), np.zeros(28)])
    with pytest.raises(ValueError, match="permutation"):
        estimate_motion(prev, curr, CAMERA, order=np.zeros(30, dtype=int))
    with pytest.raises(ValueError, match="not both"):
        estimate_motion(prev, curr, CAMERA, priors=np.ones(30), order=np.arange(30))


def test_estimate_problem_equals_estimate_motion_on_the_same_frame():
    from stereovo.estimation import estimate_problem

    rng = np.random.default_rng(5)
    prev, curr = noise_free_pair(rng, random_rotation(rng, 0.05), np.array([0.1, 0.0, -1.0]), 60)
    curr = curr + rng.normal(0, 0.5, curr.shape)
    curr[:10] = curr[10:20]  # mismatches
    problem = StereoProblem.build(prev, curr, CAMERA, 0.5)
    for method in ("probabilistic", "msac"):
        a = estimate_motion(prev, curr, CAMERA, method=method, rng=3, noise_sigma=0.5)
        b = estimate_problem(problem, method=method, rng=3)
        np.testing.assert_array_equal(a.rotation, b.rotation)
        np.testing.assert_array_equal(a.inliers, b.inliers)
    with pytest.raises(ValueError, match="differs from the problem"):
        estimate_problem(problem, noise_sigma=1.0)


def test_hopeless_frames_fail_without_raising():
    prev, curr = noise_free_pair(np.random.default_rng(0), np.eye(3), np.array([0, 0, -1.0]), 30)
    few = estimate_motion(prev[:2], curr[:2], CAMERA)
    assert not few.ok and "too few" in few.status
    assert np.array_equal(few.rotation, np.eye(3)) and few.inliers.shape == (2,)

    line = np.array([[x, 0.0, 10.0] for x in np.linspace(-3, 3, 12)])
    collinear = estimate_motion(CAMERA.project(line), CAMERA.project(line + [0, 0, -1]), CAMERA, budget=64)
    assert not collinear.ok and "degenerate" in collinear.status

    rng = np.random.default_rng(5)
    shuffled = curr[rng.permutation(30)]
    none = estimate_motion(prev, shuffled, CAMERA, method="ransac", rng=1, max_iterations=300)
    assert not none.ok and "no consensus" in none.status
    np.testing.assert_array_equal(none.translation, np.zeros(3))


def test_same_seed_same_result_different_seed_differs():
    rng = np.random.default_rng(3)
    R, t = random_rotation(rng, 0.05), np.array([0.1, 0.0, -1.0])
    prev, curr = noise_free_pair(rng, R, t, 200)
    curr = curr + rng.normal(0, 0.5, curr.shape)
    curr[:, 3] = curr[:, 1]
    curr[:100] = curr[rng.permutation(100)]  # half of them mismatched
    a = estimate_motion(prev, curr, CAMERA, rng=7)
    b = estimate_motion(prev, curr, CAMERA, rng=np.random.default_rng(7))
    c = estimate_motion(prev, curr, CAMERA, rng=8)
    np.testing.assert_array_equal(a.rotation, b.rotation)
    np.testing.assert_array_equal(a.inliers, b.inliers)
    assert a.n_hypotheses == b.n_hypotheses
    assert not np.array_equal(a.translation, c.translation)
    d = estimate_motion(prev, curr, CAMERA, rng=np.random.SeedSequence(7))
    np.testing.assert_array_equal(a.rotation, d.rotation)  # a SeedSequence is the seed's own
    for bad in ("abc", -1, 1.5, True, [7]):
        with pytest.raises(ValueError, match=rf"^rng must be a numpy.random.Generator, a SeedSequence or an "
                                             rf"integer seed >= 0, got {re.escape(repr(bad))}$"):
            estimate_motion(prev, curr, CAMERA, rng=bad)


@pytest.mark.parametrize("method", available_methods())
def test_an_integer_seed_is_the_generator_numpy_seeds_with_it(method):
    """An integer seed's generator is built from cached seed words (a few microseconds less a frame):
    every method gives what ``np.random.default_rng(seed)`` gives it, for small, repeated and
    the largest seeds, and numpy integers (which take numpy's path)."""
    frame = simulate_frame(SimulationConfig(n_correspondences=120, outlier_ratio=0.4), np.random.default_rng(11))
    for seed in (0, 5, 5, 2**63 - 1):
        for given in (seed, np.uint64(seed)):
            a = run(method, frame, rng=given)
            b = run(method, frame, rng=np.random.default_rng(seed))
            np.testing.assert_array_equal(a.rotation, b.rotation)
            np.testing.assert_array_equal(a.translation, b.translation)
            np.testing.assert_array_equal(a.inliers, b.inliers)
            assert (a.status, a.n_hypotheses, a.counters) == (b.status, b.n_hypotheses, b.counters)


def test_fixed_budget_draws_exactly_budget():
    rng = np.random.default_rng(4)
    prev, curr = noise_free_pair(rng, np.eye(3), np.array([0, 0, -1.0]), 100)
    est = estimate_motion(prev, curr, CAMERA, budget=17, batch_size=5)
    assert est.n_hypotheses == 17 and est.ok


def test_priors_and_order_reach_the_sampler():
    # Only the first 20 correspondences are correct; priors or an order naming them
    # finds the motion within the first batch, uniform sampling at 90 % outliers rarely does.
    rng = np.random.default_rng(6)
    t = np.array([0.0, 0.0, -1.0])
    prev, curr = noise_free_pair(rng, np.eye(3), t, 200)
    curr[20:] = curr[20:][rng.permutation(180)]
    priors = np.r_[np.ones(20), np.zeros(180)]
    guided = estimate_motion(prev, curr, CAMERA, priors=priors, budget=8, batch_size=8, rng=0)
    prosac = estimate_motion(prev, curr, CAMERA, order=np.arange(200), budget=1, batch_size=1, rng=0)
    assert guided.ok and np.linalg.norm(guided.translation - t) < 1e-6
    assert prosac.ok and np.linalg.norm(prosac.translation - t) < 1e-6
    assert guided.inliers[:20].all()


@pytest.mark.parametrize("method", ["waldsac", "r-ransac", "inlier-detection"])
def test_estimate_exposes_the_methods_counters(method):
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=300, outlier_ratio=0.5), rng=6)
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=0)
    assert est.counters and est.counters == est.report.counters
    assert all(isinstance(v, (int, float)) for v in est.counters.values())
    c = est.counters  # what each count must add up to on this frame (half its rows outliers)
    if method == "waldsac":  # every tested hypothesis is accepted, rejected or verified in full
        assert 0 < c["sprt_rejected"] and c["sprt_accepted"] + c["sprt_rejected"] + c["sprt_full"] == c["sprt_tested"]
        assert c["sprt_tested"] <= est.n_hypotheses and 0 < c["sprt_epsilon"] < 1
    elif method == "r-ransac":  # the T(d,d) pretest, where switched on, passes or fails each hypothesis
        assert 0 < c["tdd_failed"] and c["tdd_passed"] + c["tdd_failed"] == c["tdd_tested"] == c["tdd_on"]
        assert c["tdd_on"] + c["tdd_off"] <= est.n_hypotheses
    else:  # the consistency graph has a node per usable row, and the clique is within it
        assert c["clique_graph_nodes"] == int((~est.unusable).sum()) > 0
        assert 6 <= c["clique_size"] <= c["clique_graph_nodes"]
    assert estimate_motion(frame.prev[:2], frame.curr[:2], frame.camera, method=method).counters == {}


@pytest.mark.slow
# The foundation's bar is for the project's recipes: "ransac" is now Fischler & Bolles' textbook
# loop (closed-form minimal fits, no polish or LM); its enhanced row is the recipe this bar was set on.
@pytest.mark.parametrize("method", ["probabilistic", "ransac+polish+refit+lm"])
@pytest.mark.parametrize("epsilon,required", [(0.5, 0.99), (0.8, 0.97)])
def test_success_rate_on_200_frames(method, epsilon, required):
    assert success_rate(method, epsilon) >= required


@pytest.mark.parametrize("method", CLASSICAL)
def test_method_succeeds_on_most_frames_and_is_deterministic(method):
    # Every method recovers the motion on most frames at epsilon 0.5, N 300. The papers' recipes
    # (minimal fits, one least-squares refit) miss the 1 degree / 5 cm bar on some frames (measured:
    # 0.70-1.00 over these 20), the sample polish and the LM refinement lift all to 1.00.
    results = [run(method, frame, rng=i) for i, frame in enumerate(frames())]
    success = np.mean([succeeded(e, f) for e, f in zip(results, frames())])
    assert success >= 0.65, f"{method}: success {success:.2f}"
    # (the sample polish where the method fits minimal samples: inlier-detection fits on its clique)
    enhanced = [run(method, f, rng=i, **drop_unread(method, {"polish_iterations": 2, "refine": True}))
                for i, f in enumerate(frames())]
    success = np.mean([succeeded(e, f) for e, f in zip(enhanced, frames())])
    assert success >= 0.95, f"{method} with polish and LM: success {success:.2f}"
    again = run(method, frames()[0], rng=0)
    first = results[0]
    np.testing.assert_array_equal(again.rotation, first.rotation)
    np.testing.assert_array_equal(again.translation, first.translation)
    np.testing.assert_array_equal(again.inliers, first.inliers)
    assert (again.n_hypotheses, again.n_point_checks) == (first.n_hypotheses, first.n_point_checks)


def test_methods_needing_an_input_say_which():
    frame = frames()[0]
    with pytest.raises(ValueError, match="order="):
        estimate_motion(frame.prev, frame.curr, frame.camera, method="prosac")
    with pytest.raises(ValueError, match="priors="):
        estimate_motion(frame.prev, frame.curr, frame.camera, method="guided-mlesac")
    with pytest.raises(ValueError, match="does not sample"):
        estimate_motion(frame.prev, frame.curr, frame.camera, method="inlier-detection", priors=frame.scores)
    with pytest.raises(ValueError, match="does not sample"):
        estimate_motion(frame.prev, frame.curr, frame.camera, method="inlier-detection", order=np.arange(300))


@pytest.mark.parametrize(
    "method,option,value",
    [("r-ransac", "tdd_d", 0), ("waldsac", "sprt_t_m", -1.0), ("lo-ransac", "lo_steps", 1.5),
     ("preemptive", "preemptive_block", 0), ("mlesac", "mlesac_em_iterations", 0),
     ("prosac", "prosac_beta", 1.0), ("inlier-detection", "clique_c", 0.0)],
)
def test_bad_method_options_raise_naming_the_option(method, option, value):
    frame = frames()[0]
    with pytest.raises(ValueError, match=option):
        run(method, frame, **{option: value})


def test_options_of_one_method_are_rejected_by_another():
    frame = frames()[0]
    with pytest.raises(ValueError, match="unknown option"):
        run("ransac", frame, sprt_t_m=10.0)


def test_fixed_budget_is_honoured_by_adaptive_methods():
    frame = frames()[0]
    for method in ("r-ransac", "waldsac", "lo-ransac", "mlesac", "prosac", "usac"):
        est = run(method, frame, budget=40, batch_size=8)
        assert est.n_hypotheses == 40, method
    assert run("preemptive", frame, budget=64).n_hypotheses == 64


@pytest.mark.parametrize("method", CLASSICAL)
def test_degenerate_and_tiny_frames_fail_without_raising(method):
    camera = frames()[0].camera
    line = np.array([[x, 0.0, 10.0] for x in np.linspace(-3, 3, 12)])
    prev, curr = camera.project(line), camera.project(line + [0, 0, -1])
    collinear = estimate_motion(prev, curr, camera, method=method, **drop_unread(method, {"budget": 64}),
                                **inputs_for(method, 12))
    assert not collinear.ok and "degenerate" in collinear.status
    np.testing.assert_array_equal(collinear.rotation, np.eye(3))
    few = frames()[0]
    tiny = estimate_motion(few.prev[:2], few.curr[:2], few.camera, method=method, **inputs_for(method, 2))
    assert not tiny.ok and "too few" in tiny.status


VALID_SHARED_OPTIONS = {"budget": (64, None), "max_iterations": (200, 50), "confidence": (0.99, 0.9),
                        "noise_sigma": (0.5, 1.0), "refine": (False, True), "batch_size": (32, 128),
                        "min_inliers": (6, 10), "threshold_px": (None, 2.0), "polish_iterations": (0, 2)}


def kwargs_options(kwargs: dict) -> dict:
    """The estimator options among an example's keyword arguments (not its priors or order)."""
    return {k: v for k, v in kwargs.items() if k not in ("priors", "order")}


def adaptive_cap(name: str, value) -> dict:
    """``max_iterations=200``, the cap that keeps an adaptive search short; none beside a fixed budget, which is
    the stop itself (the cap would be refused as unread there)."""
    return {} if name == "budget" and value is not None else {"max_iterations": 200}


@pytest.mark.parametrize("method", sorted(available_methods()))
def test_estimate_motion_fuzz(method):
    # Each example has at most one fault besides the measurements strategy's: a WEIRD_NUMBERS value for its option
    # (else a valid one: a shared option's from VALID_SHARED_OPTIONS, a method's own its default), bad priors or
    # order, or priors / order the method may not take. Faulty examples are refused naming the argument or
    # estimate; fault-free ones on a well-formed frame are never refused. How many examples land on each side is
    # hypothesis' choice, which moves with this test's source: the explicit calls below guarantee both sides.
    spec = method_spec(method)
    outcomes = []

    @FUZZ
    @given(data=measurements(), fault=st.sampled_from(["none", "none", "none", "option", "option", "priors", "order",
                                                        "bad-priors", "bad-order"]),
           option=st.sampled_from(SHARED_FUZZ_OPTIONS + ("extra",)), pick=st.integers(0, 1), weird=WEIRD_NUMBERS,
           seed=st.integers(0, 2**31))
    def run(data, fault, option, pick, weird, seed):
        prev, curr, scores, kind = data
        n = len(scores)
        name = option
        if option == "extra":
            name = spec.extra_options[seed % len(spec.extra_options)] if spec.extra_options else "budget"
        value = weird if fault == "option" else valid_value(spec, name, pick)
        # a valid setting only where the method reads it (a fault-free example is never refused)
        kwargs: dict = drop_unread(method, adaptive_cap(name, value))
        if fault == "priors" or (fault in ("none", "option") and spec.inputs == "priors"):
            kwargs["priors"] = scores
        elif fault == "order" or (fault in ("none", "option") and spec.inputs == "order"):
            kwargs["order"] = np.argsort(-scores, kind="stable")
        elif fault == "bad-priors":
            kwargs["priors"] = np.full(n, weird if not isinstance(weird, (str, list)) else -1.0, dtype=object)
        elif fault == "bad-order":
            kwargs["order"] = np.zeros(n, dtype=int)
        if fault == "option" or name in drop_unread(method, {**kwargs_options(kwargs), name: value}):
            kwargs[name] = value
        try:
            est = estimate_quietly(prev, curr, method, seed, kwargs)
        except (ValueError, TypeError) as err:
            assert names_an_argument(err, (name, method)), repr(err)
            assert not (fault == "none" and kind == "none"), repr(err)
            outcomes.append("refused")
            return
        _check_estimate(est, np.shape(prev)[0])
        outcomes.append("estimated")

    run()
    assert len(outcomes) == 30


def valid_value(spec, name: str, pick: int):
    """A valid value of option ``name``: a method's own option its default, a shared one
    VALID_SHARED_OPTIONS[name][pick]."""
    defaults = spec.option_defaults()
    return defaults[name] if name in defaults else VALID_SHARED_OPTIONS[name][pick]


def estimate_quietly(prev, curr, method: str, seed: int, kwargs: dict):
    """estimate_motion, with numpy's ComplexWarning (complex input cast to real in silence) an error."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", np.exceptions.ComplexWarning)
        return estimate_motion(prev, curr, CAMERA, method=method, rng=seed, **kwargs)


def drawn_call(spec, rng: np.random.Generator, kind: str) -> tuple:
    """A fault-free call as the fuzz makes them, drawn from ``rng``: a frame of 3 to 60 rows made into
    ``kind`` (tests.support.fuzz.corrupted), one option at a valid value, and priors or an order where
    the method takes one (either or none where it takes any)."""
    n = int(rng.integers(3, 61))
    frame = fuzz_frame(int(rng.integers(0, 2**16)), n, float(rng.choice([0.0, 0.3, 0.7, 0.95])))
    prev, curr, scores = corrupted(frame.prev.copy(), frame.curr.copy(), frame.scores.copy(), kind,
                                   int(rng.integers(0, n)), int(rng.integers(0, 4)))
    names = SHARED_FUZZ_OPTIONS + spec.extra_options
    name = names[int(rng.integers(len(names)))]
    value = valid_value(spec, name, int(rng.integers(0, 2)))
    # a valid setting only where the method reads it (an option it would not read is refused)
    kwargs: dict = drop_unread(spec.name, adaptive_cap(name, value))
    taken = {"any": ("none", "priors", "order"), "priors-optional": ("none", "priors"), "priors": ("priors",),
             "order": ("order",), "none": ("none",)}[spec.inputs]
    given = taken[int(rng.integers(len(taken)))]
    if given == "priors":
        kwargs["priors"] = scores
    elif given == "order":
        kwargs["order"] = np.argsort(-np.asarray(scores), kind="stable")
    if name in drop_unread(spec.name, {**kwargs_options(kwargs), name: value}, order=given == "order"):
        kwargs[name] = value
    return prev, curr, kwargs, name, int(rng.integers(0, 2**31))


def method_rng(method: str, stream: int) -> np.random.Generator:
    """A generator of its own for each method and test (a method added or renamed moves no other's calls)."""
    return np.random.default_rng([stream, zlib.crc32(method.encode())])


@pytest.mark.parametrize("method", sorted(available_methods()))
def test_fault_free_calls_estimate_on_every_well_formed_layout(method):
    """Every layout the estimator must take (unusable rows, valid but unusual arrays, no rows at all),
    each with a valid option and the method's inputs, is estimated, never refused: the fuzz's valid side,
    every call counted."""
    spec = method_spec(method)
    rng = method_rng(method, 1)
    for kind in WELL_FORMED_KINDS:
        prev, curr, kwargs, name, seed = drawn_call(spec, rng, kind)
        try:
            est = estimate_quietly(prev, curr, method, seed, kwargs)
        except (ValueError, TypeError) as err:
            raise AssertionError(f"{kind} with {name}={kwargs.get(name, '(unread, left out)')!r} refused: {err}") from err
        _check_estimate(est, np.shape(prev)[0])


@pytest.mark.parametrize("method", sorted(available_methods()))
def test_faulty_calls_are_refused_naming_the_argument(method):
    """A fault-free call made faulty in one way (a malformed array, an invalid option value, bad priors
    or order, an input the method does not take) is refused with a one-line error naming the argument:
    the fuzz's refused side, every fault counted."""
    spec = method_spec(method)
    rng = method_rng(method, 2)
    taken = {"any": "priors order", "priors-optional": "priors", "priors": "priors", "order": "order", "none": ""}
    faults = [*MALFORMED_KINDS, "nan-option", "text-option", "bad-priors", "bad-order",
              *(f"{given}-not-taken" for given in ("priors", "order") if given not in taken[spec.inputs])]
    for fault in faults:
        kind = fault if fault in MALFORMED_KINDS else "none"
        prev, curr, kwargs, name, seed = drawn_call(spec, rng, kind)
        n = len(prev)
        kwargs.pop("priors", None)
        kwargs.pop("order", None)
        if spec.inputs in ("priors", "order") and fault not in ("bad-priors", "bad-order"):
            kwargs[spec.inputs] = np.ones(n) if spec.inputs == "priors" else np.arange(n)
        if fault.endswith("-option"):
            kwargs[name] = math.nan if fault == "nan-option" else "no"
        elif fault == "bad-priors":
            kwargs["priors"] = np.full(n, -1.0)
        elif fault == "bad-order":
            kwargs["order"] = np.zeros(n, dtype=int)
        elif fault.endswith("-not-taken"):
            kwargs["priors"] = np.ones(n) if fault.startswith("priors") else None
            kwargs["order"] = np.arange(n) if fault.startswith("order") else None
        kwargs = {key: value for key, value in kwargs.items() if value is not None or key == name}
        with pytest.raises((ValueError, TypeError)) as err:
            estimate_quietly(prev, curr, method, seed, kwargs)
        assert names_an_argument(err.value, (name, method)), (fault, repr(err.value))


@pytest.mark.parametrize("method", sorted(available_methods()))
def test_ok_means_the_returned_inliers_pass_the_final_gate_under_the_returned_pose(method, rendered_frame):
    for i, frame in enumerate([*FRAMES, rendered_frame]):
        est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=i,
                              **drop_unread(method, {"max_iterations": 2000}), noise_sigma=frame.noise_sigma,
                              **score_inputs(frame, METHOD_INPUTS.get(method)))
        if not est.ok:
            assert est.n_inliers == 0 and np.array_equal(est.rotation, np.eye(3))
            continue
        assert np.all(np.isfinite(est.rotation)) and np.all(np.isfinite(est.translation))
        gate_model, gate_sq = est.report.gate
        problem, rows = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma).usable_subproblem()
        passing = gate_model.squared(problem, est.rotation[None], est.translation[None])[0] < gate_sq
        returned = est.inliers if rows is None else est.inliers[rows]
        np.testing.assert_array_equal(returned, passing)
        assert not np.any(est.inliers & est.unusable)
        assert passing.sum() >= 6


@pytest.mark.parametrize("seed", [2, 15, 24])
@pytest.mark.parametrize("method", ["probabilistic", "mlesac", "guided-mlesac", "bansac"])
def test_no_confident_absurd_pose_where_far_rows_once_won_the_consensus(method, seed):
    # Hostile frames at eps 0.8, N 500 on which the estimator before the post-condition and the
    # resolvable-depth rule returned "ok" with a rotation error of 140-175 deg, translations of
    # 1.9-22 km and 93-327 inliers (probabilistic), none of which passed its gate.
    frame = simulate_frame(SimulationConfig(n_correspondences=500, outlier_ratio=0.8, outliers="hostile"), seed)
    given = score_inputs(frame, METHOD_INPUTS.get(method))
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=0, **given)
    errors = frame_metrics(est, frame.truth)
    assert not (est.ok and (errors.rot_err_deg > 10 or errors.trans_err_m > 1)), (est.status, errors)
    if method == "probabilistic":
        assert errors.success


def test_estimate_problem_scatters_like_estimate_motion(frame):
    prev, curr = spoil_rows(frame, np.array([7, 8]), "prev")
    problem = StereoProblem.build(prev, curr, CAMERA, 0.5)
    assert problem.n_unusable == 2 and not problem.usable[[7, 8]].any()
    a = estimate_problem(problem, rng=4)
    b = estimate_motion(prev, curr, CAMERA, rng=4)
    np.testing.assert_array_equal(a.inliers, b.inliers)
    np.testing.assert_array_equal(a.unusable, b.unusable)


@pytest.mark.parametrize("seed", [0, 7, 2**63, np.int64(11), np.uint32(3), np.random.SeedSequence(5)])
def test_a_seed_gives_numpys_default_generator_stream(seed):
    from stereovo.estimation.api import as_generator

    np.testing.assert_array_equal(as_generator(seed).random(8), np.random.default_rng(seed).random(8))
    assert type(as_generator(seed).bit_generator) is np.random.PCG64


@pytest.mark.parametrize("method", ["bansac", "p-bansac", "ars"])
def test_belief_samplers_refuse_an_order_before_running(method):
    """A belief sampler takes priors= or nothing: an order is refused when the call is checked (the
    environments check at construction), not when the recipe is built at the first estimate."""
    with pytest.raises(ValueError, match=f"method '{method}' samples by inlier beliefs: give priors= \\(or nothing\\)"):
        validate_options(method, {}, priors=False, order=True)
    validate_options(method, {}, priors=True, order=False)
    validate_options(method, {}, priors=False, order=False)
