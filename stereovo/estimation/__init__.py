"""The shared estimator core: one RANSAC loop, roles as components, named methods.

Public entry point: :func:`estimate_motion` (:func:`estimate_problem` for a prebuilt
:class:`StereoProblem`); the registry: :func:`available_methods`.
"""

from stereovo.estimation.methods import (
    EstimatorOptions,
    MotionEstimate,
    available_methods,
    estimate_motion,
    estimate_problem,
    method_spec,
    register_method,
)
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation import classical  # noqa: F401  (registers the classical family)

__all__ = [
    "EstimatorOptions",
    "MotionEstimate",
    "StereoProblem",
    "available_methods",
    "estimate_motion",
    "estimate_problem",
    "method_spec",
    "register_method",
]
