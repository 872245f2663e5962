"""The rigid-distance test: the one definition of when two matches keep their distance.

A rigid motion preserves distances, so for two correct matches ``a`` and ``b`` the distance between
their triangulated points changes from frame k-1 to frame k only by triangulation noise. Three parts
of the project ask this question: the rigidity sample check (:mod:`stereovo.estimation.roles.sample_check`,
each pair of a minimal sample), the consistency graph of maximum-clique inlier detection
(:func:`stereovo.estimation.methods.clique.consistency_matrix`, Hirschmueller, Innocent & Garibaldi, ICARCV
2002; Howard, IROS 2008) and the environment's per-match consistency feature
(:func:`vo_gym.features.rigid_consistency_degree`). Each supplies its own noise model (the variance
``var`` of the distance change, m^2: covariances carried onto the pair's direction, or per-match
scalar spreads) and its own gate; the distance change and the comparison are written here once.

Both functions are plain arithmetic, so they take scalars or numpy arrays (elementwise, the clique's
vectorised blocks); ``*_jit`` are the same functions compiled for inlining into numba kernels.
"""

from __future__ import annotations

import numpy as np
from numba import njit


def distance_change_sq(x0, x1, x2, y0, y1, y2):
    """``(|y| - |x|)^2`` in m^2: the squared change of a pairwise distance between the frames.

    ``x = X_a - X_b`` is the difference of the two points at k-1 and ``y = Y_a - Y_b`` at k, each
    given by its three components (m; scalars or arrays of one shape).
    """
    return (np.sqrt(y0 * y0 + y1 * y1 + y2 * y2) - np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)) ** 2


def rigid_distance_consistent(change_sq, var, gate_sq):
    """True where a pair keeps its distance: ``change_sq < gate_sq * var``.

    ``change_sq`` from :func:`distance_change_sq` (m^2), ``var`` the variance of the change under the
    caller's noise model (m^2), ``gate_sq`` the squared gate in standard deviations (a chi-square(1)
    quantile, or ``c^2``). Strict, so a pair with no variance (coincident points) never passes.
    """
    return change_sq < gate_sq * var


distance_change_sq_jit = njit(cache=True, nogil=True, inline="always")(distance_change_sq)
rigid_distance_consistent_jit = njit(cache=True, nogil=True, inline="always")(rigid_distance_consistent)
