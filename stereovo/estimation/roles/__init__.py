"""The roles the shared loop composes, named for what they do and for no method.

- :mod:`~stereovo.estimation.roles.solvers`: minimal 3-point fits, the sample size, degeneracy;
- :mod:`~stereovo.estimation.roles.reprojection`: the stereo reprojection residuals and Gauss-Newton steps;
- :mod:`~stereovo.estimation.roles.scoring`: residual models (reprojection, Mahalanobis) and qualities;
- :mod:`~stereovo.estimation.roles.verification`: scoring a batch of hypotheses (the full verifier);
- :mod:`~stereovo.estimation.roles.partial`: residuals on some points only (for early rejection);
- :mod:`~stereovo.estimation.roles.termination`: the adaptive bound and the fixed budget;
- :mod:`~stereovo.estimation.roles.samplers`: uniform, weighted (guided), replayed and PROSAC draws;
- :mod:`~stereovo.estimation.roles.sample_check`: the rigidity check of a minimal sample;
- :mod:`~stereovo.estimation.roles.refinement`: the final LM refinement with inlier re-selection;
- :mod:`~stereovo.estimation.roles.local_optimization`: the consensus refit of each new best.
"""
