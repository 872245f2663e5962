"""The shared estimator core: one RANSAC loop, roles as components, named methods.

Public entry point: :func:`estimate_motion` (:func:`estimate_problem` for a prebuilt
:class:`StereoProblem`); the registry: :func:`available_methods`. For code that drives the
loop itself (the NG-RANSAC trainer replays its own minimal samples): :func:`run_ransac` on a
method's :class:`RansacComponents`, and the samplers.
"""

from stereovo.estimation.methods import (
    EstimatorOptions,
    MotionEstimate,
    available_methods,
    estimate_motion,
    estimate_problem,
    method_spec,
    register_method,
    validate_options,
)
from stereovo.estimation.loop import RansacComponents, RansacReport, run_ransac
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.samplers import ReplaySampler, UniformSampler, WeightedSampler
from stereovo.estimation.solvers import SAMPLE_SIZE
from stereovo.estimation import classical  # noqa: F401  (registers the classical family)
from stereovo.estimation import ars, bansac  # noqa: F401  (register bansac and ars)

__all__ = [
    "SAMPLE_SIZE",
    "RansacComponents",
    "RansacReport",
    "ReplaySampler",
    "UniformSampler",
    "WeightedSampler",
    "run_ransac",
    "EstimatorOptions",
    "MotionEstimate",
    "StereoProblem",
    "available_methods",
    "estimate_motion",
    "estimate_problem",
    "method_spec",
    "register_method",
    "validate_options",
]
