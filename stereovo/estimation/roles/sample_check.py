"""Sample checks: reject a minimal sample before it is fitted and scored.

A rigid motion preserves distances, so the three pairwise distances of an
all-inlier triplet agree between frames k-1 and k up to triangulation noise;
a triplet holding an outlier usually breaks two of them. The probabilistic
RANSAC of Brink et al. (docs/algorithms.md, `probabilistic`) drops a 3-point fit whose
similarity scale is far from 1 for this reason. :class:`RigidityCheck` is the
covariance-aware form of that check: each distance's change is standardised
by its first-order variance from the triangulation covariances, so far points
(large depth error) are judged as leniently as their noise requires and near
ones as strictly. It removes most contaminated samples at high contamination, at a small
fraction of a fit's cost, before the fit and the scoring over all N (docs/performance.md,
"Measurements behind the code").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stereovo.estimation.kernels.sampling import rigid_triplets
from stereovo.estimation.problem import StereoProblem


@dataclass(frozen=True)
class RigidityCheck:
    """Keep a triplet if each of its pairwise distances changes by at most ``sqrt(threshold_sq)``
    standard deviations between the frames.

    Args:
        threshold_sq: chi-square(1) quantile; 10.83 (probability 0.999) rejects about 0.1 % of
            all-inlier triplets (three tests, correlated).
    """

    threshold_sq: float

    def accept(self, problem: StereoProblem, samples: np.ndarray) -> np.ndarray:
        """``(H,)`` bool: which of the ``(H, 3)`` index samples are rigid enough to fit."""
        return rigid_triplets(
            np.ascontiguousarray(samples, dtype=np.int64), problem.points_prev, problem.points_curr,
            problem.cov_prev, problem.cov_curr, float(self.threshold_sq),
        )
