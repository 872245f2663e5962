"""Rigid-motion solvers: the batched 3-point minimal solver and the non-minimal fit.

Both solve the weighted least-squares rigid fit in closed form with Horn's
unit quaternion (1987): the same minimiser as Kabsch/Arun's SVD with the
det(R) = +1 correction, always a proper rotation, compiled without a LAPACK
call (a 3x3 SVD cost more than the rest of a minimal fit). The minimal solver handles a whole batch of hypotheses in one compiled pass
(gather, degeneracy test, fit, polish). Because depth noise makes a 3-point fit on
triangulated points badly conditioned (docs/algorithms.md, the `polish` enhancement), the minimal
solver can polish each hypothesis with a few batched Gauss-Newton steps on
the stereo reprojection error of its own three points (as libviso2 does):
the hypothesis stays minimal, but is judged where pixel noise is isotropic.
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels import fitting as fitting_kernels
from stereovo.estimation.problem import StereoProblem

SAMPLE_SIZE = 3  # a rigid motion from three 3-D points: the one definition the core shares
# A triplet whose triangle area is below this fraction of its
# squared longest side is near-collinear and leaves the rotation about its line free.
DEGENERATE_AREA_RATIO = 1e-3


def kabsch_batch(X: np.ndarray, Y: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rigid motions with ``Y ~ R X + t`` for a batch of point sets.

    Args:
        X, Y: ``(H, M, 3)`` corresponding points (metres), M >= 3.
        weights: optional ``(H, M)`` non-negative weights.

    Returns:
        ``R (H, 3, 3)`` with det +1 and ``t (H, 3)``.
    """
    X = np.ascontiguousarray(X, dtype=float)
    Y = np.ascontiguousarray(Y, dtype=float)
    w = np.ones(X.shape[:2]) if weights is None else np.ascontiguousarray(weights, dtype=float)
    return fitting_kernels.rigid_fits(X, Y, w)


def fit_rigid(X: np.ndarray, Y: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Non-minimal least-squares rigid fit ``Y ~ R X + t`` on ``(M, 3)`` points, M >= 3."""
    R, t = kabsch_batch(X[None], Y[None], None if weights is None else np.asarray(weights)[None])
    return R[0], t[0]


def degenerate_triplets(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Mask ``(H,)`` of near-collinear or near-coincident triplets in either frame.

    Args:
        X, Y: ``(H, 3, 3)`` triplets of points at k-1 and k.
    """
    return fitting_kernels.degenerate_triplets(
        np.ascontiguousarray(X, dtype=float), np.ascontiguousarray(Y, dtype=float), DEGENERATE_AREA_RATIO
    )


def minimal_hypotheses(
    problem: StereoProblem, samples: np.ndarray, polish_iterations: int = 2
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fit one motion per minimal sample.

    Args:
        samples: ``(H, 3)`` int indices into the problem's correspondences.
        polish_iterations: Gauss-Newton steps on the three points' stereo reprojection
            error after the closed-form fit (0 keeps the plain least-squares hypothesis).

    Returns:
        ``(R (H, 3, 3), t (H, 3), valid (H,))``; invalid hypotheses came from degenerate samples
        (their motion is the identity) or did not stay finite.

    The degeneracy test, closed-form fit and polish run in one compiled pass per batch
    (:func:`stereovo.estimation.kernels.fitting.minimal_fits`), with the same arithmetic as
    :func:`degenerate_triplets`, :func:`kabsch_batch` and plain Gauss-Newton steps
    (:func:`stereovo.estimation.roles.reprojection.gauss_newton_steps` without step control).
    """
    return fitting_kernels.minimal_fits(
        np.ascontiguousarray(samples, dtype=np.int64), problem.points_prev, problem.points_curr,
        problem.prev, problem.curr, problem.camera.parameters, DEGENERATE_AREA_RATIO, int(polish_iterations),
    )
