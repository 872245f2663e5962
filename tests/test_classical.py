"""The classical family as a whole: registry, contract, success on simulated frames, determinism.

Method-specific properties live in tests/test_classical_*.py.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from stereovo import available_methods, estimate_motion
from stereovo.estimation.registry import method_spec
from stereovo.geometry import rotation_error
from stereovo.simulation import SimulationConfig, simulate_frame

CLASSICAL = [
    "mlesac",
    "guided-mlesac",
    "prosac",
    "r-ransac",
    "waldsac",
    "lo-ransac",
    "preemptive",
    "usac",
    "inlier-detection",
]


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


def test_classical_methods_are_registered_with_description_and_reference():
    methods = available_methods()
    for name in CLASSICAL:
        assert name in methods
        spec = method_spec(name)
        assert len(spec.description) > 20 and spec.reference
    assert method_spec("waldsac").extra_options == ("sprt_t_m", "sprt_epsilon0", "sprt_delta0", "sprt_chunk")
    assert "lo_inner_iterations" in method_spec("usac").extra_options


@pytest.mark.parametrize("method", CLASSICAL)
def test_method_succeeds_on_most_frames_and_is_deterministic(method):
    # Every method recovers the motion on most frames at epsilon 0.5, N 300. The papers' recipes
    # (minimal fits, one least-squares refit) miss the 1 degree / 5 cm bar on some frames (measured:
    # 0.70-1.00 over these 20), the sample polish and the LM refinement lift all to 1.00.
    results = [run(method, frame, rng=i) for i, frame in enumerate(frames())]
    success = np.mean([succeeded(e, f) for e, f in zip(results, frames())])
    assert success >= 0.65, f"{method}: success {success:.2f}"
    enhanced = [run(method, f, rng=i, polish_iterations=2, refine=True) for i, f in enumerate(frames())]
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


def inputs_for(method: str, n: int) -> dict:
    """Neutral priors / order of length n for the methods that require one."""
    if method == "guided-mlesac":
        return {"priors": np.ones(n)}
    if method in ("prosac", "usac"):
        return {"order": np.arange(n)}
    return {}


@pytest.mark.parametrize("method", CLASSICAL)
def test_degenerate_and_tiny_frames_fail_without_raising(method):
    camera = frames()[0].camera
    line = np.array([[x, 0.0, 10.0] for x in np.linspace(-3, 3, 12)])
    prev, curr = camera.project(line), camera.project(line + [0, 0, -1])
    collinear = estimate_motion(prev, curr, camera, method=method, budget=64, **inputs_for(method, 12))
    assert not collinear.ok and "degenerate" in collinear.status
    np.testing.assert_array_equal(collinear.rotation, np.eye(3))
    few = frames()[0]
    tiny = estimate_motion(few.prev[:2], few.curr[:2], few.camera, method=method, **inputs_for(method, 2))
    assert not tiny.ok and "too few" in tiny.status
