"""Compiled (numba) kernels behind the hot paths of the estimator core.

The numpy formulation of these computations builds ``(H, N, 8, 6)`` Jacobians and
a dozen ``(H, N)`` temporaries per call, and the core calls them a few hundred
times per frame; memory traffic and per-call overhead, not arithmetic, set the
time. Each kernel here walks the hypotheses and points once, keeps a point's
residual and Jacobian in registers and accumulates what the caller needs (the
normal equations, a cost, one squared residual). The Python wrappers in
:mod:`stereovo.estimation.roles` (reprojection, scoring, solvers, samplers, sample_check,
refinement, whose refine / re-gate rounds run here in one call), the early-rejection
verifiers of :mod:`stereovo.estimation.methods.tdd` and :mod:`~stereovo.estimation.methods.sprt`,
the belief samplers of :mod:`~stereovo.estimation.methods.bansac` and
:mod:`~stereovo.estimation.methods.ars`, MLESAC's mixture likelihood (:mod:`~stereovo.estimation.methods.mlesac`), the clique of :mod:`~stereovo.estimation.methods.clique`
and :mod:`stereovo.estimation.covariance` keep the shapes and documentation.

Conventions (as in :mod:`stereovo.estimation.roles.reprojection`): a motion maps
``x_k = R x_{k-1} + t``; the perturbation is ``T <- exp(delta^) T`` with
``delta = (rho, omega)``; a point's symmetric residual has 8 rows (forward
uL, vL, uR, vR at k, then backward at k-1), in pixels.

Array arguments: ``R (H, 3, 3)``, ``t (H, 3)``; point arrays ``(G, M, .)`` where
``G`` is 1 (shared by all hypotheses) or H (one set per hypothesis); ``cam`` is
``(fx, fy, cx, cy, baseline, v_per_match)`` (:attr:`stereovo.camera.StereoCamera.parameters`). All float64, C-contiguous (the wrappers ensure it).
No kernel draws random numbers or reduces in parallel, so results are
bit-for-bit repeatable.

The kernels by role (import each name from its module):

- :mod:`~stereovo.estimation.kernels.base`: the numba options, ``MIN_DEPTH``, ``BEHIND_CAMERA_RESIDUAL``;
- :mod:`~stereovo.estimation.kernels.residuals`: symmetric residuals and Jacobians, the forward error;
- :mod:`~stereovo.estimation.kernels.least_squares`: Gauss-Newton / Levenberg-Marquardt;
- :mod:`~stereovo.estimation.kernels.mahalanobis`: the 3D and the pixel Mahalanobis residuals;
- :mod:`~stereovo.estimation.kernels.scores`: the inlier count of a batch;
- :mod:`~stereovo.estimation.kernels.fitting`: rigid fits, minimal-sample fits, degeneracy;
- :mod:`~stereovo.estimation.kernels.rigidity`: the rigid-distance test (plain and compiled);
- :mod:`~stereovo.estimation.kernels.depth`: which rows have a resolvable depth;
- :mod:`~stereovo.estimation.kernels.sampling`: drawing minimal samples and their rigidity check;
- :mod:`~stereovo.estimation.kernels.refinement`: the refine / re-gate rounds;
- :mod:`~stereovo.estimation.kernels.verification`: early rejection (T(d,d), SPRT) and the guided stopping bound;
- :mod:`~stereovo.estimation.kernels.stopping`: the uniform adaptive stopping bound;
- :mod:`~stereovo.estimation.kernels.logaddexp`: numpy's ``logaddexp``, bit for bit (scalar and ``(H, N)``);
- :mod:`~stereovo.estimation.kernels.beliefs`: BANSAC's and ARS's belief updates and draws;
- :mod:`~stereovo.estimation.kernels.bansac_runner`: BANSAC's compiled search;
- :mod:`~stereovo.estimation.kernels.batch_search`: ``probabilistic``'s compiled search;
- :mod:`~stereovo.estimation.kernels.covariance`: the normal equations of the pose covariance.
"""
