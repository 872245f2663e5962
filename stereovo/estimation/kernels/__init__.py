"""Compiled (numba) kernels behind the hot paths of the estimator core.

The numpy formulation of these computations builds ``(H, N, 8, 6)`` Jacobians and
a dozen ``(H, N)`` temporaries per call, and the core calls them a few hundred
times per frame; memory traffic and per-call overhead, not arithmetic, set the
time. Each kernel here walks the hypotheses and points once, keeps a point's
residual and Jacobian in registers and accumulates what the caller needs (the
normal equations, a cost, one squared residual). The Python wrappers in
:mod:`stereovo.estimation.reprojection`, :mod:`stereovo.estimation.scoring`,
:mod:`stereovo.estimation.solvers`, :mod:`stereovo.estimation.samplers`,
:mod:`stereovo.estimation.refinement` (whose refine / re-gate rounds run here in one call,
:func:`refine_rounds`) and :mod:`stereovo.estimation.sample_check` keep the shapes and
documentation; nothing outside them calls this package.

Conventions (as in :mod:`stereovo.estimation.reprojection`): a motion maps
``x_k = R x_{k-1} + t``; the perturbation is ``T <- exp(delta^) T`` with
``delta = (rho, omega)``; a point's symmetric residual has 8 rows (forward
uL, vL, uR, vR at k, then backward at k-1), in pixels.

Array arguments: ``R (H, 3, 3)``, ``t (H, 3)``; point arrays ``(G, M, .)`` where
``G`` is 1 (shared by all hypotheses) or H (one set per hypothesis); ``cam`` is
``(fx, fy, cx, cy, baseline, v_per_match)`` (:attr:`stereovo.camera.StereoCamera.parameters`). All float64, C-contiguous (the wrappers ensure it).
No kernel draws random numbers or reduces in parallel, so results are
bit-for-bit repeatable.

The kernels by role (this package re-exports every public name, so
``from stereovo.estimation.kernels import name`` and ``kernels.name`` reach them all):

- :mod:`~stereovo.estimation.kernels.base`: the numba options, ``MIN_DEPTH``, ``BEHIND_CAMERA_RESIDUAL``;
- :mod:`~stereovo.estimation.kernels.residuals`: symmetric residuals and Jacobians, the forward error;
- :mod:`~stereovo.estimation.kernels.least_squares`: Gauss-Newton / Levenberg-Marquardt;
- :mod:`~stereovo.estimation.kernels.mahalanobis`: the 3D and the pixel Mahalanobis residuals;
- :mod:`~stereovo.estimation.kernels.fitting`: rigid fits, minimal-sample fits, degeneracy;
- :mod:`~stereovo.estimation.kernels.sampling`: drawing minimal samples and their rigidity check;
- :mod:`~stereovo.estimation.kernels.refinement`: the refine / re-gate rounds;
- :mod:`~stereovo.estimation.kernels.beliefs`: BANSAC's and ARS's belief updates and draws (imported
  as a module by :mod:`stereovo.estimation.bansac` and :mod:`stereovo.estimation.ars`, not re-exported).

The early-rejection verification kernels are :mod:`stereovo.estimation.kernels_verification`.
"""

from __future__ import annotations

from stereovo.estimation.kernels.base import BEHIND_CAMERA_RESIDUAL, MIN_DEPTH
from stereovo.estimation.kernels.fitting import degenerate_triplets, minimal_fits, rigid_fits
from stereovo.estimation.kernels.least_squares import CONVERGED_STEP_IN_STD, gauss_newton
from stereovo.estimation.kernels.mahalanobis import mahalanobis_sq, pixel_mahalanobis_sq
from stereovo.estimation.kernels.refinement import (
    GATE_MAHALANOBIS,
    GATE_PIXEL_MAHALANOBIS,
    GATE_REPROJECTION,
    refine_rounds,
)
from stereovo.estimation.kernels.residuals import forward_reprojection_sq, point_reprojection_sq, symmetric_residuals
from stereovo.estimation.kernels.sampling import distinct_triplets, prior_defects, rigid_triplets, weighted_triplets

__all__ = [
    "MIN_DEPTH",
    "BEHIND_CAMERA_RESIDUAL",
    "symmetric_residuals",
    "point_reprojection_sq",
    "forward_reprojection_sq",
    "CONVERGED_STEP_IN_STD",
    "gauss_newton",
    "mahalanobis_sq",
    "pixel_mahalanobis_sq",
    "rigid_fits",
    "degenerate_triplets",
    "minimal_fits",
    "distinct_triplets",
    "weighted_triplets",
    "prior_defects",
    "rigid_triplets",
    "GATE_REPROJECTION",
    "GATE_MAHALANOBIS",
    "GATE_PIXEL_MAHALANOBIS",
    "refine_rounds",
]
