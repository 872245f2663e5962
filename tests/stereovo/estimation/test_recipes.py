"""Named methods are their papers' recipes; the project's enhancements are named options."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo import available_methods, estimate_motion
from stereovo.estimation.recipes import ENHANCED_VARIANTS
from stereovo.estimation.estimator_options import ENHANCEMENTS, EstimatorOptions, enhancements_used
from stereovo.estimation.recipes import PROBABILISTIC_RECIPE
from stereovo.estimation.registry import method_spec
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.refinement import ReprojectionRefiner
from stereovo.estimation.roles.sample_check import RigidityCheck
from stereovo.simulation import SimulationConfig, simulate_frame


@pytest.fixture(scope="module")
def frame():
    return simulate_frame(SimulationConfig(n_correspondences=200, outlier_ratio=0.5), 21)


def components(method, frame, **options):
    """The recipe ``estimate_motion`` would run: options through the method's defaults."""
    spec = method_spec(method)
    from stereovo.estimation.registry import validate_options

    shared, extra = validate_options(method, {**options, "noise_sigma": frame.noise_sigma})
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    return spec.build(problem, shared, None, None, extra)


def test_ransac_is_fischler_and_bolles(frame):
    c = components("ransac", frame)
    assert c.polish_iterations == 0  # minimal closed-form fits
    assert c.local_optimizer is None and c.sample_check is None
    # one least-squares refit of the final inliers (one round: one re-selection), no iterated LM
    assert isinstance(c.refiner, ReprojectionRefiner) and c.refiner.rounds == 1
    assert method_spec("ransac").defaults == {}
    assert "paper's recipe, no enhancements" in available_methods()["ransac"]


def test_textbook_defaults_are_the_options_defaults():
    options = EstimatorOptions()
    assert enhancements_used({f: getattr(options, f) for f in ("polish_iterations", "local_refit",
                                                               "rigidity_gate_probability", "refine")}) == []
    assert options.least_squares_refit


def test_each_enhancement_is_a_named_option(frame):
    c = components("ransac", frame, polish_iterations=2, local_refit=True, rigidity_gate_probability=0.999,
                   refine=True)
    assert c.polish_iterations == 2 and c.local_optimizer is not None
    assert isinstance(c.sample_check, RigidityCheck)
    assert c.refiner.rounds == EstimatorOptions().refine_rounds
    assert components("ransac", frame, least_squares_refit=False).refiner is None


def test_probabilistic_keeps_its_tuned_recipe_and_says_so(frame):
    assert method_spec("probabilistic").defaults == PROBABILISTIC_RECIPE
    c = components("probabilistic", frame)
    assert c.polish_iterations == 2 and c.local_optimizer is not None and isinstance(c.sample_check, RigidityCheck)
    description = available_methods()["probabilistic"]
    assert "tuned recipe" in description
    for name in ("polish", "refit", "runner-up", "rigidity", "lm"):
        assert ENHANCEMENTS[name][0] in description
    # a caller's option still wins over the method's default
    assert components("probabilistic", frame, polish_iterations=0).polish_iterations == 0


def test_enhanced_variants_are_registered_described_and_equal_the_options(frame):
    methods = available_methods()
    for name in ("ransac+polish", "ransac+refit", "ransac+rigidity", "ransac+lm", "ransac+polish+refit+lm"):
        assert name in ENHANCED_VARIANTS and name in methods
        for enhancement in name.split("+")[1:]:
            assert ENHANCEMENTS[enhancement][0] in methods[name]
    # the variant is the base method with the options: the same estimate, draw for draw
    variant = estimate_motion(frame.prev, frame.curr, frame.camera, method="ransac+polish+refit+lm", rng=4,
                              noise_sigma=frame.noise_sigma)
    explicit = estimate_motion(frame.prev, frame.curr, frame.camera, method="ransac", rng=4,
                               noise_sigma=frame.noise_sigma, polish_iterations=2, local_refit=True, refine=True)
    np.testing.assert_array_equal(variant.rotation, explicit.rotation)
    np.testing.assert_array_equal(variant.inliers, explicit.inliers)
    assert variant.n_hypotheses == explicit.n_hypotheses


def test_the_environment_asks_for_its_enhancements_explicitly():
    from vo_gym.env import DEFAULT_ESTIMATOR_OPTIONS

    assert DEFAULT_ESTIMATOR_OPTIONS["polish_iterations"] == 2 and DEFAULT_ESTIMATOR_OPTIONS["refine"] is True
    assert DEFAULT_ESTIMATOR_OPTIONS["local_refit"] is False


@pytest.mark.parametrize("v_measurement, dof", [("shared", 3), ("independent", 4)])
@pytest.mark.parametrize("gate, refine_gate", [(0.95, 0.99), (0.9, 0.999)])
def test_probabilistics_gates_are_the_chi_square_quantiles_of_their_probabilities(v_measurement, dof, gate,
                                                                                    refine_gate):
    """Hypotheses are judged in 3-D at chi-square(3) of ``gate_probability``; the final inliers in pixels at
    chi-square(camera.measurement_dof) of ``refine_gate_probability``."""
    import dataclasses

    from scipy.stats import chi2

    frame = simulate_frame(SimulationConfig(n_correspondences=120, outlier_ratio=0.3), 4)
    camera = dataclasses.replace(frame.camera, v_measurement=v_measurement)
    problem = StereoProblem.build(frame.prev, frame.curr, camera, frame.noise_sigma)
    options = EstimatorOptions(**{**PROBABILISTIC_RECIPE, "gate_probability": gate,
                                  "refine_gate_probability": refine_gate})
    components = method_spec("probabilistic").build(problem, options, None, None, {})
    assert components.threshold_sq == pytest.approx(chi2.ppf(gate, 3), rel=1e-12)
    assert components.refiner.gate[1] == pytest.approx(chi2.ppf(refine_gate, dof), rel=1e-12)
    est = estimate_motion(frame.prev, frame.curr, camera, rng=0, gate_probability=gate,
                          refine_gate_probability=refine_gate)
    assert est.ok and est.report.gate[1] == pytest.approx(chi2.ppf(refine_gate, dof), rel=1e-12)
