"""EstimatorOptions and the method options: refused naming option and value, every declared rule
accepts its default, every method declares its options."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from stereovo.estimation import (
    EstimatorOptions,
    available_methods,
    estimate_motion,
    method_spec,
    validate_options,
)
from stereovo.estimation.estimator_options import ESTIMATOR_OPTION_RULES
from stereovo.simulation import SimulationConfig, simulate_frame


FRAME = simulate_frame(SimulationConfig(n_correspondences=120, outlier_ratio=0.3), np.random.default_rng(3))


BAD_SHARED = [
    ("batch_size", 1.5), ("polish_iterations", 1.5), ("refine_iterations", 2.5), ("min_inliers", 3.5),
    ("refine", "no"), ("local_refit", "no"), ("max_iterations", math.inf), ("budget", math.nan),
    ("confidence", "0.9"), ("noise_sigma", 1e300), ("noise_sigma", 1e-300), ("noise_sigma", -1.0),
    ("max_iterations", True), ("threshold_px", math.inf), ("gate_probability", 1.0), ("first_batch_size", 0),
    ("refine_rounds", 2.0), ("budget", 0), ("runner_up_refit", 0.0), ("runner_up_refit", 1.5),
    ("runner_up_refit", "half"),
]


BAD_METHOD_OPTIONS = [
    ("usac", "prosac_beta", 2.0), ("usac", "prosac_min_n", 4.5), ("usac", "prosac_t_n", math.inf),
    ("usac", "sprt_chunk", True), ("waldsac", "sprt_t_m", math.nan), ("lo-ransac", "lo_steps", 1.5),
    ("mlesac", "mlesac_em_tolerance", "1e-4"), ("r-ransac", "tdd_d", 1.0), ("preemptive", "preemptive_block", 0),
    ("inlier-detection", "clique_c", math.inf),
]


@pytest.mark.parametrize("name,value", BAD_SHARED)
def test_shared_options_are_refused_naming_option_and_value(name, value):
    with pytest.raises(ValueError) as err:
        EstimatorOptions(**{name: value})
    assert str(err.value).startswith(f"option {name} must be ") and str(err.value).endswith(f", got {value!r}")
    for method in ("msac", "probabilistic"):
        with pytest.raises(ValueError, match=name):
            estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method=method, **{name: value})
    with pytest.raises(ValueError, match=name):
        validate_options("msac", {name: value})


def test_runner_up_refit_needs_the_local_refit_and_yields_with_it():
    with pytest.raises(ValueError) as err:
        EstimatorOptions(runner_up_refit=0.5)
    assert "runner_up_refit=0.5" in str(err.value) and "local_refit=False" in str(err.value)
    with pytest.raises(ValueError, match="runner_up_refit=0.5 needs local_refit=True"):
        estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="probabilistic", local_refit=False,
                        runner_up_refit=0.5)
    # probabilistic's default runner-up refit goes with its local refit when a caller switches that off
    options, _ = validate_options("probabilistic", {"local_refit": False})
    assert options.runner_up_refit is None and not options.local_refit
    assert validate_options("probabilistic", {})[0].runner_up_refit == 0.5
    est = estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method="probabilistic", local_refit=False, rng=1)
    assert est.ok and est.report.n_local_optimizations == 0


def test_every_declared_rule_accepts_the_default():
    defaults = EstimatorOptions()
    for field in dataclasses.fields(EstimatorOptions):
        assert field.name in ESTIMATOR_OPTION_RULES, field.name
        ESTIMATOR_OPTION_RULES[field.name].check(field.name, getattr(defaults, field.name))


def test_validation_keeps_values_and_types():
    opts = EstimatorOptions(max_iterations=np.int64(50), noise_sigma=np.float64(0.7), refine=np.bool_(False))
    assert (opts.max_iterations, opts.noise_sigma, opts.refine) == (50, 0.7, False)
    assert type(opts.max_iterations) is int and type(opts.noise_sigma) is float and type(opts.refine) is bool


@pytest.mark.parametrize("method,name,value", BAD_METHOD_OPTIONS)
def test_method_options_are_checked_before_running(method, name, value):
    if method not in available_methods():
        pytest.skip(f"{method} not registered")
    # usac checks its prosac_* options even without an order, as prosac does
    with pytest.raises(ValueError, match=rf"option {name} must be"):
        validate_options(method, {name: value})
    with pytest.raises(ValueError, match=rf"option {name} must be"):
        estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method=method, **{name: value})


def test_every_method_declares_its_options():
    """Each method option has a declaration, so its validity never depends on a frame."""
    for name in available_methods():
        spec = method_spec(name)
        for option in spec.extra_options:
            assert spec.option_rule(option) is not None, (name, option)


def test_sampling_inputs_are_checked_by_declaration():
    with pytest.raises(ValueError, match="order="):
        validate_options("prosac", {}, priors=True)
    with pytest.raises(ValueError, match="priors="):
        validate_options("guided-mlesac", {}, order=True)
    with pytest.raises(ValueError, match="does not sample"):
        validate_options("inlier-detection", {}, priors=True)
    validate_options("prosac", {}, order=True)
