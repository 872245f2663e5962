"""One contract for options (stereovo.options): the same value is refused, naming it, wherever it enters:
the declarations themselves, EstimatorOptions / estimate_motion, each method's own options, the
simulator's config and gymnasium.make keywords."""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest

import vo_gym  # noqa: F401
from stereovo.estimation import EstimatorOptions, available_methods, estimate_motion, method_spec, validate_options
from stereovo.estimation.estimator_options import ESTIMATOR_OPTION_RULES
from stereovo.options import Boolean, Choice, Integer, Number, OptionError
from stereovo.simulation import SimulationConfig, simulate_frame
from vo_gym.env import StereoVOEnv

FRAME = simulate_frame(SimulationConfig(n_correspondences=120, outlier_ratio=0.3), np.random.default_rng(3))


# ----------------------------------------------------------------------------- the declarations


def test_integer_accepts_integers_only():
    rule = Integer(low=1)
    assert rule.check("k", 3) == 3 and type(rule.check("k", np.int64(3))) is int
    for bad in (True, np.bool_(True), 1.5, 3.0, "3", None, float("inf"), complex(3, 0), 0):
        with pytest.raises(OptionError, match=r"^option k must be an integer >= 1, got "):
            rule.check("k", bad)
    assert Integer(allow_none=True).check("k", None) is None


def test_boolean_accepts_bools_only():
    rule = Boolean()
    assert rule.check("b", True) is True and rule.check("b", np.bool_(False)) is False
    for bad in ("no", "False", 0, 1, None, 1.0):
        with pytest.raises(OptionError, match=r"^option b must be True or False, got "):
            rule.check("b", bad)


def test_number_is_finite_real_and_in_range():
    rule = Number(low=0.0, high=1.0, low_open=True, high_open=True)
    assert rule.check("p", 0.5) == 0.5 and rule.check("p", np.float32(0.25)) == 0.25
    for bad in (0.0, 1.0, math.nan, math.inf, -math.inf, "0.9", True, complex(0.5, 0), None, [0.5]):
        with pytest.raises(OptionError, match=r"^option p must be a finite number in \(0, 1\), got "):
            rule.check("p", bad)


def test_choice_lists_the_valid_values():
    with pytest.raises(OptionError, match=r"must be one of 'a', 'b', got 'c'"):
        Choice(choices=("a", "b")).check("mode", "c")


# ----------------------------------------------------------------------------- the estimator


BAD_SHARED = [
    ("batch_size", 1.5), ("polish_iterations", 1.5), ("refine_iterations", 2.5), ("min_inliers", 3.5),
    ("refine", "no"), ("local_refit", "no"), ("max_iterations", math.inf), ("budget", math.nan),
    ("confidence", "0.9"), ("noise_sigma", 1e300), ("noise_sigma", 1e-300), ("noise_sigma", -1.0),
    ("max_iterations", True), ("threshold_px", math.inf), ("gate_probability", 1.0), ("first_batch_size", 0),
    ("refine_rounds", 2.0), ("budget", 0),
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


def test_every_declared_rule_accepts_the_default():
    defaults = EstimatorOptions()
    for field in dataclasses.fields(EstimatorOptions):
        assert field.name in ESTIMATOR_OPTION_RULES, field.name
        ESTIMATOR_OPTION_RULES[field.name].check(field.name, getattr(defaults, field.name))


def test_validation_keeps_values_and_types():
    opts = EstimatorOptions(max_iterations=np.int64(50), noise_sigma=np.float64(0.7), refine=np.bool_(False))
    assert (opts.max_iterations, opts.noise_sigma, opts.refine) == (50, 0.7, False)
    assert type(opts.max_iterations) is int and type(opts.noise_sigma) is float and type(opts.refine) is bool


BAD_METHOD_OPTIONS = [
    ("usac", "prosac_beta", 2.0), ("usac", "prosac_min_n", 4.5), ("usac", "prosac_t_n", math.inf),
    ("usac", "sprt_chunk", True), ("waldsac", "sprt_t_m", math.nan), ("lo-ransac", "lo_steps", 1.5),
    ("mlesac", "mlesac_em_tolerance", "1e-4"), ("r-ransac", "tdd_d", 1.0), ("preemptive", "preemptive_block", 0),
    ("inlier-detection", "clique_c", math.inf),
]


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


# ----------------------------------------------------------------------------- simulator and environment


@pytest.mark.parametrize("name,value", [("n_frames", 2.0), ("n_correspondences", True), ("noise_sigma", 1e300),
                                        ("noise_sigma", "0.5"), ("score_auc", math.nan), ("preset", 3),
                                        ("z_min", math.inf), ("speed", complex(1, 1))])
def test_simulator_fields_follow_the_contract(name, value):
    with pytest.raises(ValueError, match=rf"^SimulationConfig\.{name} must be"):
        SimulationConfig(**{name: value})


@pytest.mark.parametrize("name,value", [
    ("batch_size", 1.5), ("refine", "no"), ("local_refit", "no"), ("polish_iterations", 1.5),
    ("refine_iterations", 2.5), ("min_inliers", 3.5), ("max_iterations", math.inf), ("budget", math.nan),
    ("confidence", "0.9"), ("budget", True), ("estimator_noise_sigma", 1e300), ("action_bound", math.inf),
    ("success_bonus", "0.5"), ("sampling", 1), ("noise_sigma", 1e300),
])
def test_make_keywords_follow_the_contract(name, value):
    with pytest.raises(ValueError, match=name):
        gym.make("vo_gym/StereoVO-v0", n_correspondences=60, **{name: value})


def test_env_learns_validity_without_running_the_method(monkeypatch):
    """No probe frame: making an env with bad method options fails before any estimate is run."""
    import stereovo.estimation.api as methods

    def boom(*args, **kwargs):
        raise AssertionError("the environment ran the estimator while being made")

    monkeypatch.setattr(methods, "_estimate", boom)
    with pytest.raises(ValueError, match="prosac_beta"):
        StereoVOEnv(n_correspondences=60, method="usac", prosac_beta=5.0)
    with pytest.raises(ValueError, match="sampling='guided'"):
        StereoVOEnv(n_correspondences=60, method="prosac")
    StereoVOEnv(n_correspondences=60, method="prosac", sampling="prosac", prosac_beta=0.1)


@pytest.mark.parametrize("value", [0, -1, 1.5, math.nan, True, "2"])
def test_worker_counts_and_seeds_of_every_layer_follow_the_contract(value):
    """One rule for counts everywhere: the backends, the benchmark grid, the agents' evaluation and sweeps."""
    from agents.evaluation.setup import EvalConfig
    from agents.sweep import MetricSpec
    import dataclasses

    from stereovo.benchmark import DEFAULT_GRID, check_seed
    from stereovo.trials.backend import LocalBackend, chunked

    cases = [
        (lambda: LocalBackend(value), r"^workers must be an integer >= 1, got "),
        (lambda: chunked([], value), r"^chunk size must be an integer >= 1, got "),
        (lambda: dataclasses.replace(DEFAULT_GRID, frames_per_cell=value), r"^BenchmarkGrid\.frames_per_cell must be an integer >= 1"),
        (lambda: EvalConfig(episodes=value), r"^episodes must be an integer >= 1, got "),
        (lambda: MetricSpec(budget=value), r"^sweep metric\.budget must be an integer >= 1, got "),
    ]
    if value != 0:  # 0 is a valid seed
        cases += [(lambda: check_seed(value), r"^seed must be an integer >= 0, got "),
                  (lambda: EvalConfig(seed=value), r"^seed must be an integer >= 0, got ")]
    for make, message in cases:
        with pytest.raises(ValueError, match=message):
            make()
