"""Residuals on part of the correspondences: what early-rejection verifiers evaluate.

The residual models score every hypothesis on every correspondence of a
:class:`StereoProblem`. Verifiers that look at a few points first (T(d,d),
SPRT, preemptive scoring) hand them a *sub-problem* holding only those rows,
so they reuse the very same residual code and gate as full verification.
"""

from __future__ import annotations

import numpy as np

from stereovo.estimation.roles.verification import ScoringContext

# Hypotheses per call of :func:`residuals_at`: its cost is O(group * d) per hypothesis.
_GROUP = 64


def residuals_on(ctx: ScoringContext, R: np.ndarray, t: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Squared residuals ``(H, M)`` of every hypothesis on the same correspondences ``rows (M,)``."""
    return ctx.residual_model.squared(ctx.problem.select(rows), R, t)


def residuals_at(ctx: ScoringContext, R: np.ndarray, t: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Squared residuals ``(H, d)`` of hypothesis h on its own correspondences ``idx[h]``.

    Args:
        R, t: ``(H, 3, 3)`` and ``(H, 3)`` motions.
        idx: ``(H, d)`` int correspondence indices, different for each hypothesis.

    The residual models evaluate all hypotheses on all rows of a problem, so a
    group of G hypotheses is scored on the G*d rows of the group and the
    diagonal blocks are kept; groups bound that waste to ``_GROUP * d`` per hypothesis.
    """
    H, d = idx.shape
    out = np.empty((H, d))
    for start in range(0, H, _GROUP):
        stop = min(start + _GROUP, H)
        g = stop - start
        sq = residuals_on(ctx, R[start:stop], t[start:stop], idx[start:stop].ravel())  # (g, g*d)
        out[start:stop] = sq.reshape(g, g, d)[np.arange(g), np.arange(g)]
    return out
