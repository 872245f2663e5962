"""The shared estimator core: one RANSAC loop, roles as components, named methods.

Public entry point: :func:`estimate_motion` (:func:`estimate_problem` for a prebuilt
:class:`StereoProblem`, :class:`PreparedEstimator` for one method's options over many frames); the registry: :func:`available_methods`. For code that drives the
loop itself (the NG-RANSAC trainer replays its own minimal samples): :func:`run_ransac` on a
method's :class:`RansacComponents`, and the samplers.

The floors, bottom to top (each imports only those below it):

- :mod:`~stereovo.estimation.kernels`: every compiled (numba) kernel: residuals, least squares,
  Mahalanobis distances, fits, sampling, rigidity, refinement rounds, early-rejection
  verification, belief updates, the covariance sums, the compiled batches of a search;
- :mod:`~stereovo.estimation.problem`: :class:`StereoProblem`, one frame pair's measurements,
  triangulated points and their covariances;
- :mod:`~stereovo.estimation.roles`: what the loop composes, named for no method: samplers,
  sample check, solvers, residuals and qualities, verification, termination, local
  optimisation, the final LM refinement; beside them :mod:`~stereovo.estimation.covariance`,
  the pose covariance of a fit;
- :mod:`~stereovo.estimation.estimator_options`: :class:`EstimatorOptions`, the options every
  method shares, the named enhancements, and :class:`OptionReads`, which of them a method reads;
- :mod:`~stereovo.estimation.loop`: :func:`run_ransac`, the one loop, on
  :class:`RansacComponents`, returning a :class:`RansacReport`; beside it
  :mod:`~stereovo.estimation.compiled_search`, the loop's batches in one compiled call for the
  ``probabilistic`` judge with uniform draws, bit for bit its steps (a ``search_runner``);
- :mod:`~stereovo.estimation.registry`: the named methods, their option declarations,
  :func:`validate_options` and :func:`unread_options` (a given option the method would not read is
  refused by every entry point), :func:`drop_unread` (settings for many methods, each given what it reads);
- :mod:`~stereovo.estimation.recipes`: the core's own methods (``ransac``, ``msac``,
  ``probabilistic``), the recipe parts every method shares and the ``+`` variants;
- :mod:`~stereovo.estimation.methods`: one module per paper (its roles, its option
  declarations, its registration); importing this package imports it, which registers them;
- :mod:`~stereovo.estimation.api`: :func:`estimate_motion`, :func:`estimate_problem`,
  :class:`PreparedEstimator` and :class:`MotionEstimate`.
"""

from stereovo.estimation import methods  # noqa: F401  (registers the named methods)
from stereovo.estimation.api import MotionEstimate, PreparedEstimator, estimate_motion, estimate_problem
from stereovo.estimation.estimator_options import EstimatorOptions, OptionReads
from stereovo.estimation.loop import RansacComponents, RansacReport, run_ransac
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.registry import (
    available_methods,
    drop_unread,
    method_spec,
    register_method,
    unread_options,
    validate_options,
)
from stereovo.estimation.roles.samplers import ReplaySampler, UniformSampler, WeightedSampler
from stereovo.estimation.roles.solvers import SAMPLE_SIZE

__all__ = [
    "SAMPLE_SIZE",
    "RansacComponents",
    "RansacReport",
    "ReplaySampler",
    "UniformSampler",
    "WeightedSampler",
    "run_ransac",
    "EstimatorOptions",
    "OptionReads",
    "MotionEstimate",
    "PreparedEstimator",
    "StereoProblem",
    "available_methods",
    "drop_unread",
    "estimate_motion",
    "estimate_problem",
    "method_spec",
    "register_method",
    "unread_options",
    "validate_options",
]
