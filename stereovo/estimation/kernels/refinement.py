"""The compiled refinement loop: Levenberg-Marquardt on the inliers, re-gated, round after round.

:func:`refine_rounds` runs :meth:`stereovo.estimation.roles.refinement.ReprojectionRefiner.refine_with_residuals`
in one call for the residual models with a compiled kernel (``GATE_*``).
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.kernels.base import jit
from stereovo.estimation.kernels.least_squares import levenberg_marquardt, lm_scratch
from stereovo.estimation.kernels.mahalanobis import mahalanobis_sq, pixel_mahalanobis_sq
from stereovo.estimation.kernels.residuals import forward_reprojection_sq


# Residual models the compiled refinement loop can gate with (see :func:`refine_rounds`).
GATE_REPROJECTION, GATE_MAHALANOBIS, GATE_PIXEL_MAHALANOBIS = 0, 1, 2


@jit
def _gate_sq(gate, R, t, X, Y, cov_prev, cov_curr, mc, cam, sigma_sq):
    """``(H, N)`` squared residuals of the residual model ``gate`` (uncapped)."""
    if gate == GATE_REPROJECTION:
        return forward_reprojection_sq(R, t, X, mc, cam)
    if gate == GATE_MAHALANOBIS:
        return mahalanobis_sq(R, t, X, Y, cam, sigma_sq, 0.0)
    return pixel_mahalanobis_sq(R, t, X, cov_prev, mc, cam, sigma_sq)


@jit
def refine_rounds(
    R, t, X, Y, mp, mc, cam, cov_prev, cov_curr, sigma_sq, inliers, gate, threshold_sq, regate,
    rounds, iterations, huber, damping, tolerance, start_sq,
):
    """:meth:`ReprojectionRefiner.refine_with_residuals` for a gate with a compiled residual kernel.

    Alternates Levenberg-Marquardt on the inliers (:func:`gauss_newton` with step control) with
    re-selecting them under ``threshold_sq`` of the model ``gate`` (``GATE_*``), for at most
    ``rounds`` rounds; with ``regate`` the given inliers are first re-selected by the gate (kept
    if at least half as many). A round that loses more than half the inliers is undone, and the
    rounds end once the inliers stay the same. ``start_sq (N,)``: the gate's squared residuals of
    ``R, t`` where the caller has them (the re-selection reads them), or an empty array. The same
    arithmetic as the Python loop, without its per-round overhead. Returns ``R (3, 3)``, ``t (3,)``, the inliers ``(N,)``, the gate's
    squared residuals ``(N,)`` of the returned motion and whether those were computed (False:
    the motion is the one given and was not gated).
    """
    N = X.shape[0]
    current_R = np.empty((1, 3, 3))
    current_t = np.empty((1, 3))
    current_R[0] = R
    current_t[0] = t
    trial_R = np.empty((1, 3, 3))
    trial_t = np.empty((1, 3))
    selected = inliers.copy()
    n_selected = 0
    for i in range(N):
        n_selected += selected[i]
    residual_sq = np.empty(N)
    have_residuals = False
    if regate:
        if start_sq.shape[0] == N:
            sq = start_sq
        else:
            sq = _gate_sq(gate, current_R, current_t, X, Y, cov_prev, cov_curr, mc, cam, sigma_sq)[0]
        n_gated = 0
        for i in range(N):
            n_gated += sq[i] < threshold_sq
        if n_gated >= n_selected // 2:
            for i in range(N):
                selected[i] = sq[i] < threshold_sq
            n_selected, residual_sq, have_residuals = n_gated, sq, True
    weights = np.empty(N)
    scratch = lm_scratch()
    for _ in range(rounds):
        if n_selected < 3:
            break
        for i in range(N):
            weights[i] = 1.0 if selected[i] else 0.0
        trial_R[0] = current_R[0]
        trial_t[0] = current_t[0]
        levenberg_marquardt(
            trial_R[0], trial_t[0], X, Y, mp, mc, cam, weights, huber, iterations, damping, tolerance, True, scratch
        )
        sq = _gate_sq(gate, trial_R, trial_t, X, Y, cov_prev, cov_curr, mc, cam, sigma_sq)[0]
        n_new = 0
        for i in range(N):
            n_new += sq[i] < threshold_sq
        if n_new < n_selected // 2:
            break  # refinement ran away from the consensus: keep what we had
        current_R[0] = trial_R[0]
        current_t[0] = trial_t[0]
        residual_sq, have_residuals = sq, True
        same = n_new == n_selected
        for i in range(N):
            now = sq[i] < threshold_sq
            if now != selected[i]:
                same = False
            selected[i] = now
        n_selected = n_new
        if same:
            break
    return current_R[0].copy(), current_t[0].copy(), selected, residual_sq, have_residuals
